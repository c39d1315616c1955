"""CiA 402 facts: statusword decoding, controlword commands, the transition table."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.canopen.codec import cia402
from adapters.canopen.codec.cia402 import Cw, DeviceCommand, State
from adapters.canopen.errors import Cia402DecodeError

# CiA 402-2 statusword table: a typical word for every state.
GOLDEN = [
    (0x0000, State.NOT_READY_TO_SWITCH_ON),
    (0x0250, State.SWITCH_ON_DISABLED),  # voltage enabled, remote
    (0x0231, State.READY_TO_SWITCH_ON),
    (0x0233, State.SWITCHED_ON),
    (0x0637, State.OPERATION_ENABLED),  # target reached
    (0x0217, State.QUICK_STOP_ACTIVE),
    (0x021F, State.FAULT_REACTION_ACTIVE),
    (0x0218, State.FAULT),
    (0x0238, State.FAULT),  # bit 5 does not matter in fault
]


@pytest.mark.parametrize(("word", "state"), GOLDEN)
def test_decode_state(word: int, state: State) -> None:
    assert cia402.decode_state(word) is state


@pytest.mark.parametrize("state", list(State))
def test_statusword_bits_round_trip(state: State) -> None:
    bits = cia402.statusword_bits(state)
    assert bits & ~cia402.SW_STATE_BITS == 0
    assert cia402.decode_state(bits | cia402.SW_REMOTE | cia402.SW_VOLTAGE_ENABLED) is state


@given(st.integers(0, 0xFFFF))
def test_decode_total_or_typed_error(word: int) -> None:
    try:
        state = cia402.decode_state(word)
    except Cia402DecodeError:
        # only the patterns the table leaves out: bit 6 with any of bits 0-3, or
        # bits 0-3 in a combination no state has
        assert word & 0x4F not in (0x00, 0x40, 0x0F, 0x08)
    else:
        assert cia402.decode_state(cia402.statusword_bits(state)) is state


def test_undefined_statusword() -> None:
    with pytest.raises(Cia402DecodeError):
        cia402.decode_state(0x0041)


@pytest.mark.parametrize(
    ("word", "command"),
    [
        (0x0006, DeviceCommand.SHUTDOWN),
        (0x000E, DeviceCommand.SHUTDOWN),
        (0x0007, DeviceCommand.SWITCH_ON),
        (0x000F, DeviceCommand.ENABLE_OPERATION),
        (0x010F, DeviceCommand.ENABLE_OPERATION),  # halt does not change the command
        (0x0000, DeviceCommand.DISABLE_VOLTAGE),
        (0x0004, DeviceCommand.DISABLE_VOLTAGE),
        (0x000D, DeviceCommand.DISABLE_VOLTAGE),
        (0x0002, DeviceCommand.QUICK_STOP),
        (0x000B, DeviceCommand.QUICK_STOP),
        (0x0080, DeviceCommand.FAULT_RESET),
        (0x008F, DeviceCommand.FAULT_RESET),
    ],
)
def test_device_command(word: int, command: DeviceCommand) -> None:
    assert cia402.device_command(word) is command


def test_controlword_constants() -> None:
    assert (Cw.SHUTDOWN, Cw.SWITCH_ON, Cw.ENABLE_OPERATION) == (0x06, 0x07, 0x0F)
    assert int(Cw.DISABLE_OPERATION) == int(Cw.SWITCH_ON) == 0x07
    assert (Cw.QUICK_STOP, Cw.DISABLE_VOLTAGE, Cw.FAULT_RESET_BIT, Cw.HALT_BIT) == (
        2,
        0,
        0x80,
        0x100,
    )
    assert cia402.controlword(DeviceCommand.ENABLE_OPERATION, halt=True) == 0x10F
    for command in DeviceCommand:
        assert cia402.device_command(cia402.controlword(command)) is command
    assert cia402.device_command(0x10000) is None


@pytest.mark.parametrize(
    ("state", "command", "after"),
    [
        (State.SWITCH_ON_DISABLED, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),  # 2
        (State.READY_TO_SWITCH_ON, DeviceCommand.SWITCH_ON, State.SWITCHED_ON),  # 3
        (State.SWITCHED_ON, DeviceCommand.ENABLE_OPERATION, State.OPERATION_ENABLED),  # 4
        (State.OPERATION_ENABLED, DeviceCommand.SWITCH_ON, State.SWITCHED_ON),  # 5
        (State.SWITCHED_ON, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),  # 6
        (State.READY_TO_SWITCH_ON, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),  # 7
        (State.OPERATION_ENABLED, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),  # 8
        (State.OPERATION_ENABLED, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),  # 9
        (State.SWITCHED_ON, DeviceCommand.QUICK_STOP, State.SWITCH_ON_DISABLED),  # 10
        (State.OPERATION_ENABLED, DeviceCommand.QUICK_STOP, State.QUICK_STOP_ACTIVE),  # 11
        (State.QUICK_STOP_ACTIVE, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),  # 12
        (State.FAULT, DeviceCommand.FAULT_RESET, State.SWITCH_ON_DISABLED),  # 15
        (State.QUICK_STOP_ACTIVE, DeviceCommand.ENABLE_OPERATION, State.OPERATION_ENABLED),  # 16
    ],
)
def test_transitions(state: State, command: DeviceCommand, after: State) -> None:
    assert cia402.next_state(state, command) is after


def test_no_transition() -> None:
    assert cia402.next_state(State.SWITCH_ON_DISABLED, DeviceCommand.ENABLE_OPERATION) is None
    assert cia402.next_state(State.FAULT, DeviceCommand.ENABLE_OPERATION) is None


def test_option_texts() -> None:
    assert (
        cia402.quick_stop_option_text(2) == "slow down on quick stop ramp, then switch on disabled"
    )
    assert cia402.quick_stop_option_text(-3) == "manufacturer specific (-3)"
    assert cia402.quick_stop_option_text(9) == "reserved (9)"
    assert cia402.quick_stop_stays(6) and not cia402.quick_stop_stays(2)
    assert cia402.abort_connection_option_text(1) == "fault signal"
    assert cia402.abort_connection_option_text(3) == "quick stop command"
