"""The manufacturer ("WEG") data profile, P0741 = 1, as the master speaks it.

Control word P0684 and speed reference P0685 out, status word P0680 and motor speed P0681
in (CFW-11 Tables 3.2 / 3.3, CFW700 and CFW320 Tables 4.2 / 4.3); the speed words have 13
bits: 8192 = the synchronous speed (CFW320: the rated frequency P403).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from adapters.profibus.weg import words as w
from adapters.profibus.weg.dataprofile import Heard, Order, Sent
from adapters.profibus.weg.scales import Ratings, SpeedBase
from adapters.profibus.weg.spec import ModelSpec
from gateway.model import Device, Direction, DriveStatus, Readings

if TYPE_CHECKING:
    from adapters.profibus.weg.options import WegOptions

MAX_13BIT_PCT: Final = 100.0 * w.WORD_MAX / w.SPEED_13BIT_BASE  # 4 x base, saturating (P681)

# P0680 bits the model has no field for, published as ``DriveState.values`` entries (0/1)
# where the model's status word has the bit (docs/devices.md): CFW320 Table 4.2 bit 2 "Fire
# mode", CFW-11 Table 3.2 bit 14 "PID automatic" (reserved on the CFW700).
STATUS_VALUES: Final = (("fire_mode", "fire_mode"), ("pid_automatic", "automatic"))


@dataclass(frozen=True)
class ManufacturerWords:
    """P0684 / P0685 out, P0680 / P0681 in, for one model."""

    spec: ModelSpec

    def base_configured(self, options: WegOptions) -> bool:
        o = options
        return o.sync_rpm is not None or (o.rated_hz is not None and o.rated_rpm is not None)

    def rating_params(self, ratings: Ratings) -> dict[str, int]:
        """P0403 and P0402 while the synchronous speed (CFW320: the rated frequency) is
        not known."""
        r, need = ratings, {}
        if r.sync_rpm is None or (self.spec.device is Device.CFW320 and r.rated_hz is None):
            if r.rated_hz is None:
                need["rated_hz"] = 403
            if r.rated_rpm is None and r.sync_rpm is None:
                need["rated_rpm"] = 402
        return need

    def speed_base(self, ratings: Ratings, suffix: str) -> SpeedBase | None:
        r = ratings
        sync = r.sync_rpm
        if sync is None and r.rated_hz is not None and r.rated_rpm is not None:
            sync = w.synchronous_rpm(r.rated_hz, r.rated_rpm)
        if sync is None:
            return None
        if self.spec.device is Device.CFW320:
            hz = "" if r.rated_hz is None else f" {r.rated_hz:g} Hz"
            label = f"8192 = {self.spec.pname(403)}{hz} = {sync:g} rpm{suffix}"
        else:
            label = f"8192 = {sync:g} rpm synchronous{suffix}"
        limit = MAX_13BIT_PCT if r.max_rpm is None else min(MAX_13BIT_PCT, 100 * r.max_rpm / sync)
        return SpeedBase(sync, w.SPEED_13BIT_BASE, limit, label)

    def control(self, order: Order) -> tuple[int, int, Sent]:
        """P0684 and P0685 (Table 3.3 / 4.3; P0685 bit 2 cases).

        Run = run/stop + general enable + remote; coast stop drops general enable; quick
        stop is bit 6 where the model has it. Bit 2 = 1 for forward and 0 for reverse, so
        the sign of the speed (normally positive) keeps the manual's meaning.

        Quick stop and coast stop clear run (bit 0) and JOG (bit 3): a drive that does not
        execute bit 6 (CFW700 "not allowed" in V/f or VVW) still ramps down, and the
        release of either stop never restarts the motor. With P0202 V/f or VVW bit 6 is
        not sent: the quick stop is a ramp stop (docs/devices.md). Bit 5 selects the
        second ramp (P0102/P0103) when the drive's ``second_ramp`` option says so.
        """
        d = order.desired
        forward = d.direction is Direction.FORWARD
        reference = order.reference
        run, jog = order.run, order.jog
        control = w.ManufacturerControl(
            run=run,
            general_enable=not d.coast_stop,
            forward=forward,
            jog=jog,
            remote=d.remote,
            second_ramp=order.second_ramp,
            quick_stop=d.quick_stop and self.spec.quick_stop and not order.quick_stop_as_ramp,
            fault_reset=order.reset,
        )
        sent = Sent(run or jog, forward, reference, d.remote, jog)
        return control.encode(self.spec.control_bits), reference, sent

    def status(
        self, word: int, speed: int, sent: Sent, near: Callable[[int], bool], changes: Readings
    ) -> Heard:
        """P0680 (Table 3.2 / 4.2) and P0681 (13 bits, 8192 = synchronous speed / P403).

        A drive jogging (bit 11 "JOG active", CFW-11 Table 3.2, CFW700 Table 4.2, CFW320
        Table 4.2) runs at its own JOG speed: commanded and at that reference (issue 32
        item 8). Local control is bit 12 LOC/REM = 0: the drive follows its local sources,
        not the network (issue 32 item 6; docs/devices.md).
        """
        st = w.ManufacturerStatus.decode(word, self.spec.status_bits)
        status_values = {
            key: int(getattr(st, bit)) for key, bit in STATUS_VALUES if self._has_status_bit(bit)
        }
        if self.spec.device is Device.CFW320:
            commanded = st.run_command or st.jog  # CFW320 bit 1 "Run command" (JOG: no)
        else:
            commanded = sent.run if st.remote else True
        jogging = st.running and st.jog
        at_ref = jogging or (st.running and commanded and st.remote and near(speed))
        if st.fault:
            status = DriveStatus.FAULTED
        elif st.config_mode or st.undervoltage:
            status = DriveStatus.NOT_READY
        elif not st.running:
            status = DriveStatus.READY
        elif st.quick_stop_active or not commanded:
            status = DriveStatus.STOPPING
        elif at_ref or not st.remote:
            status = DriveStatus.RUNNING
        else:
            status = DriveStatus.STARTING
        changes.update(
            {
                "status": status,
                "running": st.running,
                "direction": Direction.FORWARD if st.forward else Direction.REVERSE,
                "at_reference": at_ref,
                "remote": st.remote,
                "local_control": not st.remote,
                "alarm": st.alarm,
            }
        )
        return Heard(faulted=st.fault, alarm=st.alarm, status_values=status_values)

    def _has_status_bit(self, bit: str) -> bool:
        return any(name == bit for name, _ in self.spec.status_bits)
