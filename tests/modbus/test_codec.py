"""Sans-IO parts: register types, command word, edge rules, write decoding, MBAP, access policy."""

from __future__ import annotations

import contextlib
import ipaddress
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.errors import FrameDecodeError
from gateway.hub import DrivePolicy
from gateway.modbus.command import (
    UNKNOWN_CLIENT_WORD,
    ClientMemory,
    CommandWord,
    HoldingWrite,
    build_command,
)
from gateway.modbus.health import parse_version
from gateway.modbus.map import (
    DRIVE_INPUTS,
    DriveView,
    HoldingView,
    decode_holding_write,
    encode_drive_inputs,
    encode_holding_readback,
    status_flags,
)
from gateway.modbus.mbap import MbapError, MbapHeader, parse_header
from gateway.modbus.regs import (
    CODE16,
    COUNTER32,
    INT16,
    UINT16,
    UINT32,
    ExceptionCode,
    WriteRefused,
    to_signed16,
)
from gateway.modbus.server import AccessPolicy
from gateway.model import (
    CommState,
    DesiredCommand,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    SpeedScale,
)

SCALE = SpeedScale(1800.0, 100.0)

# ------------------------------------------------------------------ register types


@pytest.mark.parametrize(
    ("rtype", "value", "scale", "words"),
    [
        (INT16, -900, 1.0, (0xFC7C,)),
        (INT16, 12.34, 100.0, (1234,)),
        (INT16, None, 1.0, (0x8000,)),
        (INT16, math.nan, 1.0, (0x8000,)),
        (INT16, 40000, 1.0, (32767,)),  # saturates
        (INT16, -40000, 1.0, (0x8001,)),  # -32767: never the null
        (UINT16, None, 1.0, (0xFFFF,)),
        (UINT16, 70000, 1.0, (0xFFFE,)),
        (UINT16, -5, 1.0, (0,)),
        (UINT16, 4.25, 10.0, (42,)),  # round half to even on the scaled value
        (UINT32, 0x12345678, 1.0, (0x1234, 0x5678)),  # high word first
        (UINT32, None, 1.0, (0xFFFF, 0xFFFF)),
        (COUNTER32, 2**32 + 5, 1.0, (0, 5)),  # counters wrap
        (CODE16, 65535, 1.0, (0xFFFF,)),
    ],
)
def test_encode(rtype, value, scale, words) -> None:
    assert rtype.encode(value, scale) == words


def test_types_without_null_refuse_none() -> None:
    with pytest.raises(ValueError, match="no null"):
        CODE16.encode(None)


@settings(max_examples=200, deadline=None)
@given(st.integers(-32767, 32767))
def test_int16_round_trip(raw: int) -> None:
    words = INT16.encode(raw / 100, 100.0)
    assert INT16.decode(words, 100.0) == pytest.approx(raw / 100)
    assert to_signed16(words[0]) == raw


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 2))
def test_uint32_round_trip(raw: int) -> None:
    assert UINT32.decode(UINT32.encode(raw)) == raw


def test_decode_null_and_bad_words() -> None:
    assert INT16.decode([0x8000]) is None
    with pytest.raises(ValueError, match="register"):
        UINT32.decode([1])
    with pytest.raises(ValueError, match="register"):
        UINT16.decode([0x10000])


# ------------------------------------------------------------------ command word


@pytest.mark.parametrize("raw", range(64))
def test_command_word_round_trip(raw: int) -> None:
    assert CommandWord.from_register(raw).to_register() == raw


@pytest.mark.parametrize("raw", [0x40, 0x80, 0x8000, 0xFFFF, -1, 0x10000])
def test_command_word_refuses_reserved_bits(raw: int) -> None:
    with pytest.raises(WriteRefused) as err:
        CommandWord.from_register(raw)
    assert err.value.code is ExceptionCode.ILLEGAL_DATA_VALUE


def test_command_word_from_desired() -> None:
    desired = DesiredCommand(run=True, direction=Direction.REVERSE, fault_reset_seq=4, jog=True)
    assert CommandWord.from_desired(desired).to_register() == 0b100011


