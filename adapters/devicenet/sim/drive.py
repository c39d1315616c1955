"""The simulated CFW-08 drive behind the network: commands in, status out, motor physics.

Sans-IO: :meth:`SimDrive.advance` moves the shared motor model (gateway.sim) by ``dt``.
Command sources follow the seed: P220 chooses who selects the local or remote situation
(seed 4.2.1: always local or remote, the keypad, DI, or DeviceNet), P229 and P230 where
the commands come from in each situation (seed 4.2.4, 4.2.5: 2 = DeviceNet) and P231
the direction (seed 4.2.6: 0 clockwise, 1 counter-clockwise, 2 the commands). With P220
= 5/6 (DeviceNet) the master selects the situation: assembly 21 NetCtrl (seed 3.1.2) or
Control Supervisor NetCtrl (table 16), assembly 100 Local/Remoto (table 7); assembly 20
has no such bit and leaves the default of P220 (6: remote). The simulated drive is
commissioned for DeviceNet (P220 = 6, P229 = 0 keypad, P230 = 2 DeviceNet, P222 = 5):
the seed's factory values (P220 = 2, P230 = 1) would ignore the network. Without
network control the simulated local side (keypad, terminals) asks for nothing: the
motor ramps to a stop. P313 = 3 "go to local mode" (seed 4.1.3) holds the drive local
until the master selects remote again (NetCtrl or Local/Remoto set; on 20/70, which
has no such bit, until a reset or power cycle): a decision, the seed is silent.
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.devicenet.cfw08 import (
    ASSEMBLY_SIZE,
    AssemblyPair,
    DriveStateCode,
    In70,
    In71,
    In150,
    InputAssembly,
    Out20,
    Out21,
    Out100,
    counts_to_rpm,
    decode_output,
    rpm_to_counts,
)
from adapters.devicenet.cfw08.objects import P070, P081, P313, P710
from adapters.devicenet.errors import AssemblyDecodeError
from adapters.devicenet.sim.params import SIM_PARAMETERS
from gateway.sim import Motor, MotorParams

AT_REFERENCE_RPM = 30.0  # seed 3.1.1: within 1 Hz (30 rpm for a 4-pole motor at 60 Hz)
P313_RAMP, P313_GENERAL_DISABLE, P313_NONE, P313_LOCAL = 0, 1, 2, 3  # seed 4.1.3
E36_IDLE, E37_TIMEOUT = 36, 37  # seed 2.2
SPEED_WORD_MAX = 0x7FFF
P220, P221, P222, P229, P230, P231 = 220, 221, 222, 229, 230, 231  # seed 4.2
P220_LOCAL, P220_REMOTE, P220_HMI_LOCAL, P220_HMI_REMOTE, P220_DI = 0, 1, 2, 3, 4
P220_NET_REMOTE = 6  # seed 4.2.1: 5 = DeviceNet (default local), 6 = (default remote)
COMMANDS_DEVICENET = 2  # seed 4.2.4, 4.2.5
DIRECTION_CW, DIRECTION_CCW = 0, 1  # seed 4.2.6 (2 = from the commands)
# the simulated drive's commissioning for DeviceNet (see the module doc)
COMMISSIONED: dict[int, int] = {P220: 6, P221: 0, P222: 5, P229: 0, P230: 2, P231: 2}


@dataclass(frozen=True, slots=True)
class SimDriveConfig:
    mac: int = 63
    p710: int = 1  # seed 4.1.8: 0 = 20/70, 1 = 21/71, 2 = 100/150 (in force at power-up)
    # P710 as stored once powered up, changed (keypad, network) and not yet applied: it
    # takes effect at the next reset or power cycle (seed 4.1.8 note). None: as p710.
    p710_stored: int | None = None
    p313: int = 2  # seed 4.1.3 default: no action
    max_rpm: float = 1800.0
    ramp_time: float = 5.0  # s, written to P100/P101 (0.1 s units)
    weg_speed_scale: int = 8192
    jog_rpm: float = 150.0
    rated_current: float = 10.0
    undervoltage: bool = False


class SimDrive:
    """One simulated CFW-08: parameters, command bits, motor, faults."""

    def __init__(self, config: SimDriveConfig) -> None:
        self.config = config
        self.params: dict[int, int] = {
            n: (p.default if p.default is not None else 0) for n, p in SIM_PARAMETERS.items()
        }
        ramp = max(1, min(9990, round(config.ramp_time * 10)))
        self.params.update({700: 2, 701: config.mac, 710: config.p710, 313: config.p313})
        self.params.update({100: ramp, 101: ramp, 402: round(config.max_rpm), 70: 2})
        self.params.update(COMMISSIONED)
        self.hmi_remote = False  # the keypad's local/remote key (P220 = 2/3)
        self.di_remote = False  # the DI chosen by P220 = 4 (not wired in the simulator)
        self.forced_local = False  # P313 = 3 acted (seed 4.1.3)
        self.motor = Motor(
            MotorParams(
                rated_rpm=config.max_rpm,
                accel_time=ramp / 10,
                decel_time=ramp / 10,
                rated_current=config.rated_current,
            )
        )
        self.pair = AssemblyPair.from_p710(config.p710) or AssemblyPair.BASIC
        self._p710_unapplied = config.p710_stored
        self.fault_code: int | None = None
        self.comm_error: int | None = None
        self.idle = True  # no run-mode I/O from the master yet (P081)
        self.bad_outputs = 0
        self._last_output: bytes | None = None
        self._input_cache: tuple[object, bytes] | None = None
        self.reset_requested = False
        self._clear_commands()
        self._situation_defaults()

    def _clear_commands(self) -> None:
        self._last_output = None
        self.run_fwd = False
        self.run_rev = False
        self.net_ctrl = False
        self.net_ref = False
        self.ramp_enable = False
        self.general_enable = False
        self.reverse = False
        self.jog = False
        self.remote = False
        self.speed_ref_rpm = 0.0
        self.coasting = False
        self._reset_bit = False

    # ------------------------------------------------------------ life cycle

    def power_up(self) -> None:
        """After power-on or a reset: P710 takes effect (seed 4.1.8), commands and any
        fault cleared (the simulator's faults have no condition that outlives a restart)."""
        self.pair = AssemblyPair.from_p710(self.params[P710]) or AssemblyPair.BASIC
        # The pair in force changes only here: a P710 written while powered waits for the
        # next reset or power cycle (config p710_stored: one written and not yet reset).
        if self._p710_unapplied is not None:
            self.params[P710], self._p710_unapplied = self._p710_unapplied, None
        self._clear_commands()
        self.fault_code = None
        self.comm_error = None
        self.idle = True
        self._situation_defaults()
        self.motor.coast()

    def trip(self, code: int) -> None:
        """Fault injection: the drive trips with error ``code`` and coasts."""
        self.fault_code = code
        self.motor.coast()

    def fault_reset(self) -> bool:
        """A reset of a faulted drive (seed 3.4); True if there was a fault to reset."""
        if self.fault_code is None:
            return False
        self.fault_code = None
        self.reset_requested = True
        return True

    # ------------------------------------------------------------ network inputs

    def _situation_defaults(self) -> None:
        """At power-up the situation is P220's default (seed 4.2.1: "default: local" or
        "default: remoto"), until the keypad or the master selects another."""
        self.forced_local = False
        self.hmi_remote = self.params[P220] == P220_HMI_REMOTE
        self.net_ctrl = self.remote = self.params[P220] == P220_NET_REMOTE

    @property
    def situation_remote(self) -> bool:
        """The drive is in its remote situation (seed 4.2.1, P220)."""
        if self.forced_local:
            return False
        p220 = self.params[P220]
        fixed = {P220_LOCAL: False, P220_REMOTE: True, P220_DI: self.di_remote}
        if p220 in fixed:
            return fixed[p220]
        if p220 in (P220_HMI_LOCAL, P220_HMI_REMOTE):
            return self.hmi_remote
        if self.pair is AssemblyPair.EXTENDED:
            return self.net_ctrl
        if self.pair is AssemblyPair.WEG:
            return self.remote
        return p220 == P220_NET_REMOTE  # 20/70 has no bit: P220's default

    @property
    def network_control(self) -> bool:
        """The drive takes its run/stop commands from DeviceNet (seed 4.2.4, 4.2.5)."""
        source = self.params[P230] if self.situation_remote else self.params[P229]
        return source == COMMANDS_DEVICENET

    def local_remote_key(self) -> None:
        """The keypad's local/remote key (acts with P220 = 2 or 3, seed 4.2.1)."""
        self.hmi_remote = not self.hmi_remote

    def apply_output(self, data: bytes) -> None:
        """Consume the master's I/O data: empty = idle (P081 = 1, seed 4.1.2)."""
        if not data:
            if not self.idle:
                self.idle = True
                self.comm_loss(E36_IDLE)
            return
        if data == self._last_output and not self.idle:
            return  # the same command again: nothing changes
        try:
            assembly = decode_output(self.pair.output_instance, data)
        except AssemblyDecodeError:
            self.bad_outputs += 1
            return
        self._last_output = data
        self.idle = False
        self.comm_error = None
        self.coasting = False
        self._apply(assembly)

    def _apply(self, a: Out20 | Out21 | Out100) -> None:
        if isinstance(a, Out20):
            self.run_fwd, self.run_rev = a.run_fwd, False
            self.speed_ref_rpm = float(a.speed_rpm)
            self._reset_edge(a.fault_reset)
        elif isinstance(a, Out21):
            self.run_fwd, self.run_rev = a.run_fwd, a.run_rev
            self.net_ctrl, self.net_ref = a.net_ctrl, a.net_ref
            self.forced_local = self.forced_local and not a.net_ctrl
            self.speed_ref_rpm = float(a.speed_rpm)
            self._reset_edge(a.fault_reset)
        else:
            self.ramp_enable, self.general_enable = a.ramp_enable, a.general_enable
            self.reverse, self.jog, self.remote = a.reverse, a.jog, a.remote
            self.forced_local = self.forced_local and not a.remote
            c = self.config
            self.speed_ref_rpm = counts_to_rpm(a.speed_counts, c.max_rpm, c.weg_speed_scale)
            self._reset_edge(a.fault_reset)

    def _reset_edge(self, bit: bool) -> None:
        """Fault reset is a 0 -> 1 transition (seed 3.1.2, table 7)."""
        if bit and not self._reset_bit:
            self.fault_reset()
        self._reset_bit = bit

    def forget_output(self) -> None:
        """The next I/O data is applied even if it repeats the last (commands changed)."""
        self._last_output = None

    def set_fault_reset_attribute(self, bit: bool) -> None:
        """Control Supervisor attribute 12: 0 -> 1 resets (seed table 16)."""
        self._reset_edge(bit)

    def comm_loss(self, code: int) -> None:
        """I/O timeout (E37) or master idle (E36): the P313 action (seed 4.1.3), only when
        the drive takes its commands from DeviceNet."""
        self.comm_error = code
        self.forget_output()
        if not self.network_control:
            return
        action = self.params[P313]
        if action == P313_RAMP:
            self.run_fwd = self.run_rev = self.ramp_enable = self.jog = False
        elif action == P313_GENERAL_DISABLE:
            self.run_fwd = self.run_rev = self.ramp_enable = self.jog = False
            self.general_enable = False
            self.coasting = True
        elif action == P313_LOCAL:
            self.net_ctrl = self.remote = False
            self.forced_local = True

    # ------------------------------------------------------------ physics

    def _demand(self) -> tuple[bool, bool, float]:
        """(run, reverse, reference rpm) the drive follows now."""
        if not self.network_control:
            return False, False, 0.0
        if self.pair is AssemblyPair.WEG:
            reverse = self._direction(self.reverse)
            if self.jog and self.general_enable:
                return True, reverse, self.config.jog_rpm
            return self.general_enable and self.ramp_enable, reverse, self.speed_ref_rpm
        run = self.run_fwd != self.run_rev and (self.run_fwd or self.run_rev)
        ref = self.speed_ref_rpm
        if self.pair is AssemblyPair.EXTENDED and not self.net_ref:
            ref = 0.0  # local reference: the simulated keypad gives none
        return run, self._direction(self.run_rev), ref

    def _direction(self, commanded_reverse: bool) -> bool:
        """P231 (seed 4.2.6): always clockwise, always counter-clockwise, or commanded."""
        forced = {DIRECTION_CW: False, DIRECTION_CCW: True}
        return forced.get(self.params[P231], commanded_reverse)

    @property
    def coast_requested(self) -> bool:
        if self.coasting:
            return True
        return self.pair is AssemblyPair.WEG and self.network_control and not self.general_enable

    def advance(self, dt: float) -> None:
        m = self.motor
        m.accel_time = self.params[100] / 10
        m.decel_time = self.params[101] / 10
        if self.fault_code is not None or self.coast_requested:
            m.coast()
        else:
            run, reverse, rpm = self._demand()
            rpm = min(rpm, self.config.max_rpm)
            if run:
                m.command(True, -rpm if reverse else rpm)
            else:
                m.command(m.speed != 0.0, 0.0)
        m.advance(dt)
        if m.enabled and m.reference == 0.0 and m.speed == 0.0:
            m.command(False, 0.0)
        self.params[3] = min(9999, round(m.current() * 10))
        self.params[P081] = 1 if self.idle else 0
        self.params[P070] = 2

    # ------------------------------------------------------------ status out

    @property
    def running_forward(self) -> bool:
        m = self.motor
        return m.running and (m.speed > 0 or (m.speed == 0 and m.reference > 0))

    @property
    def running_reverse(self) -> bool:
        m = self.motor
        return m.running and (m.speed < 0 or (m.speed == 0 and m.reference < 0))

    @property
    def state(self) -> DriveStateCode:
        """Control Supervisor state (seed table 16, 3.1.1)."""
        if self.fault_code is not None:
            return DriveStateCode.FAULT_STOP if self.motor.speed else DriveStateCode.FAULTED
        if self.motor.running:
            run, _, _ = self._demand()
            return DriveStateCode.ENABLED if run else DriveStateCode.STOPPING
        return DriveStateCode.READY

    @property
    def at_reference(self) -> bool:
        m = self.motor
        return m.running and abs(m.speed - m.reference) <= AT_REFERENCE_RPM

    @property
    def speed_word(self) -> int:
        return min(round(abs(self.motor.speed)), SPEED_WORD_MAX)

    def input_assembly(self, instance: int | None = None) -> InputAssembly:
        """The status in input assembly ``instance`` (default: the active pair's)."""
        instance = instance or self.pair.input_instance
        faulted = self.fault_code is not None
        if instance == 70:
            return In70(faulted, self.running_forward, self.speed_word)
        if instance == 71:
            state = self.state
            return In71(
                faulted=faulted,
                warning=False,  # seed 3.1.1: no function on the CFW-08
                running1=self.running_forward,
                running2=self.running_reverse,
                ready=state
                in (DriveStateCode.READY, DriveStateCode.ENABLED, DriveStateCode.STOPPING),
                ctrl_from_net=self.network_control,
                ref_from_net=self.pair is AssemblyPair.BASIC or self.net_ref,
                at_reference=self.at_reference,
                drive_state=state,
                speed_rpm=self.speed_word,
            )
        m, c = self.motor, self.config
        return In150(
            error_code=self.fault_code or 0,
            ramp_enabled=self.ramp_enable,
            general_enabled=self.general_enable and not self.coasting,
            forward=m.speed > 0 or (m.speed == 0 and not self.reverse),
            jog=self.jog,
            remote=self.situation_remote,
            undervoltage=c.undervoltage,
            error=faulted,
            speed_counts=rpm_to_counts(min(abs(m.speed), c.max_rpm), c.max_rpm, c.weg_speed_scale),
        )

    def _input_key(self, instance: int) -> object:
        m = self.motor
        return (
            instance,
            self.fault_code,
            m.speed,
            m.reference,
            m.enabled,
            self.net_ctrl,
            self.net_ref,
            self.ramp_enable,
            self.general_enable,
            self.reverse,
            self.jog,
            self.remote,
            self.coasting,
            self.run_fwd,
            self.run_rev,
            self.forced_local,
            self.hmi_remote,
            tuple(self.params[n] for n in COMMISSIONED),
        )

    def input_data(self, instance: int | None = None) -> bytes:
        """The encoded input assembly; recomputed only when the drive's state moved."""
        instance = instance or self.pair.input_instance
        key = self._input_key(instance)
        cached = self._input_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        data = self.input_assembly(instance).encode()
        if len(data) != ASSEMBLY_SIZE:
            raise AssemblyDecodeError("input assembly of the wrong size", data)
        self._input_cache = (key, data)
        return data
