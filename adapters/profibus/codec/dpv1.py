"""DP-V1 MSAC_C1 PDUs: read, write, alarm acknowledge, error PDU and its code tables.

Sans-IO codec written from the fact sheet (``reference/protocol-facts.md``) 1.10 (PDU formats,
error reply, transport on SAP 51) and 1.8 (alarm acknowledge to SAP 50), and from the WEG
manuals' DS_Read/DS_Write tables (CFW-11 4.2.3, CFW700 5.2.3, CFW320 5.2.3) for the WEG
Error_Code_1 texts. PDUs are frozen dataclasses with ``encode()``; :func:`decode_request`
(simulator) and :func:`decode_response` (master) turn DU bytes back into them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from types import MappingProxyType
from typing import Final, Self, TypeVar

from adapters.profibus.codec.diag import AlarmDiag, AlarmSpecifier, decode_specifier
from adapters.profibus.codec.dp import MasterSap, SlaveSap
from adapters.profibus.codec.fdl import DataTelegram, RequestFc, ResponseStatus, StationType
from adapters.profibus.errors import DecodeFailure, Dpv1DecodeError, require_length
from gateway.errors import FrameEncodeError, require_int


class Dpv1Function(IntEnum):
    """DP-V1 function numbers (fact sheet 1.10)."""

    IDLE = 0x48
    DATA_TRANSPORT = 0x51
    RESOURCE_MANAGER = 0x56
    INITIATE = 0x57
    ABORT = 0x58
    ALARM_ACK = 0x5C
    READ = 0x5E
    WRITE = 0x5F


ERROR_FLAG: Final = 0x80  # 1.10: error reply function = request function | 0x80 (DE, DF)
MAX_DATA: Final = 240  # 1.10: header 4 bytes, data up to 240 bytes


class ErrorDecode(IntEnum):
    """Error_Decode byte of an error reply (fact sheet 1.10)."""

    DPV1 = 0x80
    FMS = 0xFE
    HART = 0xFF


class ErrorClass(IntEnum):
    """Error_Code_1 high nibble when Error_Decode is DP-V1 (fact sheet 1.10)."""

    APPLICATION = 0xA
    ACCESS = 0xB
    RESOURCE = 0xC


ERROR_CLASS_TEXTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        ErrorClass.APPLICATION: "application",
        ErrorClass.ACCESS: "access",
        ErrorClass.RESOURCE: "resource",
    }
)

# 1.10 error table: (class, code) -> text.
ERROR_CODE_TEXTS: Final[Mapping[tuple[int, int], str]] = MappingProxyType(
    {
        (ErrorClass.APPLICATION, 0): "read error",
        (ErrorClass.APPLICATION, 1): "write error",
        (ErrorClass.APPLICATION, 2): "module failure",
        (ErrorClass.APPLICATION, 8): "version conflict",
        (ErrorClass.APPLICATION, 9): "feature not supported",
        (ErrorClass.ACCESS, 0): "invalid index",
        (ErrorClass.ACCESS, 1): "write length error",
        (ErrorClass.ACCESS, 2): "invalid slot",
        (ErrorClass.ACCESS, 3): "type conflict",
        (ErrorClass.ACCESS, 4): "invalid area",
        (ErrorClass.ACCESS, 5): "state conflict",
        (ErrorClass.ACCESS, 6): "access denied",
        (ErrorClass.ACCESS, 7): "invalid range",
        (ErrorClass.ACCESS, 8): "invalid parameter",
        (ErrorClass.ACCESS, 9): "invalid type",
        (ErrorClass.RESOURCE, 0): "read constraint conflict",
        (ErrorClass.RESOURCE, 1): "write constraint conflict",
        (ErrorClass.RESOURCE, 2): "resource busy",
        (ErrorClass.RESOURCE, 3): "resource unavailable",
    }
)

# WEG CFW-11 4.2.3, CFW700 5.2.3, CFW320 5.2.3, "Error Code 1" (identical in the three
# manuals; the seeds win over the generic table above, e.g. B0h is "invalid slot" there).
WEG_ERROR_CODE_1_TEXTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        0xB0: "access error - invalid slot",
        0xB2: "access error - invalid index",
        0xB5: "access error - modification not allowed for the parameter",
        0xB6: "access error - modification in read-only parameter",
        0xB7: "access error - incorrect values for parameter access",
        0xB8: "access error - invalid parameter number",
        0xC3: "resource error - response not available for the reading request",
    }
)


def error_code_1_text(
    code_1: int,
    error_decode: int = ErrorDecode.DPV1,
    table: Mapping[int, str] | None = None,
) -> str:
    """Text for an Error_Code_1: ``table`` (a device's own) first, then fact sheet 1.10."""
    if table is not None and code_1 in table:
        return table[code_1]
    if error_decode != ErrorDecode.DPV1:
        kind = ErrorDecode(error_decode).name if error_decode in (0xFE, 0xFF) else "unknown"
        return f"{kind} error 0x{code_1:02X}"
    error_class, code = code_1 >> 4, code_1 & 0x0F
    class_text = ERROR_CLASS_TEXTS.get(error_class)
    if class_text is None:
        return f"reserved or user specific error class 0x{error_class:X}, code {code}"
    code_text = ERROR_CODE_TEXTS.get((error_class, code), f"reserved or user specific code {code}")
    return f"{class_text} error - {code_text}"


def _fail(reason: DecodeFailure, message: str, raw: bytes) -> Dpv1DecodeError:
    return Dpv1DecodeError(reason, message, raw)


def _exact(data: bytes, size: int, what: str) -> None:
    if len(data) != size:
        reason = DecodeFailure.TRUNCATED if len(data) < size else DecodeFailure.TRAILING_BYTES
        raise _fail(reason, f"{what} is {size} bytes, got {len(data)}", data)


def _header(function: Dpv1Function, slot: int, index: int, length: int) -> bytes:
    return bytes(
        (
            function,
            require_int("slot", slot, 0, 255),
            require_int("index", index, 0, 255),
            require_int("length", length, 0, MAX_DATA),
        )
    )


def _with_data(data: bytes, what: str) -> tuple[int, int, bytes]:
    """Decode ``F slot index len data`` where len must equal the data length."""
    if len(data) < 4:
        raise _fail(DecodeFailure.TRUNCATED, f"{what} needs 4 header bytes", data)
    length, body = data[3], data[4:]
    if length != len(body) or length > MAX_DATA:
        raise _fail(DecodeFailure.BAD_LENGTH, f"{what} length {length}, data {len(body)}", data)
    return data[1], data[2], body


@dataclass(frozen=True)
class ReadRequest:
    """DS_Read request ``5E slot index len`` (fact sheet 1.10)."""

    slot: int
    index: int
    length: int = MAX_DATA

    def encode(self) -> bytes:
        return _header(Dpv1Function.READ, self.slot, self.index, self.length)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _exact(data, 4, "read request")
        if data[3] > MAX_DATA:
            raise _fail(DecodeFailure.BAD_LENGTH, f"read length {data[3]} > {MAX_DATA}", data)
        return cls(data[1], data[2], data[3])


@dataclass(frozen=True)
class ReadResponse:
    """DS_Read positive reply ``5E slot index len data`` (fact sheet 1.10)."""

    slot: int
    index: int
    data: bytes = b""

    def encode(self) -> bytes:
        data = require_length("read data", self.data, 0, MAX_DATA)
        return _header(Dpv1Function.READ, self.slot, self.index, len(data)) + data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        return cls(*_with_data(data, "read response"))


@dataclass(frozen=True)
class WriteRequest:
    """DS_Write request ``5F slot index len data`` (fact sheet 1.10)."""

    slot: int
    index: int
    data: bytes = b""

    def encode(self) -> bytes:
        data = require_length("write data", self.data, 0, MAX_DATA)
        return _header(Dpv1Function.WRITE, self.slot, self.index, len(data)) + data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        return cls(*_with_data(data, "write request"))


@dataclass(frozen=True)
class WriteResponse:
    """DS_Write positive reply ``5F slot index len`` (fact sheet 1.10; WEG sends len 0)."""

    slot: int
    index: int
    length: int = 0

    def encode(self) -> bytes:
        return _header(Dpv1Function.WRITE, self.slot, self.index, self.length)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _exact(data, 4, "write response")
        return cls(data[1], data[2], data[3])


@dataclass(frozen=True)
class AlarmAck:
    """Alarm acknowledge ``5C slot type specifier`` to SAP 50 (fact sheet 1.8, ◐)."""

    slot: int
    alarm_type: int
    specifier: AlarmSpecifier = AlarmSpecifier.APPEARS
    add_ack: bool = False
    sequence: int = 0

    @classmethod
    def for_alarm(cls, alarm: AlarmDiag) -> Self:
        return cls(alarm.slot, alarm.alarm_type, alarm.specifier, alarm.add_ack, alarm.sequence)

    def encode(self) -> bytes:
        return bytes(
            (
                Dpv1Function.ALARM_ACK,
                require_int("slot", self.slot, 0, 255),
                require_int("alarm_type", self.alarm_type, 0, 127),
                require_int("sequence", self.sequence, 0, 31) << 3
                | (0x04 if self.add_ack else 0)
                | AlarmSpecifier(self.specifier),
            )
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _exact(data, 4, "alarm acknowledge")
        specifier, add_ack, sequence = decode_specifier(data[3])
        return cls(data[1], data[2] & 0x7F, specifier, add_ack, sequence)


@dataclass(frozen=True)
class Dpv1ErrorResponse:
    """Error reply ``function|0x80, Error_Decode, Error_Code_1, Error_Code_2`` (1.10).

    ``function`` is the function of the failed request (READ for ``DE``, WRITE for ``DF``).
    ``error_code_1`` is the code; :attr:`text` is its generic text and :meth:`text_in` looks
    it up in a device table first (e.g. :data:`WEG_ERROR_CODE_1_TEXTS`).
    """

    function: Dpv1Function
    error_decode: int = ErrorDecode.DPV1
    error_code_1: int = 0
    error_code_2: int = 0

    @property
    def error_class(self) -> int:
        """Error_Code_1 bits 7-4 (meaningful when Error_Decode is DP-V1)."""
        return self.error_code_1 >> 4

    @property
    def error_code(self) -> int:
        """Error_Code_1 bits 3-0."""
        return self.error_code_1 & 0x0F

    @property
    def text(self) -> str:
        return error_code_1_text(self.error_code_1, self.error_decode)

    def text_in(self, table: Mapping[int, str]) -> str:
        return error_code_1_text(self.error_code_1, self.error_decode, table)

    def encode(self) -> bytes:
        try:
            function = Dpv1Function(self.function)
        except ValueError:
            raise FrameEncodeError(f"unknown DP-V1 function {self.function!r}") from None
        return bytes(
            (
                function | ERROR_FLAG,
                require_int("error_decode", self.error_decode, 0, 255),
                require_int("error_code_1", self.error_code_1, 0, 255),
                require_int("error_code_2", self.error_code_2, 0, 255),
            )
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _exact(data, 4, "error response")
        return cls(_function(data[0] & ~ERROR_FLAG, data), data[1], data[2], data[3])


Dpv1Request = ReadRequest | WriteRequest | AlarmAck
Dpv1Response = ReadResponse | WriteResponse | AlarmAck | Dpv1ErrorResponse


def _function(value: int, data: bytes) -> Dpv1Function:
    try:
        return Dpv1Function(value)
    except ValueError:
        raise _fail(
            DecodeFailure.UNKNOWN_FUNCTION, f"unknown DP-V1 function 0x{value:02X}", data
        ) from None


_T = TypeVar("_T")

_REQUEST_DECODERS: Final[dict[Dpv1Function, Callable[[bytes], Dpv1Request]]] = {
    Dpv1Function.READ: ReadRequest.decode,
    Dpv1Function.WRITE: WriteRequest.decode,
    Dpv1Function.ALARM_ACK: AlarmAck.decode,
}

_RESPONSE_DECODERS: Final[dict[Dpv1Function, Callable[[bytes], Dpv1Response]]] = {
    Dpv1Function.READ: ReadResponse.decode,
    Dpv1Function.WRITE: WriteResponse.decode,
    Dpv1Function.ALARM_ACK: AlarmAck.decode,
}


def _dispatch(data: bytes, table: Mapping[Dpv1Function, Callable[[bytes], _T]], what: str) -> _T:
    data = bytes(data)
    if not data:
        raise _fail(DecodeFailure.TRUNCATED, f"empty DP-V1 {what}", data)
    decoder = table.get(_function(data[0] & ~ERROR_FLAG, data))
    if decoder is None:
        raise _fail(DecodeFailure.UNSUPPORTED, f"DP-V1 {what} 0x{data[0]:02X}", data)
    return decoder(data)


def decode_request(data: bytes) -> Dpv1Request:
    """Simulator side: decode the DU of an MSAC_C1 request."""
    data = bytes(data)
    if data and data[0] & ERROR_FLAG:
        raise _fail(DecodeFailure.UNKNOWN_FUNCTION, "error PDU is no request", data)
    return _dispatch(data, _REQUEST_DECODERS, "request")


def decode_response(data: bytes) -> Dpv1Response:
    """Master side: decode the DU of an MSAC_C1 reply (positive or error PDU)."""
    data = bytes(data)
    if data and data[0] & ERROR_FLAG:
        return Dpv1ErrorResponse.decode(data)
    return _dispatch(data, _RESPONSE_DECODERS, "response")


def request_sap(pdu: Dpv1Request) -> SlaveSap:
    """MSAC_C1 read/write go to SAP 51, alarm acknowledge to SAP 50 (fact sheet 1.4)."""
    return SlaveSap.ALARM_ACK if isinstance(pdu, AlarmAck) else SlaveSap.MSAC_C1


def build_request(pdu: Dpv1Request, *, da: int, sa: int, fc: RequestFc) -> DataTelegram:
    """SRD from master SAP 51 to the slave's SAP (fact sheet 1.10 transport)."""
    return DataTelegram(da, sa, fc, request_sap(pdu), MasterSap.MS1, pdu.encode())


def poll_request(*, da: int, sa: int, fc: RequestFc) -> DataTelegram:
    """An empty SRD on 51/51 to fetch a pending reply (✖ unverified on the wire, 1.10)."""
    return DataTelegram(da, sa, fc, SlaveSap.MSAC_C1, MasterSap.MS1)


def build_response(
    pdu: Dpv1Response,
    *,
    request: DataTelegram,
    status: ResponseStatus = ResponseStatus.DL,
    station_type: StationType = StationType.SLAVE,
) -> DataTelegram:
    """Simulator side: the reply to ``request`` with addresses and SAPs swapped."""
    return request.reply(pdu.encode(), status, station_type)
