"""The simulated CiA 402 drive, stepped with an injected clock: every transition of the
standard's table (CiA 402-2 §6.2), fault reset on the edge of bit 7 only, the quick stop
option 0x605A, the fault reaction, the 0x6007 reactions, vl and pv ramps and limits."""

from __future__ import annotations

import pytest

from adapters.canopen.codec.cia402 import (
    TRANSITIONS,
    DeviceCommand,
    State,
    controlword,
    decode_state,
)
from adapters.canopen.sim.drive import (
    EMCY_HEARTBEAT_LOST,
    EMCY_RPDO_TIMEOUT,
    Cia402Drive,
    CommLoss,
    DriveConfig,
    Emcy,
    Mode,
    error_register_of,
)

VL_RUN = 0x70  # vl: ramp function generator enabled, unlocked, reference used


class Rig:
    def __init__(self, **kw: float) -> None:
        self.now = 0.0
        self.drive = Cia402Drive(DriveConfig(max_rpm=1800.0, ramp_time=1.0, **kw), now=0.0)

    def cw(self, word: int) -> list[Emcy]:
        return self.drive.set_controlword(self.now, word)

    def advance(self, seconds: float, step: float = 0.01) -> None:
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.now = min(end, self.now + step)
            self.drive.step(self.now)

    def state(self) -> State:
        state = decode_state(self.drive.statusword)
        assert state is self.drive.state
        return state

    def enable(self, extra: int = VL_RUN) -> None:
        self.cw(controlword(DeviceCommand.SHUTDOWN))
        self.cw(controlword(DeviceCommand.SWITCH_ON))
        self.cw(controlword(DeviceCommand.ENABLE_OPERATION, extra=extra))
        assert self.state() is State.OPERATION_ENABLED

    def run_at(self, rpm: int) -> None:
        self.drive.vl_target = rpm
        self.drive.set_reference_inputs(self.now)


def put_in(rig: Rig, state: State) -> None:
    """Bring the drive into ``state`` by the standard's commands."""
    if state is State.SWITCH_ON_DISABLED:
        return
    if state is State.FAULT:
        rig.drive.inject_fault(rig.now, 0x5000)
        return
    rig.cw(controlword(DeviceCommand.SHUTDOWN))
    if state is State.READY_TO_SWITCH_ON:
        return
    rig.cw(controlword(DeviceCommand.SWITCH_ON))
    if state is State.SWITCHED_ON:
        return
    rig.cw(controlword(DeviceCommand.ENABLE_OPERATION, extra=VL_RUN))
    if state is State.OPERATION_ENABLED:
        return
    rig.drive.quick_stop_option = 6  # stays in quick stop active (transition 16 allowed)
    rig.cw(controlword(DeviceCommand.QUICK_STOP))
    assert state is State.QUICK_STOP_ACTIVE


def test_boots_switch_on_disabled_with_remote_bit() -> None:
    rig = Rig()
    assert rig.state() is State.SWITCH_ON_DISABLED
    assert rig.drive.statusword == 0x0240  # switch on disabled + remote (bit 9)


@pytest.mark.parametrize(("number", "start", "command", "end"), TRANSITIONS)
def test_every_transition_of_the_standard(
    number: int, start: State, command: DeviceCommand, end: State
) -> None:
    rig = Rig()
    put_in(rig, start)
    assert rig.state() is start
    if command is DeviceCommand.FAULT_RESET:
        rig.cw(0)
    rig.cw(controlword(command, extra=VL_RUN))
    expected = end
    if number == 3 and command is DeviceCommand.ENABLE_OPERATION:
        expected = State.OPERATION_ENABLED  # "switch on + enable operation": 3 then 4
    assert rig.state() is expected, f"transition {number}"


def test_fault_reset_acts_on_the_rising_edge_only() -> None:
    rig = Rig()
    rig.cw(0x80)  # bit 7 already high when the fault comes
    rig.drive.inject_fault(rig.now, 0x2310)
    assert rig.state() is State.FAULT
    rig.cw(0x80)  # still high: no edge
    assert rig.state() is State.FAULT
    rig.cw(0x00)
    assert rig.state() is State.FAULT
    out = rig.cw(0x80)
    assert rig.state() is State.SWITCH_ON_DISABLED
    assert out == [Emcy(0, 0)]  # CiA 301: the error reset EMCY
    assert rig.drive.error_code == 0
    assert rig.drive.last_fault == 0x2310


def test_fault_with_a_running_motor_goes_through_fault_reaction() -> None:
    rig = Rig()
    rig.drive.fault_reaction_option = 2  # quick stop ramp
    rig.enable()
    rig.run_at(900)
    rig.advance(1.0)
    out = rig.drive.inject_fault(rig.now, 0x3210)
    assert out == [Emcy(0x3210, 0x05)]  # generic + voltage
    assert rig.state() is State.FAULT_REACTION_ACTIVE
    assert rig.drive.statusword & 0x4F == 0x0F
    rig.advance(0.5)
    assert rig.drive.velocity_actual == 0
    assert rig.state() is State.FAULT
    assert rig.drive.error_register == 0x05


def test_vl_ramps_by_0x6048_and_clamps_by_0x6046() -> None:
    rig = Rig()
    rig.enable()
    rig.drive.vl_accel = (1800, 2)  # 1800 rpm per 2 s
    rig.run_at(900)
    rig.advance(0.5)
    assert rig.drive.velocity_actual == pytest.approx(450, abs=2)
    assert not rig.drive.statusword & 0x0400
    rig.advance(0.6)
    assert rig.drive.velocity_actual == 900
    assert rig.drive.statusword & 0x0400  # target reached
    rig.drive.vl_max = 1000
    rig.run_at(1500)
    rig.advance(3.0)
    assert rig.drive.velocity_actual == 1000
    assert rig.drive.statusword & 0x0800  # internal limit active
    rig.run_at(-500)  # reverse through zero
    rig.advance(5.0)
    assert rig.drive.velocity_actual == -500


