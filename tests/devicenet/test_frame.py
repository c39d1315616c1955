"""The CAN frame dataclass (fact sheet 2.13)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.errors import DeviceNetDecodeError, InvalidCanFrame
from gateway.errors import FrameDecodeError, FrameEncodeError
from tests.support.canframes import DATA, IDENTIFIERS, carried


def test_frame_keeps_id_and_bytes():
    frame = CanFrame(0x456, bytearray(b"\x00\x4b\x03\x01\x03\x00"))  # type: ignore[arg-type]
    assert frame.arbitration_id == 0x456
    assert frame.data == bytes.fromhex("00 4B 03 01 03 00")
    assert isinstance(frame.data, bytes)
    assert str(frame) == "456#004B03010300"


@pytest.mark.parametrize(
    ("arbitration_id", "data"),
    [(-1, b""), (0x800, b""), (0x1FFFFFFF, b""), (0x400, bytes(9)), (True, b"")],
)
def test_frame_out_of_range_is_an_encode_error(arbitration_id, data):
    with pytest.raises(FrameEncodeError):
        CanFrame(arbitration_id, data)


def test_frame_data_must_be_bytes():
    with pytest.raises(FrameEncodeError):
        CanFrame(0x400, [1, 2])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("arbitration_id", "data", "extended"),
    [(0x400, b"", True), (0x800, b"", False), (-5, b"", False), (0x400, bytes(12), False)],
)
def test_from_bus_rejects_what_devicenet_cannot_carry(arbitration_id, data, extended):
    with pytest.raises(InvalidCanFrame) as info:
        CanFrame.from_bus(arbitration_id, data, is_extended_id=extended)
    assert isinstance(info.value, FrameDecodeError)
    assert info.value.raw == bytes(data)


@settings(max_examples=200, deadline=None)
@given(st.integers(-(1 << 30), 1 << 30), st.binary(max_size=64), st.booleans())
def test_from_bus_raises_only_typed_errors(arbitration_id, data, extended):
    try:
        frame = CanFrame.from_bus(arbitration_id, data, is_extended_id=extended)
    except DeviceNetDecodeError:
        return
    assert (frame.arbitration_id, frame.data) == (arbitration_id, data)


@given(IDENTIFIERS, DATA, st.booleans())
def test_from_bus_short_cut_is_the_checked_constructor(arbitration_id, data, extended):
    """``from_bus``'s one-test path for the usual frame against the checked constructor:
    the same frame, or InvalidCanFrame for what DeviceNet cannot carry."""
    valid = carried(arbitration_id, data, extended)
    if not valid:
        with pytest.raises(InvalidCanFrame):
            CanFrame.from_bus(arbitration_id, data, is_extended_id=extended)
        return
    frame = CanFrame.from_bus(arbitration_id, data, is_extended_id=extended)
    assert frame == CanFrame(arbitration_id, bytes(data))
    assert type(frame.data) is bytes and frame.data == bytes(data)
