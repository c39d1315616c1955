"""PROFIdrive parameter record 47 (fact sheet 1.11; WEG CFW-11 4.2.4-4.2.5, CFW320 5.2.5)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.codec import dpv1
from adapters.profibus.codec import profidrive as pd
from adapters.profibus.codec.fdl import (
    DataTelegram,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    decode_telegram,
)
from adapters.profibus.codec.profidrive import (
    Attribute,
    DataFormat,
    ParameterAddress,
    ParameterRequest,
    ParameterResponse,
    RequestId,
    ResponseId,
    ValueBlock,
)
from adapters.profibus.errors import DecodeFailure, ProfidriveDecodeError
from gateway.errors import FrameEncodeError

FAST = settings(max_examples=50, deadline=None)


def b(*values: int) -> bytes:
    """Bytes written as the manuals' tables list them (byte 1, byte 2, ...)."""
    return bytes(values)


# ---------------------------------------------------------------- WEG worked examples, verbatim

# CFW-11 4.2.5 / CFW320 5.2.5 Example 1: read P0002 (speed) and P0003 (motor current)
READ_P2_P3 = b(1, 1, 0, 2, 0x10, 1, 0, 2, 0, 0, 0x10, 1, 0, 3, 0, 0)
READ_P2_P3_PDU = ParameterRequest(
    reference=1,
    request_id=RequestId.READ,
    parameters=(ParameterAddress(2, 0, 1), ParameterAddress(3, 0, 1)),
    axis=0,
)
# positive: P0002 = 100 rpm, P0003 = 5.0 A (value 50)
READ_P2_P3_OK = b(1, 1, 0, 2, 0x42, 1, 0, 100, 0x42, 1, 0, 50)
READ_P2_P3_OK_PDU = ParameterResponse(
    1, ResponseId.READ_OK, 2, (ValueBlock.word(100), ValueBlock.word(50))
)
# negative: error reading the second parameter, error 0000h
READ_P2_P3_NOK = b(1, 129, 0, 2, 0x42, 1, 0, 100, 0x44, 1, 0, 0)
READ_P2_P3_NOK_PDU = ParameterResponse(
    1, ResponseId.READ_ERROR, 2, (ValueBlock.word(100), ValueBlock.error(0x0000))
)

# CFW-11 4.2.5 Example 2: change P0100 (acceleration ramp) = 8.5 s, value 85
WRITE_P100 = b(1, 2, 0, 1, 0x10, 1, 0, 100, 0, 0, 0x42, 1, 0, 85)
WRITE_P100_PDU = ParameterRequest.change(1, [(ParameterAddress(100), ValueBlock.word(85))])
# CFW320 5.2.5 Example 2: change P134 (upper speed limit) = 1000 rpm (03h E8h)
WRITE_P134 = b(1, 2, 0, 1, 0x10, 1, 0, 134, 0, 0, 0x42, 1, 0x03, 0xE8)
WRITE_P134_PDU = ParameterRequest.change(1, [(ParameterAddress(134), ValueBlock.word(1000))])
# positive change reply (both manuals)
WRITE_OK = b(1, 2, 0, 1)
WRITE_OK_PDU = ParameterResponse.change_ok(1, 1)
# negative change reply, error 0002h (value out of limits). Both manuals print
# "No. of Parameters 2" with the description "change of one parameter": kept as printed.
WRITE_NOK = b(1, 130, 0, 2, 0x44, 1, 0, 2)
WRITE_NOK_PDU = ParameterResponse(1, ResponseId.CHANGE_ERROR, 2, (ValueBlock.error(0x0002),))

# fact sheet 1.11 examples (DU after the DS_Write header)
ABB_READ_12_04 = b(0x05, 0x01, 0x01, 0x01, 0x10, 0x01, 0x00, 0x0C, 0x00, 0x04)
ABB_READ_12_04_PDU = ParameterRequest.read(5, ParameterAddress(12, 4, 1), axis=1)
TOSHIBA_WRITE_927 = b(
    0x01, 0x02, 0x01, 0x01, 0x10, 0x01, 0x03, 0x9F, 0x00, 0x00, 0x06, 0x01, 0x00, 0x00
)
TOSHIBA_WRITE_927_PDU = ParameterRequest.change(
    1, [(ParameterAddress(927), ValueBlock(DataFormat.UNSIGNED16, (0,)))], axis=1
)

REQUESTS = [
    (READ_P2_P3, READ_P2_P3_PDU),
    (WRITE_P100, WRITE_P100_PDU),
    (WRITE_P134, WRITE_P134_PDU),
    (ABB_READ_12_04, ABB_READ_12_04_PDU),
    (TOSHIBA_WRITE_927, TOSHIBA_WRITE_927_PDU),
]
RESPONSES = [
    (READ_P2_P3_OK, READ_P2_P3_OK_PDU),
    (READ_P2_P3_NOK, READ_P2_P3_NOK_PDU),
    (WRITE_OK, WRITE_OK_PDU),
    (WRITE_NOK, WRITE_NOK_PDU),
]


