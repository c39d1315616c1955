"""Duplicate MAC ID check message (fact sheet 2.3)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.dupmac import WEG_VENDOR_ID, DupMacCheck, DupMacKind
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.errors import DeviceNetDecodeError, DupMacDecodeError, UnexpectedCanId
from gateway.errors import FrameEncodeError
from tests.devicenet.strategies import frames, macs

# Fact sheet 2.2/2.3: master MAC 0 claims its MAC on 0x407; 7 bytes = port byte
# (b7 response), vendor id UINT LE (WEG 355h, seed table 8), serial UDINT LE.
GOLDEN = [
    (
        DupMacCheck(0, DupMacKind.REQUEST, 0, WEG_VENDOR_ID, 0x12345678),
        CanFrame(0x407, bytes.fromhex("00 55 03 78 56 34 12")),
    ),
    (
        DupMacCheck(10, DupMacKind.RESPONSE, 1, WEG_VENDOR_ID, 0x0A0B0C0D),
        CanFrame(0x457, bytes.fromhex("81 55 03 0D 0C 0B 0A")),
    ),
]


@pytest.mark.parametrize(("message", "frame"), GOLDEN)
def test_golden_both_directions(message, frame):
    assert message.to_frame() == frame
    assert DupMacCheck.from_frame(frame) == message


@pytest.mark.parametrize("length", [0, 6, 8])
def test_wrong_length(length):
    with pytest.raises(DupMacDecodeError) as info:
        DupMacCheck.from_frame(CanFrame(0x407, bytes(length)))
    assert info.value.raw == bytes(length)


@pytest.mark.parametrize("arbitration_id", [0x406, 0x3CA, 0x7C7])
def test_other_identifier_is_unexpected(arbitration_id):
    with pytest.raises(UnexpectedCanId):
        DupMacCheck.from_frame(CanFrame(arbitration_id, bytes(7)))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"mac": 64},
        {"port": 128},
        {"vendor_id": 0x10000},
        {"serial_number": -1},
        {"kind": 2},
    ],
)
def test_encode_range(kwargs):
    fields = {"mac": 0, "kind": DupMacKind.REQUEST, "port": 0, "vendor_id": 1, "serial_number": 1}
    with pytest.raises(FrameEncodeError):
        DupMacCheck(**(fields | kwargs))


@settings(max_examples=100, deadline=None)
@given(
    macs,
    st.sampled_from(DupMacKind),
    st.integers(0, 127),
    st.integers(0, 0xFFFF),
    st.integers(0, 0xFFFFFFFF),
)
def test_round_trip(mac, kind, port, vendor, serial):
    message = DupMacCheck(mac, kind, port, vendor, serial)
    assert DupMacCheck.from_frame(message.to_frame()) == message


DUPMAC_FRAMES = st.builds(
    CanFrame, macs.map(lambda mac: 0x400 | mac << 3 | 7), st.binary(max_size=8)
)


@settings(max_examples=200, deadline=None)
@given(frames | DUPMAC_FRAMES)
def test_fuzz_raises_only_typed_errors(frame):
    try:
        message = DupMacCheck.from_frame(frame)
    except DeviceNetDecodeError:
        return
    assert message.to_frame() == frame
