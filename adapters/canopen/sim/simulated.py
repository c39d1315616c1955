"""A simulated CANopen line: the link factory the composition root gives the CANopen
adapter for ``simulate = true`` (the production adapter never imports a simulator).

The adapter opens its link on the configured in-process channel (``interface =
"virtual"``); once it is open, :meth:`SimulatedBus.start` runs the bus's drives as
simulated CiA 402 nodes (:class:`~adapters.canopen.sim.runner.SimRunner`) on the same
channel, each with the drive's own EDS, and :meth:`SimulatedBus.stop` ends them after the
adapter has left the line.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Final

from adapters.can.simulated import SIM_START_BOUND, SimulatedLine
from adapters.canopen.codec.frames import CanFrame
from adapters.canopen.link import CanLink, LinkConfig
from adapters.canopen.options import BusOptions, DriveOptions
from adapters.canopen.sim.node import BootState, SimNodeConfig
from adapters.canopen.sim.runner import SimRunner
from gateway.config import BusConfig

SIM_DEFAULT_RATED_CURRENT: Final = 10.0  # A, for a drive whose config and EDS give none


def sim_configs(bus: BusConfig) -> list[SimNodeConfig]:
    """The simulated node of each configured drive (its ``sim_*`` keys, else what the
    drive's config says it is)."""
    out = []
    for d in bus.drives:
        o: DriveOptions = d.options
        s = o.sim
        out.append(
            SimNodeConfig(
                node_id=d.address,
                eds=o.eds_path,
                max_rpm=s.max_rpm or o.max_rpm,
                ramp_time=s.ramp_time,
                boot_state=BootState.OPERATIONAL
                if s.boot_operational
                else BootState.PRE_OPERATIONAL,
                rated_current=o.rated_current or SIM_DEFAULT_RATED_CURRENT,
            )
        )
    return out


class SimulatedBus(SimulatedLine[CanFrame, SimRunner]):
    """The bus's drives simulated on its in-process channel (see the module docstring)."""

    def __init__(self, bus: BusConfig, nodes: list[SimNodeConfig] | None = None) -> None:
        options: BusOptions = bus.options
        config = LinkConfig(options.interface, options.channel, options.bitrate)
        super().__init__("canopen", bus.name, config)
        self.nodes = sim_configs(bus) if nodes is None else nodes

    def link(self) -> CanLink:
        return CanLink(self.config)

    def new_runner(self) -> SimRunner:
        return SimRunner("virtual", self.config.channel, self.nodes)

    async def end(self, task: asyncio.Task[None]) -> None:
        """The runner told to stop (it shuts its bus down and returns), awaited at most
        :data:`SIM_START_BOUND` s; cancelled if it did not end."""
        if self.runner is not None:
            self.runner.stop()
        with contextlib.suppress(TimeoutError, asyncio.CancelledError, Exception):
            async with asyncio.timeout(SIM_START_BOUND):
                await asyncio.shield(task)
        if not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
