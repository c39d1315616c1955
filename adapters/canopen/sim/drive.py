"""The simulated CiA 402 velocity drive behind the CANopen node: sans-IO, stepped clock.

The device side of the CiA 402 state machine (CiA 402-2 section 7.3: states, transitions
0-16, the controlword commands of table 8-1; a fault reset on the rising edge of
controlword bit 7 only), the option codes 0x605A (quick stop), 0x605B (shutdown),
0x605C (disable operation), 0x605E (fault reaction) and 0x6007 (abort connection), the
vl mode (0x6042 target, 0x6043 demand, 0x6044 actual, 0x6046 limits, 0x6048/0x6049
ramps) and the profile velocity mode (0x60FF target, 0x606C actual, 0x6083/0x6084
ramps), over the shared motor physics (:mod:`gateway.sim.motor`).

Velocities are in rpm in both modes (the test EDS's unit). The node
(:mod:`adapters.canopen.sim.node`) writes the inputs and reads the outputs under its
lock; :meth:`Cia402Drive.step` advances the motor to ``now``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from adapters.canopen.codec.cia402 import (
    MODE_PROFILE_VELOCITY,
    MODE_VELOCITY,
    SW_INTERNAL_LIMIT,
    SW_REMOTE,
    SW_TARGET_REACHED,
    Cw,
    DeviceCommand,
    State,
    device_command,
    quick_stop_stays,
    statusword_bits,
)
from gateway.sim import Motor, MotorParams

FAULT_RESET_BIT = int(Cw.FAULT_RESET_BIT)
CW_HALT = int(Cw.HALT_BIT)
SW_PV_SPEED_ZERO = 1 << 12  # CiA 402-2 profile velocity mode: statusword bit 12, speed = 0
# CiA 402-2 vl mode: controlword bits 4-6 (ramp function generator)
CW_VL_RFG_ENABLE = 1 << 4  # vl: 0 = ramp output to zero
CW_VL_RFG_UNLOCK = 1 << 5  # vl: 0 = hold the ramp output
CW_VL_USE_REF = 1 << 6  # vl: 0 = reference zero

# CiA 301 7.2.7.1 / CiA 402 error codes the simulator raises on its own
EMCY_HEARTBEAT_LOST = 0x8130  # life guard or heartbeat error
EMCY_RPDO_TIMEOUT = 0x8250  # RPDO timeout
TARGET_WINDOW_RPM = 1.0  # |actual - target| within which "target reached" shows


class Mode(IntEnum):
    """0x6060 modes of operation this drive supports (0x6502 bits 1 and 2)."""

    VELOCITY = MODE_VELOCITY  # vl
    PROFILE_VELOCITY = MODE_PROFILE_VELOCITY  # pv


class CommLoss(IntEnum):
    """What the node saw go silent (the 0x6007 reaction follows either way)."""

    HEARTBEAT = EMCY_HEARTBEAT_LOST
    RPDO = EMCY_RPDO_TIMEOUT


class StopKind(IntEnum):
    """How the motor is brought down (the option codes' values)."""

    COAST = 0  # disable drive function
    RAMP = 1  # slow down ramp (0x6049 / 0x6084)
    QUICK = 2  # quick stop ramp


@dataclass(frozen=True, slots=True)
class DriveConfig:
    max_rpm: float = 1800.0  # 0x6046:2 default and the speed the ramp times refer to
    ramp_time: float = 5.0  # s from 0 to max_rpm (0x6048/0x6049, 0x6083/0x6084 at boot)
    quick_stop_time: float = 0.5  # s from max_rpm to 0 on the quick stop ramp
    rated_current: float = 10.0  # A (0x6075 = rated_current * 1000 mA at boot)


@dataclass(frozen=True, slots=True)
class Emcy:
    """An EMCY the node is to send: the error code (0 = error reset) and 0x1001."""

    code: int
    register: int


def error_register_of(code: int) -> int:
    """0x1001 for an error code (CiA 301 7.5.2.2: bit 0 generic, 1 current, 2 voltage,
    3 temperature, 4 communication, 5 device profile specific, 7 manufacturer)."""
    if code == 0:
        return 0
    reg = 0x01
    group = code >> 12
    if code >= 0xFF00:
        reg |= 0x80
    elif group == 0x2:
        reg |= 0x02
    elif group == 0x3:
        reg |= 0x04
    elif group == 0x4:
        reg |= 0x08
    elif (code >> 8) in (0x81, 0x82):
        reg |= 0x10
    return reg


class Cia402Drive:
    """One simulated CiA 402 drive: option codes and mode in, statusword and actuals out."""

    def __init__(self, config: DriveConfig | None = None, now: float = 0.0) -> None:
        self.config = config or DriveConfig()
        c = self.config
        self.motor = Motor(
            MotorParams(
                rated_rpm=c.max_rpm,
                accel_time=c.ramp_time,
                decel_time=c.ramp_time,
                quick_stop_time=c.quick_stop_time,
                rated_current=c.rated_current,
            )
        )
        self.last = now
        self.state = State.SWITCH_ON_DISABLED  # transitions 0 and 1 done at boot
        self.controlword = 0
        self.mode = Mode.VELOCITY
        self.vl_target = 0
        self.pv_target = 0
        self.vl_min = 0
        self.vl_max = round(c.max_rpm)
        # 0x6048/0x6049: delta speed (rpm) per delta time (s)
        self.vl_accel = (round(c.max_rpm), max(round(c.ramp_time), 0))
        self.vl_decel = (round(c.max_rpm), max(round(c.ramp_time), 0))
        rate = round(c.max_rpm / c.ramp_time) if c.ramp_time > 0 else 1_000_000
        self.profile_accel = rate  # rpm/s
        self.profile_decel = rate
        self.quick_stop_option = 2
        self.shutdown_option = 0
        self.disable_operation_option = 1
        self.fault_reaction_option = 0
        self.abort_connection_option = 1
        self.rated_current_ma = round(c.rated_current * 1000)
        self.error_code = 0
        self.last_fault = 0  # 0x2000:3: the last fault code, kept after a reset
        self.limited = False
        self._stopping_to_off = False  # ramping down, the output goes off at zero speed

    # ------------------------------------------------------------ outputs

    @property
    def statusword(self) -> int:
        sw = statusword_bits(self.state) | SW_REMOTE
        if self._target_reached():
            sw |= SW_TARGET_REACHED
        if self.limited and self.state is State.OPERATION_ENABLED:
            sw |= SW_INTERNAL_LIMIT
        if self.mode is Mode.PROFILE_VELOCITY and self.motor.speed == 0.0:
            sw |= SW_PV_SPEED_ZERO
        return sw

    @property
    def error_register(self) -> int:
        return error_register_of(self.error_code)

    @property
    def velocity_actual(self) -> int:
        return round(self.motor.speed)

    @property
    def velocity_demand(self) -> int:
        return round(self.motor.reference)

    @property
    def current_permille(self) -> int:
        """0x6078: current in per mille of the motor rated current (0x6075)."""
        rated = self.rated_current_ma / 1000.0
        return _i16(round(self.motor.current() / rated * 1000)) if rated > 0 else 0

    @property
    def torque_permille(self) -> int:
        """0x6077: the current's torque-producing part in per mille, signed by direction."""
        p = self.motor.params
        amps = self.motor.current()
        active = math.sqrt(max(amps**2 - p.magnetising_current**2, 0.0))
        full = math.sqrt(max(p.rated_current**2 - p.magnetising_current**2, 1e-9))
        sign = -1 if self.motor.speed < 0 else 1
        return _i16(sign * round(active / full * 1000))

    def _target_reached(self) -> bool:
        if self.state is State.OPERATION_ENABLED:
            if self.controlword & CW_HALT:
                return self.motor.speed == 0.0
            return abs(self.motor.speed - self._reference()) <= TARGET_WINDOW_RPM
        if self.state is State.QUICK_STOP_ACTIVE:
            return self.motor.speed == 0.0
        return False

    # ------------------------------------------------------------ inputs

    def set_controlword(self, now: float, cw: int) -> list[Emcy]:
        """A new controlword (SDO or RPDO): the command of CiA 402-2 table 8-1."""
        self.step(now)
        previous, self.controlword = self.controlword, cw & 0xFFFF
        out: list[Emcy] = []
        rising_reset = bool(cw & FAULT_RESET_BIT) and not previous & FAULT_RESET_BIT
        if self.state is State.FAULT:
            if rising_reset:  # transition 15, on the edge only
                out += self._clear_fault()
            return out
        if self.state is State.FAULT_REACTION_ACTIVE:
            return out
        self._apply(device_command(cw))
        self._drive_motor()
        return out

    def _apply(self, command: DeviceCommand | None) -> None:
        s = self.state
        C = DeviceCommand
        if command is None:
            return
        if s is State.SWITCH_ON_DISABLED:
            if command is C.SHUTDOWN:
                self.state = State.READY_TO_SWITCH_ON  # 2
        elif s is State.READY_TO_SWITCH_ON:
            if command is C.SWITCH_ON:
                self.state = State.SWITCHED_ON  # 3
            elif command is C.ENABLE_OPERATION:
                self.state = State.OPERATION_ENABLED  # 3 + 4
            elif command in (C.DISABLE_VOLTAGE, C.QUICK_STOP):
                self.state = State.SWITCH_ON_DISABLED  # 7
        elif s is State.SWITCHED_ON:
            if command is C.ENABLE_OPERATION:
                self.state = State.OPERATION_ENABLED  # 4
            elif command is C.SHUTDOWN:
                self.state = State.READY_TO_SWITCH_ON  # 6
            elif command in (C.DISABLE_VOLTAGE, C.QUICK_STOP):
                self.state = State.SWITCH_ON_DISABLED  # 10
        elif s is State.OPERATION_ENABLED:
            if command is C.SWITCH_ON:  # "disable operation" in this state
                self._stop(StopKind(min(self.disable_operation_option, 1)))
                self.state = State.SWITCHED_ON  # 5
            elif command is C.SHUTDOWN:
                self._stop(StopKind(min(self.shutdown_option, 1)))
                self.state = State.READY_TO_SWITCH_ON  # 8
            elif command is C.DISABLE_VOLTAGE:
                self._stop(StopKind.COAST)
                self.state = State.SWITCH_ON_DISABLED  # 9
            elif command is C.QUICK_STOP:
                self._quick_stop()  # 11
        elif s is State.QUICK_STOP_ACTIVE:
            if command is C.DISABLE_VOLTAGE:
                self._stop(StopKind.COAST)
                self.state = State.SWITCH_ON_DISABLED  # 12
            elif command is C.ENABLE_OPERATION and quick_stop_stays(self.quick_stop_option):
                self.state = State.OPERATION_ENABLED  # 16
                self.motor.quick_stopping = False

    def _quick_stop(self) -> None:
        """Transition 11 with the 0x605A option (CiA 402-2 6.5.3)."""
        option = self.quick_stop_option
        kind = {0: StopKind.COAST, 1: StopKind.RAMP, 5: StopKind.RAMP}.get(option, StopKind.QUICK)
        if option == 0:
            self._stop(StopKind.COAST)
            self.state = State.SWITCH_ON_DISABLED  # disable drive function, then 12
            return
        self.state = State.QUICK_STOP_ACTIVE
        self._stop(kind, to_off=False)

    def _stop(self, kind: StopKind, *, to_off: bool = True) -> None:
        m = self.motor
        if kind is StopKind.COAST:
            m.coast()
            self._stopping_to_off = False
            return
        self._use_ramps()
        m.command(True, 0.0)
        if kind is StopKind.QUICK:
            m.quick_stop()
        self._stopping_to_off = to_off

    def inject_fault(self, now: float, code: int) -> list[Emcy]:
        """A drive fault (transition 13): 0x603F, 0x1001 and an EMCY; the 0x605E reaction."""
        self.step(now)
        if self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            return []
        self.error_code = self.last_fault = code & 0xFFFF
        option = self.fault_reaction_option
        kind = StopKind.COAST if option <= 0 else StopKind(min(option, 2))
        if self.motor.speed == 0.0 or kind is StopKind.COAST or not self.motor.enabled:
            self.motor.coast()
            self.state = State.FAULT  # 13 + 14 at once: nothing to bring down
        else:
            self.state = State.FAULT_REACTION_ACTIVE
            self._stop(kind)
        return [Emcy(self.error_code, self.error_register)]

    def comm_lost(self, now: float, what: CommLoss) -> list[Emcy]:
        """The 0x6007 reaction (CiA 402-2 6.4.5): 0 none, 1 fault, 2 disable voltage,
        3 quick stop."""
        option = self.abort_connection_option
        if option == 1:
            return self.inject_fault(now, int(what))
        self.step(now)
        if option == 2:
            self._apply(DeviceCommand.DISABLE_VOLTAGE)
        elif option == 3:
            self._apply(DeviceCommand.QUICK_STOP)
        self._drive_motor()
        return []

    def keypad_reset(self, now: float) -> list[Emcy]:
        """The reset key of the drive's own panel: clears a fault as transition 15 does."""
        self.step(now)
        if self.state is State.FAULT:
            return self._clear_fault()
        return []

    def _clear_fault(self) -> list[Emcy]:
        self.state = State.SWITCH_ON_DISABLED  # 15
        self.error_code = 0
        self.motor.coast()
        self._stopping_to_off = False
        return [Emcy(0, 0)]  # CiA 301 7.2.7.1: error reset

    # ------------------------------------------------------------ stepping

    def set_reference_inputs(self, now: float) -> None:
        """After a write to a target, mode, limit or ramp object: apply it now."""
        self.step(now)
        self._drive_motor()

    def step(self, now: float) -> None:
        dt = now - self.last
        if dt > 0:
            self.motor.advance(dt)
            self.last = now
        m = self.motor
        if self._stopping_to_off and m.speed == 0.0:
            m.coast()
            self._stopping_to_off = False
        if self.state is State.FAULT_REACTION_ACTIVE and m.speed == 0.0:
            m.coast()
            self.state = State.FAULT  # 14
        elif (
            self.state is State.QUICK_STOP_ACTIVE
            and m.speed == 0.0
            and not quick_stop_stays(self.quick_stop_option)
        ):
            m.coast()
            self.state = State.SWITCH_ON_DISABLED  # 12, automatic for options 1-4
        if self.state is State.OPERATION_ENABLED:
            self._drive_motor()

    def _reference(self) -> float:
        """The target the ramp heads for in OPERATION ENABLED, limits applied."""
        cw = self.controlword
        self.limited = False
        if cw & CW_HALT:
            return 0.0
        if self.mode is Mode.VELOCITY:
            if not cw & CW_VL_RFG_ENABLE or not cw & CW_VL_USE_REF:
                return 0.0
            target = float(self.vl_target)
            sign = -1.0 if target < 0 else 1.0
            amount = abs(target)
            if amount and amount < self.vl_min:
                amount, self.limited = float(self.vl_min), True
            if amount > self.vl_max:
                amount, self.limited = float(self.vl_max), True
            return sign * amount
        target = float(self.pv_target)
        limit = self.config.max_rpm
        if abs(target) > limit:
            self.limited = True
            return math.copysign(limit, target)
        return target

    def _use_ramps(self) -> None:
        m, top = self.motor, self.motor.params.rated_rpm
        if self.mode is Mode.VELOCITY:
            m.accel_time = _ramp_time(top, *self.vl_accel)
            m.decel_time = _ramp_time(top, *self.vl_decel)
        else:
            m.accel_time = top / self.profile_accel if self.profile_accel else 0.0
            m.decel_time = top / self.profile_decel if self.profile_decel else 0.0

    def _drive_motor(self) -> None:
        if self.state is not State.OPERATION_ENABLED:
            return
        self._stopping_to_off = False
        self._use_ramps()
        m = self.motor
        if self.mode is Mode.VELOCITY and not self.controlword & CW_VL_RFG_UNLOCK:
            m.command(True, m.speed if m.enabled else 0.0)  # ramp held where it is
            return
        m.command(True, self._reference())


def _ramp_time(top: float, delta_speed: int, delta_time: int) -> float:
    """0x6048/0x6049 (delta speed per delta time) as the time from 0 to ``top`` rpm."""
    if delta_speed <= 0:
        return 0.0
    return top * delta_time / delta_speed


def _i16(value: int) -> int:
    return max(-0x8000, min(0x7FFF, value))
