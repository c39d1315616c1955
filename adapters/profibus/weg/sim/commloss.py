"""The simulated drive's actions on a communication error (P0313: CFW-11 Table 3.3.1,
CFW700 Table 4.1, CFW320 Table 4.1) other than a fault.

Each writes the network's command (P0684) or the HMI's: it acts only where the network is
a command source. P0313 = 5 trips F2xx instead (:meth:`.drive.WegSim._comm_error`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Final

from adapters.profibus.weg import spec as specs
from adapters.profibus.weg.sim.commands import Panel
from adapters.profibus.weg.sim.dataprofile import PdState, PdStop, SimDrive


def _ramp_stop(drive: SimDrive) -> None:
    drive.net = replace(drive.net, run=False)
    if drive.pd_state is PdState.S4:
        drive.pd_stop = PdStop.OFF1


def _disable(drive: SimDrive) -> None:
    drive.net = replace(drive.net, general_enable=False, run=False)
    drive.pd_state = PdState.S1
    drive.pd_stop = None


def _local(drive: SimDrive) -> None:
    drive.net = replace(drive.net, remote=False)


def _local_keep(drive: SimDrive) -> None:
    commands = drive.commands
    remote = commands.remote()
    drive.panel = Panel(
        run=commands.run_command(remote), reference_rpm=commands.reference_rpm(remote)
    )
    drive.net = replace(drive.net, remote=False)


COMM_ACTIONS: Final[Mapping[specs.CommAction, Callable[[SimDrive], None]]] = {
    specs.CommAction.RAMP_STOP: _ramp_stop,
    specs.CommAction.GENERAL_DISABLE: _disable,
    specs.CommAction.GO_TO_LOCAL: _local,
    specs.CommAction.LOCAL_KEEP: _local_keep,
}
