"""DP-V1 MSAC_C1 PDUs and error codes (fact sheet 1.10; WEG DS_Read/DS_Write tables)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.diag import AlarmDiag, AlarmSpecifier, AlarmType
from adapters.profibus.codec.dpv1 import (
    WEG_ERROR_CODE_1_TEXTS,
    AlarmAck,
    Dpv1ErrorResponse,
    Dpv1Function,
    ErrorDecode,
    ReadRequest,
    ReadResponse,
    WriteRequest,
    WriteResponse,
)
from adapters.profibus.codec.fdl import (
    DataTelegram,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    decode_telegram,
)
from adapters.profibus.errors import DecodeFailure, Dpv1DecodeError
from gateway.errors import FrameEncodeError

h = bytes.fromhex
FAST = settings(max_examples=50, deadline=None)


def test_read_index_47_frame_golden() -> None:
    frame = h("68 09 09 68 85 82 7D 33 33 5E 00 2F F0 67 16")  # fact sheet 1.10 example
    fc = RequestFc(RequestFunction.SRD_HIGH, fcb=True, fcv=True)
    request = ReadRequest(slot=0, index=47, length=240)
    assert dpv1.build_request(request, da=5, sa=2, fc=fc).encode() == frame
    telegram = decode_telegram(frame)
    assert isinstance(telegram, DataTelegram)
    assert (telegram.dsap, telegram.ssap) == (51, 51)
    assert dpv1.decode_request(telegram.data) == request


# WEG CFW-11 4.2.3 / CFW700 5.2.3 / CFW320 5.2.3 telegram tables (slot 0, index 47)
PDU_GOLDEN = [
    ("5F 00 2F 02 AB CD", WriteRequest(0, 47, h("ABCD")), "request"),  # "5Fh 0 47 n data"
    ("5F 00 2F 00", WriteResponse(0, 47, 0), "response"),  # positive write reply, size 0
    ("5E 00 2F F0", ReadRequest(0, 47, 240), "request"),  # read request, size 240
    ("5E 00 2F 02 00 64", ReadResponse(0, 47, h("0064")), "response"),
    ("DF 80 B0 00", Dpv1ErrorResponse(Dpv1Function.WRITE, 128, 0xB0, 0), "response"),
    ("DE 80 C3 00", Dpv1ErrorResponse(Dpv1Function.READ, 128, 0xC3, 0), "response"),
    ("DE 80 B5 00", Dpv1ErrorResponse(Dpv1Function.READ, 0x80, 0xB5), "response"),  # 1.11
    ("5C 01 01 2D", AlarmAck(1, 1, AlarmSpecifier.APPEARS, True, 5), "request"),  # computed
]


@pytest.mark.parametrize(("wire", "pdu", "side"), PDU_GOLDEN)
def test_pdu_golden_both_directions(wire: str, pdu: object, side: str) -> None:
    decode = dpv1.decode_request if side == "request" else dpv1.decode_response
    assert decode(h(wire)) == pdu
    assert pdu.encode() == h(wire)


# Seeds, Error Code 1 (identical in CFW-11 4.2.3 (pt), CFW700 5.2.3, CFW320 5.2.3)
WEG_SEED_TEXTS = {
    0xB0: "access error - invalid slot",
    0xB2: "access error - invalid index",
    0xB5: "access error - modification not allowed for the parameter",
    0xB6: "access error - modification in read-only parameter",
    0xB7: "access error - incorrect values for parameter access",
    0xB8: "access error - invalid parameter number",
    0xC3: "resource error - response not available for the reading request",
}


def test_weg_error_table_is_the_seeds_table() -> None:
    assert dict(WEG_ERROR_CODE_1_TEXTS) == WEG_SEED_TEXTS


@pytest.mark.parametrize(("code", "text"), sorted(WEG_SEED_TEXTS.items()))
def test_weg_error_codes_decode_with_text(code: int, text: str) -> None:
    for function, first in ((Dpv1Function.READ, 0xDE), (Dpv1Function.WRITE, 0xDF)):
        error = dpv1.decode_response(bytes((first, 0x80, code, 0x00)))
        assert isinstance(error, Dpv1ErrorResponse)
        assert error.function is function
        assert error.error_decode == ErrorDecode.DPV1
        assert error.error_code_1 == code
        assert error.error_code_2 == 0
        assert error.text_in(WEG_ERROR_CODE_1_TEXTS) == text


@pytest.mark.parametrize(
    ("code_1", "error_class", "error_code", "text"),
    [
        (0xA0, 0xA, 0, "application error - read error"),
        (0xA9, 0xA, 9, "application error - feature not supported"),
        (0xB0, 0xB, 0, "access error - invalid index"),
        (0xB2, 0xB, 2, "access error - invalid slot"),
        (0xB5, 0xB, 5, "access error - state conflict"),
        (0xB9, 0xB, 9, "access error - invalid type"),
        (0xC2, 0xC, 2, "resource error - resource busy"),
        (0xC3, 0xC, 3, "resource error - resource unavailable"),
        (0xAF, 0xA, 15, "application error - reserved or user specific code 15"),
        (0xD1, 0xD, 1, "reserved or user specific error class 0xD, code 1"),
    ],
)
def test_generic_error_split_and_texts(
    code_1: int, error_class: int, error_code: int, text: str
) -> None:
    error = Dpv1ErrorResponse(Dpv1Function.READ, ErrorDecode.DPV1, code_1)
    assert (error.error_class, error.error_code) == (error_class, error_code)
    assert error.text == text
    # a device table wins where it has the code, the generic table covers the rest
    assert error.text_in({}) == text


def test_fms_and_hart_error_texts() -> None:
    assert Dpv1ErrorResponse(Dpv1Function.READ, 0xFE, 0x12).text == "FMS error 0x12"
    assert Dpv1ErrorResponse(Dpv1Function.READ, 0xFF, 0x01).text == "HART error 0x01"
    assert Dpv1ErrorResponse(Dpv1Function.READ, 0x10, 0x01).text == "unknown error 0x01"


def test_alarm_ack_for_alarm_goes_to_sap_50() -> None:
    alarm = AlarmDiag(AlarmType.PROCESS, 3, AlarmSpecifier.APPEARS, False, 7)
    ack = AlarmAck.for_alarm(alarm)
    assert ack.encode() == h("5C 03 02 39")
    fc = RequestFc(RequestFunction.SRD_HIGH, True, True)
    telegram = dpv1.build_request(ack, da=5, sa=2, fc=fc)
    assert (telegram.dsap, telegram.ssap) == (50, 51)


def test_response_telegram_swaps_saps_and_poll() -> None:
    fc = RequestFc(RequestFunction.SRD_HIGH, True, True)
    request = dpv1.build_request(ReadRequest(0, 47), da=5, sa=2, fc=fc)
    reply = dpv1.build_response(ReadResponse(0, 47, h("0102")), request=request)
    assert (reply.da, reply.sa, reply.dsap, reply.ssap) == (2, 5, 51, 51)
    assert reply.fc == ResponseFc(ResponseStatus.DL)
    assert dpv1.decode_response(reply.data) == ReadResponse(0, 47, h("0102"))
    poll = dpv1.poll_request(da=5, sa=2, fc=fc)
    assert (poll.dsap, poll.ssap, poll.data) == (51, 51, b"")


@pytest.mark.parametrize(
    ("wire", "side", "reason"),
    [
        ("", "response", DecodeFailure.TRUNCATED),
        ("5E 00 2F", "request", DecodeFailure.TRUNCATED),
        ("5E 00 2F F1", "request", DecodeFailure.BAD_LENGTH),  # > 240
        ("5E 00 2F F0 00", "request", DecodeFailure.TRAILING_BYTES),
        ("5F 00 2F 03 01 02", "request", DecodeFailure.BAD_LENGTH),
        ("5E 00 2F 01", "response", DecodeFailure.BAD_LENGTH),
        ("5F 00 2F 00 00", "response", DecodeFailure.TRAILING_BYTES),
        ("DE 80 B5", "response", DecodeFailure.TRUNCATED),
        ("C0 80 B5 00", "response", DecodeFailure.UNKNOWN_FUNCTION),
        ("DE 80 B5 00", "request", DecodeFailure.UNKNOWN_FUNCTION),
        ("01 00 00 00", "request", DecodeFailure.UNKNOWN_FUNCTION),
        ("57 00 00 00", "request", DecodeFailure.UNSUPPORTED),  # Initiate is MSAC_C2
    ],
)
def test_decode_errors(wire: str, side: str, reason: DecodeFailure) -> None:
    decode = dpv1.decode_request if side == "request" else dpv1.decode_response
    with pytest.raises(Dpv1DecodeError) as info:
        decode(h(wire))
    assert info.value.reason is reason
    assert info.value.raw == h(wire)


def test_encode_errors() -> None:
    with pytest.raises(FrameEncodeError):
        WriteRequest(0, 47, bytes(241)).encode()
    with pytest.raises(FrameEncodeError):
        ReadRequest(0, 256).encode()
    with pytest.raises(FrameEncodeError):
        Dpv1ErrorResponse(0x01, 0x80, 0xB0).encode()  # type: ignore[arg-type]


u8 = st.integers(0, 255)
pdus = st.one_of(
    st.builds(ReadRequest, u8, u8, st.integers(0, 240)),
    st.builds(WriteRequest, u8, u8, st.binary(max_size=240)),
    st.builds(
        AlarmAck,
        u8,
        st.integers(0, 127),
        st.sampled_from(AlarmSpecifier),
        st.booleans(),
        st.integers(0, 31),
    ),
)
responses = st.one_of(
    st.builds(ReadResponse, u8, u8, st.binary(max_size=240)),
    st.builds(WriteResponse, u8, u8, st.integers(0, 240)),
    st.builds(
        AlarmAck,
        u8,
        st.integers(0, 127),
        st.sampled_from(AlarmSpecifier),
        st.booleans(),
        st.integers(0, 31),
    ),
    st.builds(Dpv1ErrorResponse, st.sampled_from(Dpv1Function), u8, u8, u8),
)


@FAST
@given(pdus)
def test_request_round_trip(pdu: dpv1.Dpv1Request) -> None:
    assert dpv1.decode_request(pdu.encode()) == pdu


@FAST
@given(responses)
def test_response_round_trip(pdu: dpv1.Dpv1Response) -> None:
    assert dpv1.decode_response(pdu.encode()) == pdu


@FAST
@given(st.binary(max_size=12) | st.binary(min_size=4, max_size=250))
def test_decoders_raise_only_typed_errors(raw: bytes) -> None:
    for decode in (dpv1.decode_request, dpv1.decode_response):
        try:
            decode(raw)
        except Dpv1DecodeError as exc:
            assert exc.raw == raw
