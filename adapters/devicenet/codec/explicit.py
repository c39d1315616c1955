"""Explicit message bodies (unfragmented or reassembled) for a Group 2 Only slave.

Fact sheet 2.4 (header byte b7 frag, b6 XID, b5-0 MAC; byte 1 b7 R/R, b6-0
service; 8/8 body class, instance, data; success ``[hdr, svc|0x80, data]``; error
``[hdr, 0x94, general status, additional code]``), 2.5 (Allocate/Release layouts),
2.7 (service request layouts). The same code serves both ends: the scanner encodes
requests and decodes responses, a simulated slave decodes requests and encodes
responses. A malformed request raises :class:`ExplicitDecodeError` carrying the
general status the server should answer with.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from adapters.devicenet.codec.cip import (
    NO_ADDITIONAL_CODE,
    GeneralStatus,
    Service,
    general_status_text,
)
from adapters.devicenet.codec.ids import MAX_MAC
from adapters.devicenet.codec.objects import AllocationChoice
from adapters.devicenet.codec.validate import check_bytes
from adapters.devicenet.errors import ExplicitDecodeError
from gateway.errors import FrameEncodeError, require_int

FRAG_BIT = 0x80  # byte 0 b7 (fact sheet 2.4)
XID_BIT = 0x40  # byte 0 b6
MAC_MASK = 0x3F  # byte 0 b5-0
RESPONSE_BIT = 0x80  # byte 1 b7 R/R (fact sheet 2.4)
SERVICE_MASK = 0x7F  # byte 1 b6-0
DEVICENET_CLASS = 0x03  # Allocate/Release target: class 3, instance 1 (fact sheet 2.5)
DEVICENET_INSTANCE = 0x01


class BodyFormat(IntEnum):
    """Message body formats (fact sheet 2.4, 2.5): class id / instance id widths in bits."""

    CLASS8_INSTANCE8 = 0
    CLASS8_INSTANCE16 = 1
    CLASS16_INSTANCE16 = 2
    CLASS16_INSTANCE8 = 3


# (class id bytes, instance id bytes); 16-bit ids are little-endian (fact sheet 2.4).
_ID_WIDTHS: dict[BodyFormat, tuple[int, int]] = {
    BodyFormat.CLASS8_INSTANCE8: (1, 1),
    BodyFormat.CLASS8_INSTANCE16: (1, 2),
    BodyFormat.CLASS16_INSTANCE16: (2, 2),
    BodyFormat.CLASS16_INSTANCE8: (2, 1),
}


# ---------------------------------------------------------------- requests (R/R = 0)


def _check_path(class_id: int, instance_id: int) -> None:
    require_int("class id", class_id, 0, 0xFFFF)
    require_int("instance id", instance_id, 0, 0xFFFF)


@dataclass(frozen=True, slots=True)
class GetAttributeSingle:
    """Get_Attribute_Single: ``[hdr, 0E, class, inst, attr]`` (fact sheet 2.7)."""

    service: ClassVar[int] = Service.GET_ATTRIBUTE_SINGLE
    class_id: int
    instance_id: int
    attribute_id: int

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        require_int("attribute id", self.attribute_id, 0, 0xFF)

    def encode_data(self) -> bytes:
        return bytes((self.attribute_id,))


@dataclass(frozen=True, slots=True)
class SetAttributeSingle:
    """Set_Attribute_Single: ``[hdr, 10, class, inst, attr, value...]`` (fact sheet 2.7)."""

    service: ClassVar[int] = Service.SET_ATTRIBUTE_SINGLE
    class_id: int
    instance_id: int
    attribute_id: int
    value: bytes

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        require_int("attribute id", self.attribute_id, 0, 0xFF)
        value = check_bytes("attribute value", self.value)
        if not value:
            raise FrameEncodeError("Set_Attribute_Single needs a value of at least one byte")
        object.__setattr__(self, "value", value)

    def encode_data(self) -> bytes:
        return bytes((self.attribute_id,)) + self.value


@dataclass(frozen=True, slots=True)
class GetAttributesAll:
    """Get_Attributes_All: ``[hdr, 01, class, inst]`` (fact sheet 2.7)."""

    service: ClassVar[int] = Service.GET_ATTRIBUTES_ALL
    class_id: int
    instance_id: int

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)

    def encode_data(self) -> bytes:
        return b""


@dataclass(frozen=True, slots=True)
class SetAttributesAll:
    """Set_Attributes_All: ``[hdr, 02, class, inst, data...]`` (fact sheet 2.7)."""

    service: ClassVar[int] = Service.SET_ATTRIBUTES_ALL
    class_id: int
    instance_id: int
    data: bytes

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        object.__setattr__(self, "data", check_bytes("attribute data", self.data))

    def encode_data(self) -> bytes:
        return self.data


@dataclass(frozen=True, slots=True)
class Reset:
    """Reset: ``[hdr, 05, class, inst]`` plus an optional type byte (fact sheet 2.7, ✖)."""

    service: ClassVar[int] = Service.RESET
    class_id: int
    instance_id: int
    reset_type: int | None = None

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        if self.reset_type is not None:
            require_int("reset type", self.reset_type, 0, 0xFF)

    def encode_data(self) -> bytes:
        return b"" if self.reset_type is None else bytes((self.reset_type,))


@dataclass(frozen=True, slots=True)
class AllocateConnectionSet:
    """Allocate_Master/Slave_Connection_Set: ``[hdr, 4B, 03, 01, choice, allocator MAC]``.

    Fact sheet 2.5; sent on G2 message 6 (the Group 2 Only unconnected port).
    """

    service: ClassVar[int] = Service.ALLOCATE_MASTER_SLAVE_CONNECTION_SET
    choice: AllocationChoice
    allocator_mac: int
    class_id: int = DEVICENET_CLASS
    instance_id: int = DEVICENET_INSTANCE

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        require_int("allocation choice", self.choice, 0, 0xFF)
        require_int("allocator MAC", self.allocator_mac, 0, MAX_MAC)
        object.__setattr__(self, "choice", AllocationChoice(self.choice))

    def encode_data(self) -> bytes:
        return bytes((int(self.choice), self.allocator_mac))


@dataclass(frozen=True, slots=True)
class ReleaseConnectionSet:
    """Release_Master/Slave_Connection_Set: ``[hdr, 4C, 03, 01, choice]`` (fact sheet 2.5)."""

    service: ClassVar[int] = Service.RELEASE_MASTER_SLAVE_CONNECTION_SET
    choice: AllocationChoice
    class_id: int = DEVICENET_CLASS
    instance_id: int = DEVICENET_INSTANCE

    def __post_init__(self) -> None:
        _check_path(self.class_id, self.instance_id)
        require_int("release choice", self.choice, 0, 0xFF)
        object.__setattr__(self, "choice", AllocationChoice(self.choice))

    def encode_data(self) -> bytes:
        return bytes((int(self.choice),))


@dataclass(frozen=True, slots=True)
class GenericRequest:
    """Any other service (Start, Stop, Save, Restore, vendor services): data kept as bytes."""

    service: int  # a field here, a ClassVar in the other requests
    class_id: int
    instance_id: int
    data: bytes = b""

    def __post_init__(self) -> None:
        require_int("service", self.service, 0, SERVICE_MASK)
        if self.service in _REQUEST_DECODERS:
            raise FrameEncodeError(f"service 0x{self.service:02X} has its own request type; use it")
        _check_path(self.class_id, self.instance_id)
        object.__setattr__(self, "data", check_bytes("request data", self.data))

    def encode_data(self) -> bytes:
        return self.data


Request = (
    GetAttributeSingle
    | SetAttributeSingle
    | GetAttributesAll
    | SetAttributesAll
    | Reset
    | AllocateConnectionSet
    | ReleaseConnectionSet
    | GenericRequest
)


# ---------------------------------------------------------------- responses (R/R = 1)


@dataclass(frozen=True, slots=True)
class SuccessResponse:
    """``[hdr, svc|0x80, data...]`` (fact sheet 2.4); ``data`` is what the service returns."""

    service: int
    data: bytes = b""

    def __post_init__(self) -> None:
        require_int("service", self.service, 0, SERVICE_MASK)
        if self.service in _RESPONSE_DECODERS:
            raise FrameEncodeError(
                f"service 0x{self.service:02X} has its own response type; use it"
            )
        object.__setattr__(self, "data", check_bytes("response data", self.data))

    def encode_data(self) -> bytes:
        return self.data


@dataclass(frozen=True, slots=True)
class AllocateResponse:
    """Allocate success: ``[hdr, CB, message body format]`` (fact sheet 2.5).

    ``message_body_format`` is the byte as sent; :attr:`body_format` reads its low
    nibble (the exact nibble is marked ◐ in the fact sheet).
    """

    service: ClassVar[int] = Service.ALLOCATE_MASTER_SLAVE_CONNECTION_SET
    message_body_format: int = BodyFormat.CLASS8_INSTANCE8

    def __post_init__(self) -> None:
        require_int("message body format", self.message_body_format, 0, 0xFF)

    @property
    def body_format(self) -> BodyFormat | None:
        nibble = self.message_body_format & 0x0F
        return BodyFormat(nibble) if nibble in _ID_WIDTHS else None

    def encode_data(self) -> bytes:
        return bytes((self.message_body_format,))


@dataclass(frozen=True, slots=True)
class ErrorResponse:
    """``[hdr, 94, general status, additional code]`` (fact sheet 2.4, 2.6)."""

    service: ClassVar[int] = Service.ERROR_RESPONSE
    general_status: int
    additional_code: int = NO_ADDITIONAL_CODE

    def __post_init__(self) -> None:
        require_int("general status", self.general_status, 0, 0xFF)
        require_int("additional code", self.additional_code, 0, 0xFF)

    @property
    def text(self) -> str:
        """The general status text of fact sheet 2.6."""
        return general_status_text(self.general_status)

    def encode_data(self) -> bytes:
        return bytes((self.general_status, self.additional_code))


Response = SuccessResponse | AllocateResponse | ErrorResponse
Body = Request | Response


# ---------------------------------------------------------------- the message


@dataclass(frozen=True, slots=True)
class ExplicitMessage:
    """A whole explicit message: header (XID, MAC) and a request or response body.

    ``mac`` is the master's MAC in both directions (fact sheet 2.4: source in a
    request, destination in a response); the frag bit belongs to fragmentation.
    """

    mac: int
    xid: bool
    body: Body

    def __post_init__(self) -> None:
        require_int("MAC ID", self.mac, 0, MAX_MAC)
        if not isinstance(self.xid, bool):
            raise FrameEncodeError(f"XID must be a bool, not {self.xid!r}")
        if not isinstance(self.body, _BODY_TYPES):
            raise FrameEncodeError(f"not an explicit message body: {self.body!r}")

    @property
    def is_request(self) -> bool:
        return not isinstance(self.body, _RESPONSE_TYPES)

    @property
    def header(self) -> int:
        """Byte 0 with the frag bit clear."""
        return (XID_BIT if self.xid else 0) | self.mac

    def encode(self, body_format: BodyFormat = BodyFormat.CLASS8_INSTANCE8) -> bytes:
        """The message bytes; longer than 8 bytes means it must be fragmented to send."""
        body = self.body
        if isinstance(body, _RESPONSE_TYPES):
            return bytes((self.header, RESPONSE_BIT | body.service)) + body.encode_data()
        path = _encode_path(body.class_id, body.instance_id, body_format)
        return bytes((self.header, body.service)) + path + body.encode_data()

    @classmethod
    def decode(
        cls,
        data: bytes,
        body_format: BodyFormat = BodyFormat.CLASS8_INSTANCE8,
        *,
        arbitration_id: int | None = None,
    ) -> ExplicitMessage:
        """Decode an unfragmented (or reassembled) message; only typed errors escape."""
        return _Decoder(bytes(data), arbitration_id).message(body_format)

    def reply(self, body: Response) -> ExplicitMessage:
        """The response to this request: same MAC and XID (fact sheet 2.4, XID ◐)."""
        return ExplicitMessage(self.mac, self.xid, body)

    def answers(self, request: ExplicitMessage) -> bool:
        """Whether this response matches ``request`` (MAC, XID, and service or an error)."""
        if not isinstance(self.body, _RESPONSE_TYPES) or not request.is_request:
            return False
        if (self.mac, self.xid) != (request.mac, request.xid):
            return False
        return isinstance(self.body, ErrorResponse) or self.body.service == request.body.service


_RESPONSE_TYPES = (SuccessResponse, AllocateResponse, ErrorResponse)
_BODY_TYPES = (
    GetAttributeSingle,
    SetAttributeSingle,
    GetAttributesAll,
    SetAttributesAll,
    Reset,
    AllocateConnectionSet,
    ReleaseConnectionSet,
    GenericRequest,
    *_RESPONSE_TYPES,
)


def _encode_path(class_id: int, instance_id: int, body_format: BodyFormat) -> bytes:
    class_width, instance_width = _ID_WIDTHS[body_format]
    for name, value, width in (
        ("class", class_id, class_width),
        ("instance", instance_id, instance_width),
    ):
        if value >= 1 << (8 * width):
            raise FrameEncodeError(f"{name} id {value} does not fit body format {body_format.name}")
    return class_id.to_bytes(class_width, "little") + instance_id.to_bytes(instance_width, "little")


# ---------------------------------------------------------------- decoding


@dataclass(frozen=True, slots=True)
class _Context:
    """What a request decoder gets: the path and the bytes after it."""

    class_id: int
    instance_id: int
    data: bytes


class _Decoder:
    """One decode pass over ``raw``; every failure becomes an ExplicitDecodeError."""

    def __init__(self, raw: bytes, arbitration_id: int | None) -> None:
        self.raw = raw
        self.arbitration_id = arbitration_id
        self.mac: int | None = None
        self.xid: bool | None = None
        self.service: int | None = None

    def fail(self, reason: str, general_status: int | None = None) -> ExplicitDecodeError:
        return ExplicitDecodeError(
            reason,
            self.raw,
            arbitration_id=self.arbitration_id,
            mac=self.mac,
            xid=self.xid,
            service=self.service,
            general_status=general_status,
        )

    def message(self, body_format: BodyFormat) -> ExplicitMessage:
        if not self.raw:
            raise self.fail("empty explicit message")
        header = self.raw[0]
        self.mac, self.xid = header & MAC_MASK, bool(header & XID_BIT)
        if header & FRAG_BIT:
            raise self.fail("fragment frame: feed it to a reassembler")
        if len(self.raw) < 2:
            raise self.fail("no service byte", GeneralStatus.NOT_ENOUGH_DATA)
        self.service = self.raw[1] & SERVICE_MASK
        if self.raw[1] & RESPONSE_BIT:
            body: Body = self.response(self.raw[2:])
        else:
            body = self.request(self.raw[2:], body_format)
        return ExplicitMessage(self.mac, self.xid, body)

    def response(self, data: bytes) -> Response:
        decoder = _RESPONSE_DECODERS.get(self.service or 0, _decode_success)
        return decoder(self, data)

    def request(self, data: bytes, body_format: BodyFormat) -> Request:
        if body_format not in _ID_WIDTHS:
            raise self.fail(f"unsupported body format {body_format!r}")
        class_width, instance_width = _ID_WIDTHS[body_format]
        if len(data) < class_width + instance_width:
            raise self.fail("request without class and instance", GeneralStatus.NOT_ENOUGH_DATA)
        context = _Context(
            int.from_bytes(data[:class_width], "little"),
            int.from_bytes(data[class_width : class_width + instance_width], "little"),
            data[class_width + instance_width :],
        )
        decoder = _REQUEST_DECODERS.get(self.service or 0, _decode_generic)
        return decoder(self, context)

    def exact(self, data: bytes, length: int, what: str) -> None:
        """Fail with not enough / too much data unless ``data`` has ``length`` bytes."""
        if len(data) < length:
            raise self.fail(f"{what}: not enough data", GeneralStatus.NOT_ENOUGH_DATA)
        if len(data) > length:
            raise self.fail(f"{what}: too much data", GeneralStatus.TOO_MUCH_DATA)


def _decode_get_single(d: _Decoder, c: _Context) -> Request:
    d.exact(c.data, 1, "Get_Attribute_Single")
    return GetAttributeSingle(c.class_id, c.instance_id, c.data[0])


def _decode_set_single(d: _Decoder, c: _Context) -> Request:
    if len(c.data) < 2:
        raise d.fail("Set_Attribute_Single: not enough data", GeneralStatus.NOT_ENOUGH_DATA)
    return SetAttributeSingle(c.class_id, c.instance_id, c.data[0], c.data[1:])


def _decode_get_all(d: _Decoder, c: _Context) -> Request:
    d.exact(c.data, 0, "Get_Attributes_All")
    return GetAttributesAll(c.class_id, c.instance_id)


def _decode_set_all(_d: _Decoder, c: _Context) -> Request:
    return SetAttributesAll(c.class_id, c.instance_id, c.data)


def _decode_reset(d: _Decoder, c: _Context) -> Request:
    if len(c.data) > 1:
        raise d.fail("Reset: too much data", GeneralStatus.TOO_MUCH_DATA)
    return Reset(c.class_id, c.instance_id, c.data[0] if c.data else None)


def _decode_allocate(d: _Decoder, c: _Context) -> Request:
    d.exact(c.data, 2, "Allocate")
    choice, allocator = c.data
    if allocator > MAX_MAC:
        raise d.fail(f"allocator MAC {allocator}", GeneralStatus.INVALID_PARAMETER_VALUE)
    return AllocateConnectionSet(AllocationChoice(choice), allocator, c.class_id, c.instance_id)


def _decode_release(d: _Decoder, c: _Context) -> Request:
    d.exact(c.data, 1, "Release")
    return ReleaseConnectionSet(AllocationChoice(c.data[0]), c.class_id, c.instance_id)


def _decode_generic(d: _Decoder, c: _Context) -> Request:
    return GenericRequest(d.service or 0, c.class_id, c.instance_id, c.data)


def _decode_success(d: _Decoder, data: bytes) -> Response:
    return SuccessResponse(d.service or 0, data)


def _decode_allocate_response(d: _Decoder, data: bytes) -> Response:
    if len(data) != 1:
        raise d.fail(f"Allocate response with {len(data)} data bytes (1 expected)")
    return AllocateResponse(data[0])


def _decode_error(d: _Decoder, data: bytes) -> Response:
    if len(data) != 2:
        raise d.fail(f"error response with {len(data)} data bytes (2 expected)")
    return ErrorResponse(data[0], data[1])


# Dispatch tables by service code (fact sheet 2.5, 2.7).
_REQUEST_DECODERS: dict[int, Callable[[_Decoder, _Context], Request]] = {
    Service.GET_ATTRIBUTE_SINGLE: _decode_get_single,
    Service.SET_ATTRIBUTE_SINGLE: _decode_set_single,
    Service.GET_ATTRIBUTES_ALL: _decode_get_all,
    Service.SET_ATTRIBUTES_ALL: _decode_set_all,
    Service.RESET: _decode_reset,
    Service.ALLOCATE_MASTER_SLAVE_CONNECTION_SET: _decode_allocate,
    Service.RELEASE_MASTER_SLAVE_CONNECTION_SET: _decode_release,
}

_RESPONSE_DECODERS: dict[int, Callable[[_Decoder, bytes], Response]] = {
    Service.ALLOCATE_MASTER_SLAVE_CONNECTION_SET: _decode_allocate_response,
    Service.ERROR_RESPONSE: _decode_error,
}


def error_text(response: ErrorResponse) -> str:
    """``"0x0C Object state conflict (additional 0x01)"`` for logs and error replies."""
    extra = (
        ""
        if response.additional_code == NO_ADDITIONAL_CODE
        else f" (additional 0x{response.additional_code:02X})"
    )
    return f"0x{response.general_status:02X} {response.text}{extra}"