RUN = CommandWord(run=True)
STOPPED = CommandWord()


def cmd_for(last: CommandWord, raw: int, desired: DesiredCommand | None = None) -> DriveCommand:
    write = HoldingWrite(word=CommandWord.from_register(raw), command=True)
    return build_command(last, write, desired or DesiredCommand())


@pytest.mark.parametrize(
    ("last", "raw", "desired", "expected"),
    [
        (STOPPED, 0x0001, None, DriveCommand(run=True)),
        (RUN, 0x0001, None, DriveCommand()),  # run held: no new run command
        (RUN, 0x0000, DesiredCommand(run=True), DriveCommand(run=False)),
        (STOPPED, 0x0000, DesiredCommand(run=True), DriveCommand()),  # no edge, level ignored
        (RUN, 0x0005, None, DriveCommand(fault_reset=True)),  # reset edge, run held
        (CommandWord(fault_reset=True), 0x0004, None, DriveCommand()),  # reset held
        (STOPPED, 0x0002, None, DriveCommand(direction=Direction.REVERSE)),
        (STOPPED, 0x0002, DesiredCommand(direction=Direction.REVERSE), DriveCommand()),
        (STOPPED, 0x0008, None, DriveCommand(quick_stop=True)),
        (STOPPED, 0x0000, DesiredCommand(coast_stop=True), DriveCommand(coast_stop=False)),
        (STOPPED, 0x0020, None, DriveCommand(jog=True)),
        (CommandWord(jog=True), 0x0020, None, DriveCommand()),  # jog held
        (UNKNOWN_CLIENT_WORD, 0x0025, None, DriveCommand()),  # first word: no start, no reset
        (UNKNOWN_CLIENT_WORD, 0x0000, None, DriveCommand(run=False, jog=False)),  # may stop
    ],
)
def test_edges_and_levels(last, raw, desired, expected) -> None:
    assert cmd_for(last, raw, desired) == expected


def test_speed_levels_against_the_desired_command() -> None:
    desired = DesiredCommand(speed_rpm=300.0)
    assert build_command(STOPPED, HoldingWrite(speed_rpm=300.0), desired) == DriveCommand()
    assert build_command(STOPPED, HoldingWrite(speed_rpm=301.0), desired) == DriveCommand(
        speed_rpm=301.0
    )
    assert build_command(STOPPED, HoldingWrite(speed_pct=25.0), desired) == DriveCommand(
        speed_pct=25.0
    )


def test_client_memory_is_bounded_and_forgets_to_the_safe_side() -> None:
    memory = ClientMemory(limit=2)
    assert memory.last("10.0.0.1", 1) == UNKNOWN_CLIENT_WORD
    memory.remember("10.0.0.1", 1, STOPPED)
    memory.remember("10.0.0.2", 1, RUN)
    memory.remember("10.0.0.1", 1, RUN)  # refreshes 10.0.0.1
    memory.remember("10.0.0.3", 1, STOPPED)  # evicts 10.0.0.2
    assert len(memory) == 2
    assert memory.last("10.0.0.2", 1) == UNKNOWN_CLIENT_WORD
    assert memory.last("10.0.0.1", 1) == RUN
    assert memory.last("10.0.0.1", 2) == UNKNOWN_CLIENT_WORD  # per unit


def test_client_memory_never_evicts_a_connected_client() -> None:
    """Issue 17 item 3: writes from thousands of other addresses cannot evict a
    connected PLC's last word (its 0 -> 1 run edge would be lost)."""
    memory = ClientMemory(limit=16)
    memory.connected("10.0.0.1")
    memory.remember("10.0.0.1", 1, STOPPED)
    for i in range(5000):
        other = f"10.1.{i // 250}.{i % 250}"
        memory.connected(other)
        memory.remember(other, 1, RUN)
        memory.disconnected(other)
    assert memory.last("10.0.0.1", 1) == STOPPED
    assert len(memory) == 17  # the connected one, and the newest 16 of the others
    # a second connection from the same address: the words last until the last one closes
    memory.connected("10.0.0.1")
    memory.disconnected("10.0.0.1")
    memory.remember("10.2.0.1", 1, RUN)
    assert memory.last("10.0.0.1", 1) == STOPPED
    memory.disconnected("10.0.0.1")
    for i in range(16):
        memory.remember(f"10.3.0.{i}", 1, RUN)
    assert memory.last("10.0.0.1", 1) == UNKNOWN_CLIENT_WORD  # aged out, to the safe side


