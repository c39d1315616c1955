"""CIP elementary data types (fact sheet 2.3, 2.7, 2.12)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.datatypes import (
    CipType,
    decode_short_string,
    decode_value,
    encode_short_string,
    encode_value,
    read_short_string,
    read_value,
)
from adapters.devicenet.errors import DataTypeDecodeError
from gateway.errors import FrameEncodeError


@pytest.mark.parametrize(
    ("cip_type", "value", "wire"),
    [
        (CipType.UINT, 0x0355, b"\x55\x03"),  # WEG vendor id 355h (seed table 8)
        (CipType.UDINT, 0x12345678, b"\x78\x56\x34\x12"),
        (CipType.USINT, 0xFF, b"\xff"),
        (CipType.INT, -2, b"\xfe\xff"),
        (CipType.SINT, -128, b"\x80"),
        (CipType.DINT, -1, b"\xff\xff\xff\xff"),
        (CipType.UINT, 0x0708, b"\x08\x07"),  # 1800 rpm (fact sheet 2.11)
        (CipType.WORD, 0x04F6, b"\xf6\x04"),
    ],
)
def test_golden_values(cip_type, value, wire):
    assert encode_value(cip_type, value) == wire
    assert decode_value(cip_type, wire) == value


def test_short_string_golden():
    # Seed table 8: Identity attribute 7 "CFW-08"; fact sheet 2.12: SHORT_STRING.
    wire = b"\x06CFW-08"
    assert encode_short_string("CFW-08") == wire
    assert decode_short_string(wire) == "CFW-08"
    assert read_short_string(wire + b"\x01", 0) == ("CFW-08", 7)


@pytest.mark.parametrize(
    ("cip_type", "value"),
    [
        (CipType.USINT, 256),
        (CipType.UINT, -1),
        (CipType.INT, 0x8000),
        (CipType.UDINT, 1 << 32),
        (CipType.UINT, True),
    ],
)
def test_encode_out_of_range(cip_type, value):
    with pytest.raises(FrameEncodeError):
        encode_value(cip_type, value)


def test_short_string_encode_errors():
    with pytest.raises(FrameEncodeError):
        encode_short_string("x" * 256)
    with pytest.raises(FrameEncodeError):
        encode_short_string("\u20ac")


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(CipType), st.data())
def test_value_round_trip(cip_type, data):
    value = data.draw(st.integers(cip_type.minimum, cip_type.maximum))
    wire = encode_value(cip_type, value)
    assert len(wire) == cip_type.size
    assert decode_value(cip_type, wire) == value
    assert read_value(cip_type, b"\x00" + wire, 1) == (value, 1 + cip_type.size)


@settings(max_examples=100, deadline=None)
@given(st.text(st.characters(max_codepoint=0xFF), max_size=255))
def test_short_string_round_trip(text):
    assert decode_short_string(encode_short_string(text)) == text


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(CipType), st.binary(max_size=8), st.integers(-2, 9))
def test_decoders_raise_only_typed_errors(cip_type, data, offset):
    for decode in (
        lambda: decode_value(cip_type, data),
        lambda: read_value(cip_type, data, offset),
        lambda: decode_short_string(data),
        lambda: read_short_string(data, offset),
    ):
        try:
            decode()
        except DataTypeDecodeError as exc:
            assert exc.raw == data
