"""WEG parameter record 48 (CFW-11 4.2.6, CFW700 5.2.5, CFW320 5.2.4)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.codec import dpv1
from adapters.profibus.codec import wegrecord as weg
from adapters.profibus.codec.wegrecord import WegSelect, WegValue, WegWrite
from adapters.profibus.errors import DecodeFailure, WegRecordDecodeError
from gateway.errors import FrameEncodeError

h = bytes.fromhex
FAST = settings(max_examples=50, deadline=None)


def test_change_p100_is_one_4_byte_write() -> None:
    # "DS_Write with 4 data bytes: parameter number then content, MSB first";
    # P0100 = 8.5 s is value 85 (the index 47 example's value), computed
    request = weg.write_request(100, 85)
    assert request.encode() == h("5F 00 30 04 00 64 00 55")
    decoded = dpv1.decode_request(request.encode())
    assert isinstance(decoded, dpv1.WriteRequest)
    assert (decoded.slot, decoded.index) == (0, 48)
    assert weg.decode_write_data(decoded.data) == WegWrite(100, 85)
    # the slave's positive write reply (5.2.3 layout: size 0)
    assert dpv1.decode_response(h("5F 00 30 00")) == dpv1.WriteResponse(0, 48, 0)


def test_read_p2_is_select_then_read() -> None:
    # "DS_Write with 2 data bytes (the parameter number), then DS_Read: 2 bytes of content"
    select = weg.select_request(2)
    assert select.encode() == h("5F 00 30 02 00 02")
    assert weg.decode_write_data(h("00 02")) == WegSelect(2)
    # the DS_Read request of the 4.2.3 telegrams (CFW-11 4.2.3 / CFW700 4.2.3 / CFW320 5.2.3):
    # "Função 5Eh, Slot 0, Índice, Tamanho 240", here with index 48 (4.2.6 uses those telegrams)
    assert weg.read_request().encode() == h("5E 00 30 F0")
    reply = dpv1.decode_response(h("5E 00 30 02 00 64"))  # P0002 = 100 rpm
    assert isinstance(reply, dpv1.ReadResponse)
    assert WegValue.decode(reply.data) == WegValue(100)
    assert WegValue(100).encode() == h("00 64")


@pytest.mark.parametrize(
    ("wire", "text"),
    [
        ("DF 80 B8 00", "access error - invalid parameter number"),
        ("DF 80 B6 00", "access error - modification in read-only parameter"),
        ("DE 80 C3 00", "resource error - response not available for the reading request"),
    ],
)
def test_record_48_errors_use_the_weg_table(wire: str, text: str) -> None:
    error = dpv1.decode_response(h(wire))
    assert isinstance(error, dpv1.Dpv1ErrorResponse)
    assert error.text_in(weg.ERROR_TEXTS) == text


def test_errors() -> None:
    for raw in (b"", h("00"), h("00 01 02"), h("00 01 02 03 04")):
        with pytest.raises(WegRecordDecodeError) as info:
            weg.decode_write_data(raw)
        assert info.value.reason is DecodeFailure.BAD_LENGTH
        assert info.value.raw == raw
    with pytest.raises(WegRecordDecodeError):
        WegValue.decode(h("00"))
    with pytest.raises(FrameEncodeError):
        WegWrite(100, -1).encode()
    with pytest.raises(FrameEncodeError):
        WegSelect(0x10000).encode()


u16 = st.integers(0, 0xFFFF)


@FAST
@given(st.builds(WegSelect, u16) | st.builds(WegWrite, u16, u16), u16)
def test_round_trip(data: weg.WegWriteData, value: int) -> None:
    assert weg.decode_write_data(data.encode()) == data
    assert WegValue.decode(WegValue(value).encode()) == WegValue(value)


@FAST
@given(st.binary(max_size=8))
def test_decoders_raise_only_typed_errors(raw: bytes) -> None:
    for decode in (weg.decode_write_data, WegValue.decode):
        try:
            decode(raw)
        except WegRecordDecodeError as exc:
            assert exc.raw == raw