@pytest.mark.parametrize(("wire", "pdu"), REQUESTS)
def test_request_golden_both_directions(wire: bytes, pdu: ParameterRequest) -> None:
    assert pdu.encode() == wire
    assert ParameterRequest.decode(wire) == pdu


@pytest.mark.parametrize(("wire", "pdu"), RESPONSES)
def test_response_golden_both_directions(wire: bytes, pdu: ParameterResponse) -> None:
    assert pdu.encode() == wire
    assert ParameterResponse.decode(wire) == pdu


def test_example_values_and_errors_as_the_manuals_read_them() -> None:
    ok = ParameterResponse.decode(READ_P2_P3_OK)
    assert ok.ok
    assert [v.values for v in ok.values] == [(100,), (50,)]  # 100 rpm, 5.0 A
    nok = ParameterResponse.decode(READ_P2_P3_NOK)
    assert not nok.ok
    assert nok.values[0].values == (100,)
    assert nok.errors == ((1, 0x0000),)
    assert nok.values[1].error_text(pd.WEG_PARAMETER_ERROR_TEXTS) == "parameter does not exist"
    assert nok.values[1].error_text() == "impermissible parameter number"
    change = ParameterResponse.decode(WRITE_NOK)
    assert change.errors == ((0, 0x0002),)
    assert change.values[0].error_text() == "parameter value out of limits"
    assert change.values[0].error_text(pd.WEG_PARAMETER_ERROR_TEXTS) == (
        "parameter value out of the limits"
    )
    assert ParameterResponse.decode(WRITE_OK).ok


def test_ds_write_and_ds_read_for_record_47() -> None:
    # WEG 4.2.4: DS_Write(slot 0, index 47, request), then DS_Read(slot 0, index 47, 240)
    write = pd.write_request(READ_P2_P3_PDU)
    assert write.encode() == b(0x5F, 0, 47, 16) + READ_P2_P3
    assert pd.read_request().encode() == b(0x5E, 0, 47, 240)
    # whole telegrams, master 2 -> slave 5 and the reply (computed from 1.2 / 1.10)
    fc = RequestFc(RequestFunction.SRD_HIGH, fcv=True)
    frame = dpv1.build_request(write, da=5, sa=2, fc=fc).encode()
    assert frame == bytes.fromhex(
        "68 19 19 68 85 82 5D 33 33 5F 00 2F 10"
        " 01 01 00 02 10 01 00 02 00 00 10 01 00 03 00 00 93 16"
    )
    reply = bytes.fromhex(
        "68 15 15 68 82 85 08 33 33 5E 00 2F 0C 01 01 00 02 42 01 00 64 42 01 00 32 2E 16"
    )
    telegram = decode_telegram(reply)
    assert isinstance(telegram, DataTelegram)
    assert telegram.fc == ResponseFc(ResponseStatus.DL)
    read = dpv1.decode_response(telegram.data)
    assert read == dpv1.ReadResponse(0, 47, READ_P2_P3_OK)
    assert ParameterResponse.decode(read.data) == READ_P2_P3_OK_PDU


def test_fact_sheet_ds_write_examples_with_header() -> None:
    # fact sheet 1.11: "5F 01 2F 0A | ..." (ABB, slot 1) and "5F 00 2F 0E | ..." (Toshiba)
    abb = pd.write_request(ABB_READ_12_04_PDU, slot=1)
    assert abb.encode() == b(0x5F, 0x01, 0x2F, 0x0A) + ABB_READ_12_04
    toshiba = pd.write_request(TOSHIBA_WRITE_927_PDU, slot=0)
    assert toshiba.encode() == b(0x5F, 0x00, 0x2F, 0x0E) + TOSHIBA_WRITE_927
    for wire, pdu in (
        (abb.encode(), ABB_READ_12_04_PDU),
        (toshiba.encode(), TOSHIBA_WRITE_927_PDU),
    ):
        request = dpv1.decode_request(wire)
        assert isinstance(request, dpv1.WriteRequest)
        assert request.index == pd.PARAMETER_INDEX
        assert ParameterRequest.decode(request.data) == pdu


