"""Explicit message bodies (fact sheet 2.4, 2.5, 2.7, 2.10; seed 5.10)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.cip import AllocationRejection, GeneralStatus, allocation_rejection
from adapters.devicenet.codec.datatypes import CipType, decode_value, encode_value
from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    BodyFormat,
    ErrorResponse,
    ExplicitMessage,
    GenericRequest,
    GetAttributesAll,
    GetAttributeSingle,
    ReleaseConnectionSet,
    Reset,
    SetAttributeSingle,
    SuccessResponse,
    error_text,
)
from adapters.devicenet.codec.objects import AllocationChoice
from adapters.devicenet.errors import DeviceNetDecodeError, ExplicitDecodeError
from gateway.errors import FrameEncodeError
from tests.devicenet.strategies import messages

EXPLICIT_POLL = AllocationChoice.EXPLICIT | AllocationChoice.POLL
MASTER = 0  # fact sheet 2.2 examples: master MAC 0

# (message, wire bytes). Layouts and values from the fact sheet, verbatim where it gives bytes.
GOLDEN = [
    # 2.5 Allocate request [hdr(master MAC), 4B, 03, 01, choice, allocator MAC]; 2.10 choice 0x03.
    (
        ExplicitMessage(MASTER, False, AllocateConnectionSet(EXPLICIT_POLL, MASTER)),
        "00 4B 03 01 03 00",
    ),
    # 2.5 success reply [hdr, CB, body format]; 0 = 8/8.
    (ExplicitMessage(MASTER, False, AllocateResponse(0)), "00 CB 00"),
    # 2.5 Release [hdr, 4C, 03, 01, choice]; success [hdr, CC].
    (ExplicitMessage(MASTER, False, ReleaseConnectionSet(EXPLICIT_POLL)), "00 4C 03 01 03"),
    (ExplicitMessage(MASTER, False, SuccessResponse(0x4C)), "00 CC"),
    # 2.5 rejection "owned by another master" 0x0C / 0x01 as [hdr, 94, status, additional].
    (ExplicitMessage(MASTER, False, ErrorResponse(0x0C, 0x01)), "00 94 0C 01"),
    (ExplicitMessage(MASTER, False, ErrorResponse(0x14)), "00 94 14 FF"),
    # Seed 5.10: P023 = class 64h, instance 1, attribute 123; P432 = class 68h, attribute 132.
    (ExplicitMessage(MASTER, False, GetAttributeSingle(0x64, 1, 123)), "00 0E 64 01 7B"),
    (ExplicitMessage(MASTER, True, GetAttributeSingle(0x68, 1, 132)), "40 0E 68 01 84"),
    # 2.10 step 5: set the poll EPR [hdr, 10, 05, 02, 09, lo, hi] -> [hdr, 90, lo, hi].
    (
        ExplicitMessage(MASTER, False, SetAttributeSingle(5, 2, 9, b"\x64\x00")),
        "00 10 05 02 09 64 00",
    ),
    (ExplicitMessage(MASTER, False, SuccessResponse(0x10, b"\x64\x00")), "00 90 64 00"),
    # 2.7 Reset [hdr, 05, class, inst] (type byte ✖).
    (ExplicitMessage(MASTER, False, Reset(1, 1)), "00 05 01 01"),
    (ExplicitMessage(MASTER, False, Reset(1, 1, 0)), "00 05 01 01 00"),
    (ExplicitMessage(MASTER, False, GetAttributesAll(1, 1)), "00 01 01 01"),
    # Identity vendor id 355h (seed table 8) in a Get_Attribute_Single reply.
    (ExplicitMessage(MASTER, False, SuccessResponse(0x0E, b"\x55\x03")), "00 8E 55 03"),
    (ExplicitMessage(63, True, GenericRequest(0x16, 0x64, 1)), "7F 16 64 01"),
]


@pytest.mark.parametrize(("message", "wire"), GOLDEN)
def test_golden_both_directions(message, wire):
    assert message.encode() == bytes.fromhex(wire)
    assert ExplicitMessage.decode(bytes.fromhex(wire)) == message


def test_scanner_reads_a_weg_parameter_and_matches_the_reply():
    request = ExplicitMessage(MASTER, True, GetAttributeSingle(0x66, 1, 102))  # P202, seed 5.10
    reply = ExplicitMessage.decode(bytes.fromhex("40 8E 05 00"))
    assert reply.answers(request)
    assert isinstance(reply.body, SuccessResponse)
    assert decode_value(CipType.UINT, reply.body.data) == 5
    assert not ExplicitMessage(MASTER, False, reply.body).answers(request)  # XID differs
    assert not reply.answers(reply)


def test_simulated_slave_decodes_a_request_and_encodes_the_reply():
    request = ExplicitMessage.decode(bytes.fromhex("00 10 05 02 09 64 00"))
    assert request.is_request
    body = request.body
    assert isinstance(body, SetAttributeSingle)
    epr = decode_value(CipType.UINT, body.value)
    reply = request.reply(SuccessResponse(body.service, encode_value(CipType.UINT, epr)))
    assert reply.encode() == bytes.fromhex("00 90 64 00")
    assert reply.answers(request)


def test_allocation_error_reads_back_as_a_rejection():
    reply = ExplicitMessage.decode(bytes.fromhex("00 94 0C 01"))
    assert isinstance(reply.body, ErrorResponse)
    assert reply.body.text == "Object state conflict"
    assert error_text(reply.body) == "0x0C Object state conflict (additional 0x01)"
    rejection = allocation_rejection(reply.body.general_status, reply.body.additional_code)
    assert rejection is AllocationRejection.OWNED_BY_ANOTHER_MASTER
    assert error_text(ErrorResponse(0x16)) == "0x16 Object does not exist"


def test_allocate_response_body_format():
    assert AllocateResponse(0).body_format is BodyFormat.CLASS8_INSTANCE8
    assert AllocateResponse(0x03).body_format is BodyFormat.CLASS16_INSTANCE8
    assert AllocateResponse(0x0F).body_format is None


@pytest.mark.parametrize(
    ("body_format", "message", "wire"),
    [
        (BodyFormat.CLASS8_INSTANCE16, GetAttributeSingle(0x64, 0x1234, 1), "00 0E 64 34 12 01"),
        (BodyFormat.CLASS16_INSTANCE16, GetAttributesAll(0x0300, 0x0102), "00 01 00 03 02 01"),
        (BodyFormat.CLASS16_INSTANCE8, Reset(0x0401, 7), "00 05 01 04 07"),
    ],
)
def test_16_bit_body_formats(body_format, message, wire):
    # Fact sheet 2.4: 16-bit ids little-endian.
    assert ExplicitMessage(0, False, message).encode(body_format) == bytes.fromhex(wire)
    assert ExplicitMessage.decode(bytes.fromhex(wire), body_format).body == message


def test_class_too_wide_for_the_body_format():
    with pytest.raises(FrameEncodeError):
        ExplicitMessage(0, False, GetAttributeSingle(0x100, 1, 1)).encode()


# Malformed requests: the error names the general status a server answers with.
@pytest.mark.parametrize(
    ("wire", "status"),
    [
        ("00", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 0E 64", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 0E 64 01", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 0E 64 01 7B 00", GeneralStatus.TOO_MUCH_DATA),
        ("00 10 05 02 09", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 01 01 01 00", GeneralStatus.TOO_MUCH_DATA),
        ("00 05 01 01 00 00", GeneralStatus.TOO_MUCH_DATA),
        ("00 4B 03 01 03", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 4B 03 01 03 00 00", GeneralStatus.TOO_MUCH_DATA),
        ("00 4B 03 01 03 40", GeneralStatus.INVALID_PARAMETER_VALUE),
        ("00 4C 03 01", GeneralStatus.NOT_ENOUGH_DATA),
        ("00 4C 03 01 03 03", GeneralStatus.TOO_MUCH_DATA),
    ],
)
def test_malformed_request_suggests_a_status(wire, status):
    with pytest.raises(ExplicitDecodeError) as info:
        ExplicitMessage.decode(bytes.fromhex(wire), arbitration_id=0x456)
    error = info.value
    assert error.general_status == status
    assert error.raw == bytes.fromhex(wire)
    assert error.mac == 0
    assert error.xid is False
    assert error.arbitration_id == 0x456


@pytest.mark.parametrize(
    "wire", ["", "80 00 0E 64", "00 94 0C", "00 94 0C 01 00", "00 CB", "00 CB 00 00"]
)
def test_malformed_messages_and_responses(wire):
    with pytest.raises(ExplicitDecodeError) as info:
        ExplicitMessage.decode(bytes.fromhex(wire))
    assert info.value.general_status is None


@pytest.mark.parametrize(
    "build",
    [
        lambda: ExplicitMessage(64, False, Reset(1, 1)),
        lambda: ExplicitMessage(0, 1, Reset(1, 1)),  # type: ignore[arg-type]
        lambda: ExplicitMessage(0, False, "get"),  # type: ignore[arg-type]
        lambda: GetAttributeSingle(1, 1, 256),
        lambda: GetAttributeSingle(-1, 1, 1),
        lambda: SetAttributeSingle(1, 1, 1, b""),
        lambda: AllocateConnectionSet(EXPLICIT_POLL, 64),
        lambda: ReleaseConnectionSet(AllocationChoice(0x100)),
        lambda: GenericRequest(0x0E, 1, 1),  # has its own type
        lambda: GenericRequest(0x80, 1, 1),
        lambda: SuccessResponse(0x14),  # that is an error response
        lambda: SuccessResponse(0x4B),  # that is an allocate response
        lambda: ErrorResponse(0x100),
        lambda: Reset(1, 1, 256),
    ],
)
def test_encode_errors(build):
    with pytest.raises(FrameEncodeError):
        build()


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(BodyFormat).flatmap(lambda f: st.tuples(st.just(f), messages(f))))
def test_round_trip_every_message_type(format_and_message):
    body_format, message = format_and_message
    wire = message.encode(body_format)
    assert ExplicitMessage.decode(wire, body_format) == message


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=12), st.sampled_from(BodyFormat))
def test_fuzz_raises_only_typed_errors_and_decodes_canonically(data, body_format):
    try:
        message = ExplicitMessage.decode(data, body_format)
    except DeviceNetDecodeError as exc:
        assert exc.raw == data
        return
    assert message.encode(body_format) == data


@settings(max_examples=200, deadline=None)
@given(
    st.integers(0, 0x7F),
    st.sampled_from([0x0E, 0x10, 0x01, 0x05, 0x4B, 0x4C, 0x8E, 0x94, 0xCB]),
    st.binary(max_size=6),
)
def test_fuzz_known_services(header, service, rest):
    data = bytes((header, service)) + rest
    try:
        message = ExplicitMessage.decode(data)
    except DeviceNetDecodeError:
        return
    assert message.encode() == data
