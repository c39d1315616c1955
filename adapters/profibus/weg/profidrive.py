"""The PROFIdrive data profile, P0741 = 0 (CFW-11 and CFW700), as the master speaks it.

Control word P0967 (STW1) and NSOLL out, status word P0968 (ZSW1) and NIST in (CFW-11
Tables 3.8 / 3.9, CFW700 Tables 4.7 / 4.8); the speed words' 4000h = P0134, reversal by
a negative reference. The control word walks the drive's switching-on states.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from adapters.profibus.weg import words as w
from adapters.profibus.weg.dataprofile import Heard, Order, Sent
from adapters.profibus.weg.scales import Ratings, SpeedBase
from adapters.profibus.weg.spec import ModelSpec
from gateway.model import Direction, DriveStatus, Readings

if TYPE_CHECKING:
    from adapters.profibus.weg.options import WegOptions

MAX_PROFIDRIVE_PCT: Final = 100.0  # the drive limits the speed to P0134 = 4000h

_PROFIDRIVE_STATUS: Final[Mapping[w.ProfidriveState, DriveStatus]] = {
    w.ProfidriveState.NOT_READY: DriveStatus.NOT_READY,
    w.ProfidriveState.SWITCHING_ON_INHIBITED: DriveStatus.NOT_READY,
    w.ProfidriveState.READY_TO_SWITCH_ON: DriveStatus.READY,
    w.ProfidriveState.SWITCHED_ON: DriveStatus.READY,
    w.ProfidriveState.OPERATION: DriveStatus.RUNNING,
    w.ProfidriveState.FAULT: DriveStatus.FAULTED,
}


@dataclass(frozen=True)
class ProfidriveWords:
    """STW1 / NSOLL out, ZSW1 / NIST in, for one model."""

    spec: ModelSpec

    def base_configured(self, options: WegOptions) -> bool:
        return options.max_rpm is not None

    def rating_params(self, ratings: Ratings) -> dict[str, int]:
        """Nothing beyond P0134, which the profile reads in both data profiles."""
        return {}

    def speed_base(self, ratings: Ratings, suffix: str) -> SpeedBase | None:
        r = ratings
        if r.max_rpm is None:
            return None
        label = f"4000h = {self.spec.pname(134)} {r.max_rpm:g} rpm{suffix}"
        return SpeedBase(r.max_rpm, w.PROFIDRIVE_SPEED_BASE, MAX_PROFIDRIVE_PCT, label)

    def control(self, order: Order) -> tuple[int, int, Sent]:
        """STW1 (P0967, Table 3.8 / 4.7) walking the switching-on states, and NSOLL.

        Switching on inhibited: ON = 0 (the drive goes to ready to switch on); then ON = 1
        with enable operation, ramp and setpoint (switched on, then operation). A fault is
        acknowledged with one bit-7 pulse and ON = 0. Reverse is a negative reference
        (P0967 note). Reserved bits 5 and 9 are sent as 0.

        Quick stop (bit 2 = 0, OFF3) and coast stop (bit 1 = 0, OFF2) go with ON = 0 and
        JOG = 0, so their release never switches the drive back on. With P0202 V/f or VVW
        (bit 2 note: not recommended) a quick stop is OFF1: ON = 0 with bit 2 = 1.
        """
        d = order.desired
        zsw = order.zsw
        state = w.ProfidriveState.SWITCHING_ON_INHIBITED if zsw is None else zsw.state
        run, jog = order.run, order.jog
        want = run or jog
        walkable = state in (
            w.ProfidriveState.READY_TO_SWITCH_ON,
            w.ProfidriveState.SWITCHED_ON,
            w.ProfidriveState.OPERATION,
        )
        on = want and walkable
        magnitude = order.reference
        forward = d.direction is Direction.FORWARD
        reference = w.saturate(magnitude if forward else -magnitude)
        control = w.ProfidriveControl(
            on=on,
            no_coast_stop=not d.coast_stop,
            no_quick_stop=not (d.quick_stop and not order.quick_stop_as_ramp),
            enable_operation=True,
            enable_ramp=True,
            enable_setpoint=True,
            fault_ack=order.reset,
            jog=jog and on,
            control_by_plc=d.remote,
        )
        sent = Sent(on, True, reference, d.remote, jog and on)
        return control.encode(w.STW1_BITS), reference, sent

    def status(
        self, word: int, speed: int, sent: Sent, near: Callable[[int], bool], changes: Readings
    ) -> Heard:
        """P0968 ZSW1 (Table 3.9 / 4.8) and NIST (4000h = P0134)."""
        zsw = w.ProfidriveStatus.decode(word, self.spec.zsw1_bits)
        state = zsw.state
        operation = state is w.ProfidriveState.OPERATION
        running = operation and (sent.run or speed != 0)
        if sent.jog:  # JOG 1 (STW1 bit 8): the drive's own JOG speed is its reference
            at_ref = operation and speed != 0
        elif any(name == "frequency_reached" for name, _ in self.spec.zsw1_bits):
            at_ref = operation and sent.run and zsw.frequency_reached  # CFW-11 bit 10
        else:
            at_ref = operation and sent.run and near(speed)
        status = _PROFIDRIVE_STATUS[state]
        if operation:
            if not sent.run or not zsw.quick_stop_not_active:
                status = DriveStatus.STOPPING if speed else DriveStatus.READY
            else:
                status = DriveStatus.RUNNING if at_ref else DriveStatus.STARTING
        elif state is w.ProfidriveState.SWITCHED_ON and sent.run:
            status = DriveStatus.STARTING
        if speed > 0:
            direction = Direction.FORWARD
        elif speed < 0:
            direction = Direction.REVERSE
        else:
            direction = Direction.FORWARD if sent.reference >= 0 else Direction.REVERSE
        changes.update(
            {
                "status": status,
                "running": running,
                "direction": direction,
                "at_reference": at_ref,
                "remote": zsw.control_requested,
                "local_control": not zsw.control_requested,  # ZSW1 bit 9 (Table 3.9 / 4.8)
                "alarm": zsw.warning,
            }
        )
        return Heard(faulted=zsw.fault, alarm=zsw.warning, zsw=zsw)
