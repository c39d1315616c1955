"""The manufacturer ("WEG") data profile, P0741 = 1, as the simulated drive speaks it.

P0684 (Table 3.3 / 4.3) and P0685 (13 bits, the four direction cases) in, P0680 (Table
3.2 / 4.2) and P0681 out. P0684 bit 0 is a level: a run the network holds applies again
after a fault reset.
"""

from __future__ import annotations

from adapters.profibus.weg import words as w
from adapters.profibus.weg.sim.commands import Commands, NetCommand
from adapters.profibus.weg.sim.dataprofile import SimDrive


class ManufacturerSimWords:
    """P0684 / P0685 taken, P0680 / P0681 sent."""

    def fault_reset(self, drive: SimDrive, word: int) -> bool:
        """P0684 bit 7."""
        return w.ManufacturerControl.decode(word, drive.spec.control_bits).fault_reset

    def take(self, drive: SimDrive, word: int, reference: int) -> None:
        """P0684 (Table 3.3 / 4.3) and P0685."""
        c = w.ManufacturerControl.decode(word, drive.spec.control_bits)
        drive.net = NetCommand(
            run=c.run,
            general_enable=c.general_enable,
            forward=c.forward,
            jog=c.jog,
            remote=c.remote,
            second_ramp=c.second_ramp,
            quick_stop=c.quick_stop,
            reference=reference,
        )
        drive.values[684] = word
        drive.values[685] = w.to_word(reference)

    def status(self, drive: SimDrive) -> int:
        """P0680 (Table 3.2 / 4.2 / 4.2): the model's own bits only."""
        commands = drive.commands
        remote = commands.remote()
        run_cmd = commands.run_command(remote)
        status = w.ManufacturerStatus(
            run_command=run_cmd and not drive.fault,
            fire_mode=drive.fire_mode,
            automatic=drive.pid_automatic,
            quick_stop_active=drive.motor.quick_stopping,
            second_ramp=commands.second_ramp(),
            config_mode=drive.config_mode,
            alarm=drive.alarm != 0,
            running=drive.running,
            general_enable=drive.general_enabled(remote),
            forward=_forward(drive, commands),
            jog=drive.net.jog and drive.motor.enabled,
            remote=remote,
            undervoltage=drive.undervoltage,
            fault=drive.fault != 0,
        )
        return status.encode(drive.spec.status_bits)

    def speed(self, drive: SimDrive) -> int:
        """P0681 (13 bits, 8192 = the synchronous speed)."""
        return drive.param(681)

    def executes_quick_stop(self, drive: SimDrive) -> bool:
        """P0684 bit 6 acts unless the model ignores it with P0202 V/f or VVW.

        CFW700 P0684 bit 6: "This function is not allowed with control types (P0202) V/f
        or VVW": the simulated CFW700 ignores the bit there (the motor keeps the run/stop
        bit's command). The CFW-11 manual only advises against it: it executes it.
        """
        spec = drive.spec
        ramp_only = spec.quick_stop_as_ramp(drive.values.get(202, 0))
        return not (spec.quick_stop_ignored_ramp_only and ramp_only)

    def after_reset(self, net: NetCommand) -> NetCommand:
        """Unchanged: P0684 bit 0 is a level and applies again."""
        return net


def _forward(drive: SimDrive, commands: Commands) -> bool:
    """P0680 bit 10: the direction turning, or the one commanded at standstill."""
    m = drive.motor
    if m.speed != 0.0:
        return m.speed > 0
    if m.reference != 0.0:
        return m.reference > 0
    remote = commands.remote()
    return commands.reference_rpm(remote) >= 0 if remote else True