def test_several_formats_and_padding() -> None:
    request = ParameterRequest.change(
        9,
        [
            (ParameterAddress(1), ValueBlock(DataFormat.BYTE, (0xAB,))),  # 1 byte + pad
            (ParameterAddress(2, 3, 2), ValueBlock(DataFormat.INTEGER16, (-1, 2))),
            (ParameterAddress(4), ValueBlock(DataFormat.FLOAT, (1.5,))),
        ],
    )
    wire = request.encode()
    assert wire == bytes.fromhex(
        "09 02 00 03"
        " 10 01 00 01 00 00  10 02 00 02 00 03  10 01 00 04 00 00"
        " 41 01 AB 00  03 02 FF FF 00 02  08 01 3F C0 00 00"
    )
    assert ParameterRequest.decode(wire) == request


def test_error_number_tables() -> None:
    # WEG Table 4.2 / 5.2 "Error code", as printed
    assert dict(pd.WEG_PARAMETER_ERROR_TEXTS) == {
        0x0000: "parameter does not exist",
        0x0001: "modification of read-only parameter",
        0x0002: "parameter value out of the limits",
        0x0003: "indicated sub-index does not exist",
        0x0004: "parameter not of the array type",
        0x0005: "incorrect format for the parameter",
        0x0009: "description not available (only value)",
        0x000F: "text not available (only value)",
        0x0016: "incorrect access to the parameter",
        0x0017: "unknown format",
        0x0018: "incorrect number of values",
    }
    # fact sheet 1.11 codes all have a generic text
    for code in (0, 1, 2, 3, 4, 5, 6, 7, 9, 0x0B, 0x0F, 0x11, 0x14, 0x15, 0x16, 0x17, 0x18, 0x19):
        assert code in pd.PROFIDRIVE_ERROR_TEXTS
    assert pd.parameter_error_text(0x65) == "vendor specific error"
    assert pd.parameter_error_text(0x08) == "reserved error number"
    assert pd.parameter_error_text(0x65, {0x65: "mine"}) == "mine"


@pytest.mark.parametrize(
    ("wire", "pdu_type", "reason"),
    [
        (b(1, 1, 0), ParameterRequest, DecodeFailure.TRUNCATED),
        (b(1, 3, 0, 1), ParameterRequest, DecodeFailure.UNKNOWN_FUNCTION),
        (b(1, 1, 0, 0), ParameterRequest, DecodeFailure.BAD_FIELD),
        (b(1, 1, 0, 2, 0x10, 1, 0, 2, 0, 0), ParameterRequest, DecodeFailure.TRUNCATED),
        (READ_P2_P3 + b(0), ParameterRequest, DecodeFailure.TRAILING_BYTES),
        (b(1, 1, 0, 1, 0x11, 1, 0, 2, 0, 0), ParameterRequest, DecodeFailure.UNKNOWN_FUNCTION),
        (WRITE_P100[:-1], ParameterRequest, DecodeFailure.TRUNCATED),
        (WRITE_P100[:10], ParameterRequest, DecodeFailure.TRUNCATED),
        (WRITE_P100 + b(0x42, 1, 0, 1), ParameterRequest, DecodeFailure.TRAILING_BYTES),
        (
            b(1, 2, 0, 1, 0x10, 1, 0, 1, 0, 0, 0x99, 1, 0, 0),
            ParameterRequest,
            DecodeFailure.UNKNOWN_FUNCTION,
        ),
        (b(1, 1, 0, 2, 0x42, 1, 0, 100), ParameterResponse, DecodeFailure.BAD_LENGTH),
        (b(1, 2, 0, 1, 0x42, 1, 0, 1), ParameterResponse, DecodeFailure.BAD_LENGTH),
        (b(1, 0x83, 0, 1), ParameterResponse, DecodeFailure.UNKNOWN_FUNCTION),
        (b(1, 0x82, 0, 1), ParameterResponse, DecodeFailure.BAD_LENGTH),
        (b(1, 1, 0, 1, 0x40, 1), ParameterResponse, DecodeFailure.BAD_FIELD),
        (b(1, 1, 0, 1, 0x43, 1, 0, 0), ParameterResponse, DecodeFailure.TRUNCATED),
        (b(1, 1, 0, 1, 0x42), ParameterResponse, DecodeFailure.TRUNCATED),
        (b(1, 1), ParameterResponse, DecodeFailure.TRUNCATED),
        (b(1, 1, 0, 0), ParameterResponse, DecodeFailure.BAD_FIELD),
    ],
)
def test_decode_errors(
    wire: bytes, pdu_type: type[ParameterRequest | ParameterResponse], reason: DecodeFailure
) -> None:
    with pytest.raises(ProfidriveDecodeError) as info:
        pdu_type.decode(wire)
    assert info.value.reason is reason
    assert info.value.raw == wire