def test_client_memory_keeps_a_reconnecting_plc() -> None:
    memory = ClientMemory(limit=16)
    memory.peer("10.0.0.1", True)
    memory.remember("10.0.0.1", 1, RUN)
    memory.peer("10.0.0.1", False)
    memory.peer("10.0.0.1", True)
    assert memory.last("10.0.0.1", 1) == RUN  # a held run bit stays no edge


# ------------------------------------------------------------------ write decoding


def test_decode_a_full_block() -> None:
    write = decode_holding_write(0, [0x0001, 900, 0x8000, 7], SCALE)
    assert write == HoldingWrite(
        word=CommandWord(run=True), speed_rpm=900.0, keepalive=7, command=True
    )
    assert decode_holding_write(2, [0x10000 - 2500], SCALE).speed_pct == -25.0
    assert decode_holding_write(3, [1], None) == HoldingWrite(keepalive=1, command=False)


@pytest.mark.parametrize(
    ("address", "values", "code"),
    [
        (4, [0], ExceptionCode.ILLEGAL_DATA_ADDRESS),
        (3, [0, 0], ExceptionCode.ILLEGAL_DATA_ADDRESS),
        (100, [0], ExceptionCode.ILLEGAL_DATA_ADDRESS),
        (0, [0x0040], ExceptionCode.ILLEGAL_DATA_VALUE),
        (1, [1801], ExceptionCode.ILLEGAL_DATA_VALUE),
        (2, [10001], ExceptionCode.ILLEGAL_DATA_VALUE),
        (1, [100, 100], ExceptionCode.ILLEGAL_DATA_VALUE),
        (3, [0x10000], ExceptionCode.ILLEGAL_DATA_VALUE),
    ],
)
def test_decode_refusals(address: int, values: list[int], code: ExceptionCode) -> None:
    with pytest.raises(WriteRefused) as err:
        decode_holding_write(address, values, SCALE)
    assert err.value.code is code


def test_without_a_scale_the_hub_judges_the_speed() -> None:
    assert decode_holding_write(1, [30000], None).speed_rpm == 30000.0


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 10), st.lists(st.integers(-1, 0x10001), min_size=1, max_size=6))
def test_decode_raises_only_write_refused(address: int, values: list[int]) -> None:
    with contextlib.suppress(WriteRefused):
        decode_holding_write(address, values, SCALE)


def test_holding_readback() -> None:
    view = HoldingView(DesiredCommand(run=True, speed_pct=50.0), SCALE)
    assert encode_holding_readback(view) == [1, 900, 5000]
    assert encode_holding_readback(HoldingView(DesiredCommand(), None)) == [0, 0x8000, 0x8000]
    no_scale = HoldingView(DesiredCommand(speed_rpm=100.0), None)
    assert encode_holding_readback(no_scale) == [0, 100, 0x8000]


# ------------------------------------------------------------------ status block


def state(**changes) -> DriveState:
    base = DriveState(id="d", device=Device.CFW11, bus="b", address=7)
    return base.changed(**changes)


@pytest.mark.parametrize(
    ("changes", "flags"),
    [
        ({}, 0),
        ({"comm": CommState.ONLINE, "status": DriveStatus.READY}, 0b11),
        ({"comm": CommState.ONLINE, "status": DriveStatus.FAULTED}, 0b100001),
        ({"comm": CommState.OFFLINE, "status": DriveStatus.READY}, 0),  # not ready offline
        ({"status": DriveStatus.TRIPPED}, 0b100000),
        ({"running": True, "direction": Direction.REVERSE, "at_reference": True}, 0b11100),
        ({"alarm": True, "remote": True}, 0b11000000),
    ],
)
def test_status_flags(changes, flags) -> None:
    assert status_flags(state(**changes)) == flags