def test_vl_controlword_bits_4_to_6() -> None:
    rig = Rig()
    rig.enable(extra=0)  # 0x0F in vl mode: the ramp function generator is off
    rig.run_at(600)
    rig.advance(1.0)
    assert rig.drive.velocity_actual == 0
    rig.cw(0x7F)
    rig.advance(1.0)
    assert rig.drive.velocity_actual == 600
    rig.cw(0x5F)  # bit 5 clear: ramp held
    rig.run_at(1200)
    rig.advance(0.5)
    assert rig.drive.velocity_actual == 600
    rig.cw(0x17F)  # halt (bit 8)
    rig.advance(1.0)
    assert rig.drive.velocity_actual == 0
    assert rig.state() is State.OPERATION_ENABLED


def test_profile_velocity_mode_uses_0x60ff_and_0x6083() -> None:
    rig = Rig()
    rig.drive.mode = Mode.PROFILE_VELOCITY
    rig.drive.profile_accel = 600  # rpm/s
    rig.enable(extra=0)  # pv needs no bits 4-6
    rig.drive.pv_target = 1200
    rig.drive.set_reference_inputs(rig.now)
    rig.advance(1.0)
    assert rig.drive.velocity_actual == pytest.approx(600, abs=7)
    assert not rig.drive.statusword & 0x1000
    rig.advance(1.1)
    assert rig.drive.velocity_actual == 1200


@pytest.mark.parametrize(
    ("option", "stopped_state"),
    [
        (1, State.SWITCH_ON_DISABLED),
        (2, State.SWITCH_ON_DISABLED),
        (5, State.QUICK_STOP_ACTIVE),
        (6, State.QUICK_STOP_ACTIVE),
    ],
)
def test_quick_stop_option_0x605a(option: int, stopped_state: State) -> None:
    rig = Rig(quick_stop_time=0.2)
    rig.drive.quick_stop_option = option
    rig.enable()
    rig.run_at(1800)
    rig.advance(1.1)
    rig.cw(controlword(DeviceCommand.QUICK_STOP))
    assert rig.state() is State.QUICK_STOP_ACTIVE
    rig.advance(0.25)
    if option in (2, 6):  # quick stop ramp: 0.2 s from max
        assert rig.drive.velocity_actual == 0
    else:  # slow down ramp (1 s from max): still turning
        assert rig.drive.velocity_actual > 0
    rig.advance(1.0)
    assert rig.drive.velocity_actual == 0
    assert rig.state() is stopped_state
    if stopped_state is State.QUICK_STOP_ACTIVE:
        rig.cw(controlword(DeviceCommand.ENABLE_OPERATION, extra=VL_RUN))  # 16
        assert rig.state() is State.OPERATION_ENABLED


def test_quick_stop_option_0_coasts() -> None:
    rig = Rig()
    rig.drive.quick_stop_option = 0
    rig.enable()
    rig.run_at(900)
    rig.advance(1.0)
    rig.cw(controlword(DeviceCommand.QUICK_STOP))
    assert rig.state() is State.SWITCH_ON_DISABLED
    assert not rig.drive.motor.enabled


@pytest.mark.parametrize("what", list(CommLoss))
def test_abort_connection_1_faults_with_the_emcy_code(what: CommLoss) -> None:
    rig = Rig()
    rig.enable()
    out = rig.drive.comm_lost(rig.now, what)
    assert rig.state() is State.FAULT
    assert out == [Emcy(int(what), 0x11)]  # generic + communication
    assert int(what) in (EMCY_HEARTBEAT_LOST, EMCY_RPDO_TIMEOUT)


@pytest.mark.parametrize(
    ("option", "state"),
    [
        (0, State.OPERATION_ENABLED),
        (2, State.SWITCH_ON_DISABLED),
        (3, State.QUICK_STOP_ACTIVE),
    ],
)
def test_abort_connection_options(option: int, state: State) -> None:
    rig = Rig()
    rig.drive.abort_connection_option = option
    rig.enable()
    rig.run_at(900)
    rig.advance(1.0)
    assert rig.drive.comm_lost(rig.now, CommLoss.HEARTBEAT) == []
    assert rig.state() is state
    if option == 3:
        rig.advance(1.0)
        assert rig.drive.velocity_actual == 0
        assert rig.state() is State.SWITCH_ON_DISABLED  # option 2 (default 0x605A): 12


def test_keypad_reset_clears_a_fault() -> None:
    rig = Rig()
    rig.drive.inject_fault(rig.now, 0x4310)
    assert rig.drive.error_register == 0x09
    assert rig.drive.keypad_reset(rig.now) == [Emcy(0, 0)]
    assert rig.state() is State.SWITCH_ON_DISABLED


def test_current_and_torque_follow_the_motor() -> None:
    rig = Rig()
    assert rig.drive.current_permille == 0
    rig.enable()
    rig.run_at(1800)
    rig.advance(2.0)
    assert 300 < rig.drive.current_permille <= 1000
    assert rig.drive.torque_permille > 0
    rig.run_at(-1800)
    rig.advance(4.0)
    assert rig.drive.torque_permille < 0


@pytest.mark.parametrize(
    ("code", "register"),
    [
        (0, 0),
        (0x2310, 0x03),
        (0x3210, 0x05),
        (0x4310, 0x09),
        (0x8130, 0x11),
        (0xFF01, 0x81),
        (0x5000, 0x01),
    ],
)
def test_error_register_of_code(code: int, register: int) -> None:
    assert error_register_of(code) == register
