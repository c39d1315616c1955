"""The commands in force on a simulated WEG drive: the network's or the HMI's, as the
command-source parameters choose (P0105, P0220-P0228, CFW-11 / CFW700 section 3 / 4).

LOC/REM follows P0220 (always local or remote, or the network's P0684 bit 4 / STW1 bit
10); in local and in remote each of run/stop, reference, direction and JOG has its own
source parameter. The simulator numbers the sources as :mod:`.params` lists them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from adapters.profibus.weg import words as w
from adapters.profibus.weg.sim import params as sp


@dataclass(frozen=True)
class NetCommand:
    """The network's command as the drive holds it (P0684 bits and P0685, 13 bits)."""

    run: bool = False
    general_enable: bool = False
    forward: bool = True
    jog: bool = False
    remote: bool = True
    second_ramp: bool = False
    quick_stop: bool = False
    reference: int = 0  # P0685, signed 13-bit word

    def control_word(self, bits: w.BitTable) -> int:
        """The command as P0684 reads (the model's ``bits``; no fault reset)."""
        control = w.ManufacturerControl(
            run=self.run,
            general_enable=self.general_enable,
            forward=self.forward,
            jog=self.jog,
            remote=self.remote,
            second_ramp=self.second_ramp,
            quick_stop=self.quick_stop,
        )
        return control.encode(bits)


@dataclass(frozen=True)
class Panel:
    """The local (HMI) commands: stopped unless P0313 = 4 copied the network's."""

    run: bool = False
    reference_rpm: float = 0.0  # signed


def sync_rpm(values: Mapping[int, int]) -> float:
    """The synchronous speed from P0403 and P0402 (1800 rpm where they give none)."""
    try:
        return w.synchronous_rpm(float(values[403]), float(values[402]))
    except ValueError:
        return 1800.0


@dataclass(frozen=True)
class Commands:
    """The drive's parameters (``values``), the network's and the HMI's commands, as one
    view of what commands the drive."""

    values: Mapping[int, int]
    net: NetCommand
    panel: Panel

    def remote(self) -> bool:
        """LOC/REM per P0220 (always local/remote, or the network's bit 4 / STW1 bit 10)."""
        source = self.values[220]
        if source == sp.SRC_LOCREM_ALWAYS_LOCAL:
            return False
        if source == sp.SRC_LOCREM_ALWAYS_REMOTE:
            return True
        if source in (sp.SRC_LOCREM_NET_LOC, sp.SRC_LOCREM_NET_REM):
            return self.net.remote
        return False  # HMI key or digital input: local in the simulator

    def sources(self, remote: bool) -> tuple[int, int, int, int]:
        """(run/stop, reference, direction, JOG) sources: P0227/222/226/228 or 224/221/223/225."""
        v = self.values
        return (v[227], v[222], v[226], v[228]) if remote else (v[224], v[221], v[223], v[225])

    def run_command(self, remote: bool) -> bool:
        run_src = self.sources(remote)[0]
        return self.net.run if run_src == sp.SRC_RUN_NET else self.panel.run

    def reference_rpm(self, remote: bool) -> float:
        """Signed reference in rpm, clamped to P0134."""
        _, ref_src, dir_src, _ = self.sources(remote)
        if ref_src != sp.SRC_REF_NET:
            return self.panel.reference_rpm
        if dir_src in sp.SRC_DIR_NET:
            raw = w.effective_reference(self.net.forward, self.net.reference)
        else:
            raw = abs(self.net.reference) * (-1 if dir_src == sp.SRC_DIR_REVERSE else 1)
        rpm = w.raw_to_speed(raw, sync_rpm(self.values), w.SPEED_13BIT_BASE)
        limit = float(self.values[134])
        return max(-limit, min(limit, rpm))

    def second_ramp(self) -> bool:
        source = self.values[105]
        if source == sp.SRC_RAMP_SECOND:
            return True
        return source == sp.SRC_RAMP_NET and self.net.second_ramp