def test_encode_errors() -> None:
    address = ParameterAddress(1)
    with pytest.raises(FrameEncodeError):  # read carries no values
        ParameterRequest(1, RequestId.READ, (address,), (ValueBlock.word(1),)).encode()
    with pytest.raises(FrameEncodeError):  # change needs one block per parameter
        ParameterRequest(1, RequestId.CHANGE, (address,)).encode()
    with pytest.raises(FrameEncodeError):
        ParameterRequest(1, RequestId.READ, ()).encode()
    with pytest.raises(FrameEncodeError):  # 41 parameters do not fit 240 bytes
        ParameterRequest.read(1, *[address] * 40).encode()
    with pytest.raises(FrameEncodeError):
        ValueBlock.word(0x10000).encode()
    with pytest.raises(FrameEncodeError):
        ValueBlock(DataFormat.WORD, (1.5,)).encode()
    with pytest.raises(FrameEncodeError):
        ValueBlock(DataFormat.ZERO, (1,)).encode()
    with pytest.raises(FrameEncodeError):
        ParameterResponse(1, ResponseId.CHANGE_OK, 1, (ValueBlock.word(1),)).encode()
    with pytest.raises(FrameEncodeError):
        ParameterResponse(1, ResponseId.READ_OK, 2, (ValueBlock.word(1),)).encode()


# --------------------------------------------------------------------------- round trips

_RANGES = {
    DataFormat.INTEGER8: st.integers(-128, 127),
    DataFormat.INTEGER16: st.integers(-32768, 32767),
    DataFormat.INTEGER32: st.integers(-(2**31), 2**31 - 1),
    DataFormat.UNSIGNED8: st.integers(0, 255),
    DataFormat.UNSIGNED16: st.integers(0, 0xFFFF),
    DataFormat.UNSIGNED32: st.integers(0, 2**32 - 1),
    DataFormat.FLOAT: st.floats(width=32, allow_nan=False),
    DataFormat.BYTE: st.integers(0, 255),
    DataFormat.WORD: st.integers(0, 0xFFFF),
    DataFormat.DOUBLE_WORD: st.integers(0, 2**32 - 1),
    DataFormat.ERROR: st.integers(0, 0xFFFF),
}


@st.composite
def value_blocks(draw: st.DrawFn, max_values: int = 4) -> ValueBlock:
    fmt = draw(st.sampled_from(DataFormat))
    if fmt == DataFormat.ZERO:
        return ValueBlock(fmt)
    values = draw(st.lists(_RANGES[fmt], max_size=max_values))
    return ValueBlock(fmt, tuple(values))


addresses = st.builds(
    ParameterAddress,
    st.integers(0, 0xFFFF),
    st.integers(0, 0xFFFF),
    st.integers(0, 255),
    st.sampled_from(Attribute),
)
u8 = st.integers(0, 255)


@st.composite
def requests(draw: st.DrawFn) -> ParameterRequest:
    params = tuple(draw(st.lists(addresses, min_size=1, max_size=6)))
    if draw(st.booleans()):
        return ParameterRequest(draw(u8), RequestId.READ, params, (), draw(u8))
    values = tuple(draw(value_blocks()) for _ in params)
    return ParameterRequest(draw(u8), RequestId.CHANGE, params, values, draw(u8))


@st.composite
def responses(draw: st.DrawFn) -> ParameterResponse:
    response_id = draw(st.sampled_from(ResponseId))
    blocks = tuple(draw(st.lists(value_blocks(), min_size=1, max_size=6)))
    ref, axis = draw(u8), draw(u8)
    if response_id == ResponseId.CHANGE_OK:
        return ParameterResponse(ref, response_id, len(blocks), (), axis)
    if response_id == ResponseId.CHANGE_ERROR:
        extra = draw(st.integers(0, 3))
        return ParameterResponse(ref, response_id, len(blocks) + extra, blocks, axis)
    return ParameterResponse(ref, response_id, len(blocks), blocks, axis)


def _same(a: object, b: object) -> bool:
    """Equality that treats -0.0 and 0.0 floats as the same only when their bits match."""
    return a == b and repr(a) == repr(b)


@FAST
@given(requests())
def test_request_round_trip(pdu: ParameterRequest) -> None:
    assert _same(ParameterRequest.decode(pdu.encode()), pdu)


@FAST
@given(responses())
def test_response_round_trip(pdu: ParameterResponse) -> None:
    assert _same(ParameterResponse.decode(pdu.encode()), pdu)


@FAST
@given(st.binary(max_size=60))
def test_decoders_raise_only_typed_errors(raw: bytes) -> None:
    for pdu_type in (ParameterRequest, ParameterResponse):
        try:
            result = pdu_type.decode(raw)
        except ProfidriveDecodeError as exc:
            assert exc.raw == raw
            continue
        wire = result.encode()  # whatever decodes, encodes again, and stably so
        assert pdu_type.decode(wire).encode() == wire
