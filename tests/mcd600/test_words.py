"""Control and status words: golden bytes from the guide (4.2 tables 2 and 3), round trips."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.mcd600.errors import Mcd600DecodeError
from adapters.mcd600.words import (
    ControlWord,
    MotorSet,
    StatusWord,
    current_to_raw,
)
from gateway.errors import FrameDecodeError, FrameEncodeError


@pytest.mark.parametrize(
    ("word", "wire"),
    [
        (ControlWord(), "00 00"),  # stop, soft stop, motor set from the remote input
        (ControlWord(start=True), "00 01"),  # byte 1 bit 0 = start, byte 0 bit 4 = 0
        (ControlWord(start=True, motor_set=MotorSet.PRIMARY), "04 01"),  # bits 2-3 = 1
        (ControlWord(start=True, motor_set=MotorSet.SECONDARY), "08 01"),  # bits 2-3 = 2
        (ControlWord(quick_stop=True), "10 00"),  # byte 0 bit 4: quick stop (coast)
        (ControlWord(reset=True), "00 08"),  # byte 1 bit 3: reset
        (ControlWord(quick_stop=True, reset=True, motor_set=MotorSet.SECONDARY), "18 08"),
    ],
)
def test_control_word_golden(word: ControlWord, wire: str) -> None:
    assert word.encode() == bytes.fromhex(wire)
    assert ControlWord.decode(bytes.fromhex(wire)) == word


def test_control_word_ignores_reserved_bits() -> None:
    # byte 0 bits 0-1 and 5-7, byte 1 bits 1-2 and 4-7 are reserved
    assert ControlWord.decode(bytes.fromhex("E3 FF")) == ControlWord(
        start=True, reset=True, motor_set=MotorSet.REMOTE_INPUT
    )


@pytest.mark.parametrize(
    ("wire", "word"),
    [
        ("40 01", StatusWord(network_control=True, ready=True)),  # ready, network
        ("00 01", StatusWord(ready=True)),  # ready, LCP/digital input/clock in control
        ("FF 02", StatusWord(63, network_control=True, ramping=True, active=True)),  # starting
        ("60 02", StatusWord(32, network_control=True, active=True)),  # running, ~100 %
        ("40 04", StatusWord(network_control=True, tripped=True)),
        ("40 09", StatusWord(network_control=True, ready=True, warning=True)),
    ],
)
def test_status_word_golden(wire: str, word: StatusWord) -> None:
    assert StatusWord.decode(bytes.fromhex(wire)) == word
    assert word.encode() == bytes.fromhex(wire)


def test_status_current_scale() -> None:
    # 4.2 note 1: 63 = 200 % FLC, "divide by 0.315"
    assert StatusWord(current_raw=63).current_pct_flc == pytest.approx(200.0)
    assert StatusWord(current_raw=0).current_pct_flc == 0.0
    assert StatusWord(current_raw=32).current_pct_flc == pytest.approx(101.587, abs=1e-3)
    assert current_to_raw(200.0) == 63
    assert current_to_raw(350.0) == 63  # saturates
    assert current_to_raw(100.0) == 32
    assert current_to_raw(-5.0) == 0
    assert current_to_raw(float("nan")) == 0


def test_status_word_ignores_reserved_bits() -> None:
    assert StatusWord.decode(bytes.fromhex("00 F0")) == StatusWord()


@pytest.mark.parametrize("data", [b"", b"\x00", b"\x00\x00\x00"])
def test_words_need_two_bytes(data: bytes) -> None:
    with pytest.raises(Mcd600DecodeError) as info:
        StatusWord.decode(data)
    assert info.value.raw == data
    with pytest.raises(FrameDecodeError):
        ControlWord.decode(data)


def test_status_word_encode_range() -> None:
    with pytest.raises(FrameEncodeError):
        StatusWord(current_raw=64).encode()


control_words = st.builds(
    ControlWord,
    start=st.booleans(),
    quick_stop=st.booleans(),
    reset=st.booleans(),
    motor_set=st.sampled_from(MotorSet),
)
status_words = st.builds(
    StatusWord,
    current_raw=st.integers(0, 63),
    network_control=st.booleans(),
    ramping=st.booleans(),
    ready=st.booleans(),
    active=st.booleans(),
    tripped=st.booleans(),
    warning=st.booleans(),
)


@settings(max_examples=100, deadline=None)
@given(control_words)
def test_control_word_round_trip(word: ControlWord) -> None:
    assert ControlWord.decode(word.encode()) == word


@settings(max_examples=100, deadline=None)
@given(status_words)
def test_status_word_round_trip(word: StatusWord) -> None:
    assert StatusWord.decode(word.encode()) == word


@settings(max_examples=100, deadline=None)
@given(st.binary(min_size=2, max_size=2))
def test_any_two_bytes_decode_and_keep_the_defined_bits(data: bytes) -> None:
    status = StatusWord.decode(data)
    assert status.encode() == bytes((data[0], data[1] & 0x0F))
    control = ControlWord.decode(data)
    assert control.encode() == bytes((data[0] & 0x1C, data[1] & 0x09))


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=6))
def test_word_decoders_raise_only_typed_errors(data: bytes) -> None:
    for decoder in (StatusWord.decode, ControlWord.decode):
        try:
            decoder(data)
        except FrameDecodeError:
            assert len(data) != 2