def test_status_block_layout() -> None:
    s = state(
        comm=CommState.ONLINE,
        status=DriveStatus.RUNNING,
        speed_rpm=-1500.4,
        speed_pct=-83.36,
        current_a=12.34,
        power_kw=-5.5,
        fault_code=None,
        seq=0x10002,
    )
    regs = encode_drive_inputs(DriveView(s, DrivePolicy(command_timeout=2.5)))
    assert len(regs) == sum(f.words for f in DRIVE_INPUTS) == 21
    assert regs[1] == 3
    assert to_signed16(regs[2]) == -1500
    assert to_signed16(regs[3]) == -8336
    assert regs[6] == 123
    assert regs[7] == 0xFFFF  # not given
    assert to_signed16(regs[9]) == -55
    assert regs[11] == 0xFFFF
    assert regs[13] == 2
    assert regs[16] == 25
    assert regs[17:19] == [1, 2]
    assert regs[19] == 1  # CFW-11


def test_parse_version() -> None:
    assert parse_version("1.2.3") == (1, 2, 3)
    assert parse_version("0.10.0rc1") == (0, 10, 0)
    assert parse_version("2") == (2, 0, 0)
    assert parse_version("dev") == (0, 0, 0)


# ------------------------------------------------------------------ MBAP


def test_mbap_golden() -> None:
    frame = bytes.fromhex("0001 0000 0006 01 04 0000 0002")
    assert parse_header(frame) == MbapHeader(transaction=1, protocol=0, length=6, unit=1)
    assert parse_header(frame[:6]) is None
    assert MbapHeader(1, 0, 6, 1).frame_size == 12


@pytest.mark.parametrize("raw", ["0001 0001 0006 01", "0001 0000 0001 01", "0001 0000 00ff 01"])
def test_mbap_bad_headers(raw: str) -> None:
    data = bytes.fromhex(raw)
    with pytest.raises(MbapError) as err:
        parse_header(data)
    assert isinstance(err.value, FrameDecodeError)
    assert err.value.raw == data


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=40))
def test_mbap_raises_only_frame_decode_errors(data: bytes) -> None:
    try:
        header = parse_header(data)
    except FrameDecodeError:
        return
    assert header is None or 2 <= header.length <= 254


# ------------------------------------------------------------------ access policy


def test_access_policy() -> None:
    nets = [ipaddress.ip_network("10.0.0.0/8"), ipaddress.ip_network("fd00::/8")]
    policy = AccessPolicy(nets, {0: frozenset(), 1: frozenset({0, 1, 5})}, frozenset({3, 4}))
    assert policy.admits("10.1.2.3")
    assert policy.admits("::ffff:10.1.2.3")  # IPv4-mapped
    assert policy.admits("fd00::1%eth0")
    assert not policy.admits("127.0.0.1")
    assert not policy.admits("not an address")
    assert AccessPolicy([], {}, frozenset()).admits("192.0.2.1")  # [] = anyone
    assert policy.refusal(1, 4) is None
    assert policy.refusal(2, 4) is ExceptionCode.GATEWAY_TARGET_FAILED
    assert policy.refusal(1, 8) is ExceptionCode.ILLEGAL_FUNCTION
    assert policy.holding_read_refusal(1, 0, 2) is None
    assert policy.holding_read_refusal(1, 0, 3) is ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert policy.holding_read_refusal(0, 0, 1) is ExceptionCode.ILLEGAL_DATA_ADDRESS


def test_the_safety_flags_of_issue_32_are_status_bits_8_to_10() -> None:
    from gateway.modbus.map import status_flags
    from gateway.model import CommState, Device, DriveState

    base = DriveState(id="d", device=Device.CFW11, bus="b", address=1, comm=CommState.ONLINE)
    assert status_flags(base.changed(local_control=True)) & 0x0700 == 0x0100
    assert status_flags(base.changed(failsafe=False)) & 0x0700 == 0x0200
    assert status_flags(base.changed(failsafe=None)) & 0x0700 == 0
    assert status_flags(base.changed(doubtful=True)) & 0x0700 == 0x0400
