"""The PROFIdrive data profile, P0741 = 0 (CFW-11 and CFW700), as the simulated drive
speaks it.

P0967 STW1 (Table 3.8 / 4.7) walks the switching-on state machine (fact sheet 1.11: S1
to S4, OFF1 / OFF2 / OFF3); NSOLL (4000h = P0134, reversal by a negative reference) is
taken as P0685. P0968 ZSW1 (Table 3.9 / 4.8) and NIST out.
"""

from __future__ import annotations

from dataclasses import replace

from adapters.profibus.weg import words as w
from adapters.profibus.weg.sim.commands import NetCommand, sync_rpm
from adapters.profibus.weg.sim.dataprofile import PdState, PdStop, SimDrive


class ProfidriveSimWords:
    """STW1 / NSOLL taken, ZSW1 / NIST sent."""

    def fault_reset(self, drive: SimDrive, word: int) -> bool:
        """STW1 bit 7."""
        return w.ProfidriveControl.decode(word, w.STW1_BITS).fault_ack

    def take(self, drive: SimDrive, word: int, reference: int) -> None:
        """P0967 STW1 (Table 3.8 / 4.7) through the switching-on states; NSOLL -> P0685."""
        c = w.ProfidriveControl.decode(word, w.STW1_BITS)
        drive.stw1 = c
        drive.values[967] = word
        if not drive.fault:
            self._step_state(drive, c)
        rpm = reference * drive.values[134] / w.PROFIDRIVE_SPEED_BASE
        raw = w.speed_to_raw(rpm, sync_rpm(drive.values), w.SPEED_13BIT_BASE)
        operation = drive.pd_state is PdState.S4 and not drive.fault
        drive.net = NetCommand(
            run=operation and c.on and c.enable_ramp and drive.pd_stop is None,
            general_enable=operation and c.no_coast_stop,
            forward=True,  # reversal by a negative reference (P0967 note)
            jog=operation and c.jog,
            remote=c.control_by_plc,
            quick_stop=drive.pd_stop is PdStop.OFF3,
            reference=raw if c.enable_setpoint else 0,  # bit 6: 0 zeroes the reference
        )
        drive.values[685] = w.to_word(drive.net.reference)
        drive.values[684] = drive.net.control_word(drive.spec.control_bits)

    def status(self, drive: SimDrive) -> int:
        """P0968 (Table 3.9 / 4.8)."""
        fault = drive.fault != 0
        state = drive.pd_state
        inhibited = state is PdState.S1 or drive.undervoltage or drive.config_mode
        m = drive.motor
        run = drive.net.run
        reached = state is PdState.S4 and run and m.speed == m.reference and m.speed != 0.0
        status = w.ProfidriveStatus(
            ready_to_switch_on=not fault and not inhibited,
            ready_to_operate=not fault and state in (PdState.S3, PdState.S4),
            operation_enabled=not fault and state is PdState.S4,
            fault=fault,
            coast_stop_not_active=drive.stw1.no_coast_stop,
            quick_stop_not_active=drive.stw1.no_quick_stop and drive.pd_stop is not PdStop.OFF3,
            switching_on_inhibited=not fault and inhibited,
            warning=drive.alarm != 0,
            control_requested=drive.commands.remote(),
            frequency_reached=not fault and reached,
        )
        return status.encode(drive.spec.zsw1_bits)

    def speed(self, drive: SimDrive) -> int:
        """NIST: 4000h = P0134."""
        base = float(drive.values[134] or 1)
        return w.to_word(w.speed_to_raw(drive.motor.speed, base, w.PROFIDRIVE_SPEED_BASE))

    def executes_quick_stop(self, drive: SimDrive) -> bool:
        """The PROFIdrive OFF3 (P0967 bit 2, "not recommended" with V/f or VVW on both
        models) is always executed."""
        return True

    def after_reset(self, net: NetCommand) -> NetCommand:
        """Switching on inhibited: no operation until ON = 0 then ON = 1 (fact sheet 1.11)."""
        return replace(net, run=False, jog=False, general_enable=False)

    def _step_state(self, drive: SimDrive, c: w.ProfidriveControl) -> None:
        """One step of the PROFIdrive switching-on state machine (fact sheet 1.11)."""
        state = drive.pd_state
        if drive.undervoltage or drive.config_mode or not c.no_coast_stop:
            drive.pd_state, drive.pd_stop = PdState.S1, None  # OFF2: coast, inhibited
        elif state is PdState.S1:
            if not c.on and c.no_quick_stop:
                drive.pd_state = PdState.S2
        elif state is PdState.S2:
            if not c.no_quick_stop:
                drive.pd_state = PdState.S1
            elif c.on:
                drive.pd_state = PdState.S4 if c.enable_operation else PdState.S3
        elif not c.no_quick_stop:
            self._stop_or_go(drive, PdStop.OFF3, PdState.S1)
        elif not c.on:
            self._stop_or_go(drive, PdStop.OFF1, PdState.S2)
        else:
            drive.pd_stop = None
            drive.pd_state = PdState.S4 if c.enable_operation else PdState.S3

    def _stop_or_go(self, drive: SimDrive, stop: PdStop, then: PdState) -> None:
        if drive.pd_state is PdState.S4 and drive.motor.speed != 0.0:
            drive.pd_stop = stop
        else:
            drive.pd_state, drive.pd_stop = then, None
