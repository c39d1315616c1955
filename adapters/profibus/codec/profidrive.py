"""PROFIdrive parameter access through DP-V1 data record 47: requests, responses, errors.

Sans-IO codec written from the fact sheet (``reference/protocol-facts.md``) 1.11 (request and
response layout, formats, error numbers) and the WEG manuals (CFW-11 4.2.4-4.2.5, CFW700
5.2.4, CFW320 5.2.4-5.2.5: Tables 4.1/4.2 resp. 5.1/5.2 and the worked examples). The
sequence is: DS_Write(slot, 47, request), then DS_Read(slot, 47, 240) until the reply is
ready (see :func:`write_request` and :func:`read_request`).

Several parameters per request are supported. Values are big-endian; a value block of odd
length gets one pad byte (fact sheet 1.11).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from types import MappingProxyType
from typing import Final, Self

from adapters.profibus.codec.dpv1 import MAX_DATA, ReadRequest, WriteRequest
from adapters.profibus.errors import DecodeFailure, ProfidriveDecodeError, whole_raw
from gateway.errors import FrameEncodeError, require_int

PARAMETER_INDEX: Final = 47  # 1.11 / WEG 4.2.4: index 47
DEFAULT_SLOT: Final = 0  # WEG 4.2.3: slot 0 (Toshiba 0, ABB 1: check the device, 1.11)


class RequestId(IntEnum):
    """Request ID (fact sheet 1.11; WEG Table 4.1)."""

    READ = 0x01
    CHANGE = 0x02


class ResponseId(IntEnum):
    """Response ID (fact sheet 1.11; WEG Table 4.2: 1, 2, 129, 130)."""

    READ_OK = 0x01
    CHANGE_OK = 0x02
    READ_ERROR = 0x81
    CHANGE_ERROR = 0x82


class Attribute(IntEnum):
    """Parameter attribute (fact sheet 1.11; WEG uses 0x10 only)."""

    VALUE = 0x10
    DESCRIPTION = 0x20
    TEXT = 0x30


class DataFormat(IntEnum):
    """Value block format (fact sheet 1.11 [SINF]; WEG: 0x42 word, 0x44 error)."""

    INTEGER8 = 0x02
    INTEGER16 = 0x03
    INTEGER32 = 0x04
    UNSIGNED8 = 0x05
    UNSIGNED16 = 0x06
    UNSIGNED32 = 0x07
    FLOAT = 0x08
    ZERO = 0x40  # change OK inside a change-error response, no values
    BYTE = 0x41
    WORD = 0x42
    DOUBLE_WORD = 0x43
    ERROR = 0x44  # values are U16 PROFIdrive error numbers


# struct code per format (big-endian); ZERO carries no values.
_STRUCT: Final[Mapping[DataFormat, str]] = MappingProxyType(
    {
        DataFormat.INTEGER8: "b",
        DataFormat.INTEGER16: "h",
        DataFormat.INTEGER32: "i",
        DataFormat.UNSIGNED8: "B",
        DataFormat.UNSIGNED16: "H",
        DataFormat.UNSIGNED32: "I",
        DataFormat.FLOAT: "f",
        DataFormat.ZERO: "",
        DataFormat.BYTE: "B",
        DataFormat.WORD: "H",
        DataFormat.DOUBLE_WORD: "I",
        DataFormat.ERROR: "H",
    }
)

# 1.11 error numbers (U16 after format 0x44) [SINE][RETA]; >= 0x65 vendor specific.
PROFIDRIVE_ERROR_TEXTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        0x00: "impermissible parameter number",
        0x01: "parameter value cannot be changed",
        0x02: "parameter value out of limits",
        0x03: "faulty subindex",
        0x04: "no array",
        0x05: "incorrect data type",
        0x06: "setting not permitted (may only be reset)",
        0x07: "description element cannot be changed",
        0x09: "description data not available",
        0x0B: "no operating priority",
        0x0F: "no text array available",
        0x11: "request cannot be executed because of the operating state",
        0x14: "value impermissible",
        0x15: "response too long",
        0x16: "parameter address impermissible",
        0x17: "illegal format",
        0x18: "number of values inconsistent",
        0x19: "drive object does not exist",
    }
)
VENDOR_ERROR_START: Final = 0x65

# WEG CFW-11 4.2.4 / CFW700 5.2.4 / CFW320 5.2.4, Table 4.2 / 5.2 "Error code".
WEG_PARAMETER_ERROR_TEXTS: Final[Mapping[int, str]] = MappingProxyType(
    {
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
)


def parameter_error_text(number: int, table: Mapping[int, str] | None = None) -> str:
    """Text of a PROFIdrive error number: ``table`` (a device's own) first, then 1.11."""
    if table is not None and number in table:
        return table[number]
    if number in PROFIDRIVE_ERROR_TEXTS:
        return PROFIDRIVE_ERROR_TEXTS[number]
    return "vendor specific error" if number >= VENDOR_ERROR_START else "reserved error number"


def _fail(reason: DecodeFailure, message: str, raw: bytes) -> ProfidriveDecodeError:
    return ProfidriveDecodeError(reason, message, raw)


Value = int | float


@dataclass(frozen=True)
class ParameterAddress:
    """Attribute, number of elements, parameter number, subindex (6 bytes, fact sheet 1.11).

    ``elements`` defaults to 1 as in the WEG examples (WEG: "0 or 1"; Siemens uses 0).
    """

    number: int
    subindex: int = 0
    elements: int = 1
    attribute: Attribute = Attribute.VALUE

    def encode(self) -> bytes:
        try:
            attribute = Attribute(self.attribute)
        except ValueError:
            raise FrameEncodeError(f"unknown attribute {self.attribute!r}") from None
        return struct.pack(
            ">BBHH",
            attribute,
            require_int("elements", self.elements, 0, 255),
            require_int("parameter number", self.number, 0, 0xFFFF),
            require_int("subindex", self.subindex, 0, 0xFFFF),
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        attribute, elements, number, subindex = struct.unpack(">BBHH", data)
        try:
            return cls(number, subindex, elements, Attribute(attribute))
        except ValueError:
            raise _fail(
                DecodeFailure.UNKNOWN_FUNCTION, f"unknown attribute 0x{attribute:02X}", data
            ) from None


@dataclass(frozen=True)
class ValueBlock:
    """Format, number of values, values (fact sheet 1.11; WEG: 0x42 word, 0x44 error).

    Integer formats hold ints, FLOAT holds floats, ERROR holds U16 error numbers,
    ZERO holds nothing.
    """

    format: DataFormat
    values: tuple[Value, ...] = ()

    @classmethod
    def word(cls, *values: int) -> Self:
        return cls(DataFormat.WORD, tuple(values))

    @classmethod
    def error(cls, number: int) -> Self:
        return cls(DataFormat.ERROR, (number,))

    @property
    def is_error(self) -> bool:
        return self.format == DataFormat.ERROR

    @property
    def error_number(self) -> int | None:
        """First error number of an ERROR block, else None."""
        if not self.is_error or not self.values:
            return None
        return int(self.values[0])

    def error_text(self, table: Mapping[int, str] | None = None) -> str | None:
        number = self.error_number
        return None if number is None else parameter_error_text(number, table)

    def encode(self) -> bytes:
        try:
            fmt = DataFormat(self.format)
        except ValueError:
            raise FrameEncodeError(f"unknown data format {self.format!r}") from None
        code = _STRUCT[fmt]
        count = require_int("number of values", len(self.values), 0, 0 if not code else 255)
        try:
            body = struct.pack(f">{count}{code}", *self.values) if code else b""
        except struct.error as exc:
            raise FrameEncodeError(f"{fmt.name} values {self.values!r}: {exc}") from None
        pad = b"\x00" if len(body) % 2 else b""
        return bytes((fmt, count)) + body + pad


def _decode_block(data: bytes, pos: int) -> tuple[ValueBlock, int]:
    """Decode one value block at ``pos``; returns it and the position after it (and its pad)."""
    if pos + 2 > len(data):
        raise _fail(DecodeFailure.TRUNCATED, "value block header cut short", data)
    try:
        fmt = DataFormat(data[pos])
    except ValueError:
        raise _fail(
            DecodeFailure.UNKNOWN_FUNCTION, f"unknown data format 0x{data[pos]:02X}", data
        ) from None
    count, code = data[pos + 1], _STRUCT[fmt]
    if not code and count:
        raise _fail(DecodeFailure.BAD_FIELD, f"{fmt.name} block with {count} values", data)
    size = struct.calcsize(f">{count}{code}") if code else 0
    start, end = pos + 2, pos + 2 + size
    if end > len(data):
        raise _fail(DecodeFailure.TRUNCATED, f"{fmt.name} block needs {size} value bytes", data)
    values = struct.unpack(f">{count}{code}", data[start:end]) if code else ()
    if size % 2 and end < len(data):  # pad byte; tolerated missing at the very end
        end += 1
    return ValueBlock(fmt, tuple(values)), end


def _decode_blocks(data: bytes, pos: int, limit: int | None = None) -> tuple[ValueBlock, ...]:
    """Decode value blocks until the data ends (at most ``limit``)."""
    blocks: list[ValueBlock] = []
    while pos < len(data):
        if limit is not None and len(blocks) == limit:
            raise _fail(DecodeFailure.TRAILING_BYTES, "bytes after the last value block", data)
        block, pos = _decode_block(data, pos)
        blocks.append(block)
    return tuple(blocks)


def _check_size(out: bytes, what: str) -> bytes:
    if len(out) > MAX_DATA:
        raise FrameEncodeError(f"{what} is {len(out)} bytes, a DP-V1 record holds {MAX_DATA}")
    return out


@dataclass(frozen=True)
class ParameterRequest:
    """Parameter request in data record 47 (fact sheet 1.11; WEG Table 4.1 / 5.1).

    Header: request reference, request ID, axis (DO-ID, 0 on WEG), number of parameters;
    then one :class:`ParameterAddress` per parameter; change requests then carry one
    :class:`ValueBlock` per parameter.
    """

    reference: int
    request_id: RequestId
    parameters: tuple[ParameterAddress, ...]
    values: tuple[ValueBlock, ...] = ()
    axis: int = 0

    @classmethod
    def read(cls, reference: int, *parameters: ParameterAddress, axis: int = 0) -> Self:
        return cls(reference, RequestId.READ, tuple(parameters), (), axis)

    @classmethod
    def change(
        cls,
        reference: int,
        changes: Iterable[tuple[ParameterAddress, ValueBlock]],
        axis: int = 0,
    ) -> Self:
        pairs = tuple(changes)
        return cls(
            reference,
            RequestId.CHANGE,
            tuple(a for a, _ in pairs),
            tuple(v for _, v in pairs),
            axis,
        )

    def encode(self) -> bytes:
        try:
            request_id = RequestId(self.request_id)
        except ValueError:
            raise FrameEncodeError(f"unknown request id {self.request_id!r}") from None
        n = require_int("number of parameters", len(self.parameters), 1, 255)
        expected_values = n if request_id == RequestId.CHANGE else 0
        if len(self.values) != expected_values:
            raise FrameEncodeError(
                f"{request_id.name} request with {n} parameters needs {expected_values} "
                f"value blocks, got {len(self.values)}"
            )
        out = (
            bytes(
                (
                    require_int("request reference", self.reference, 0, 255),
                    request_id,
                    require_int("axis", self.axis, 0, 255),
                    n,
                )
            )
            + b"".join(p.encode() for p in self.parameters)
            + b"".join(v.encode() for v in self.values)
        )
        return _check_size(out, "parameter request")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        if len(data) < 4:
            raise _fail(DecodeFailure.TRUNCATED, "parameter request header needs 4 bytes", data)
        reference, raw_id, axis, n = data[0], data[1], data[2], data[3]
        try:
            request_id = RequestId(raw_id)
        except ValueError:
            raise _fail(
                DecodeFailure.UNKNOWN_FUNCTION, f"unknown request id 0x{raw_id:02X}", data
            ) from None
        if n == 0:
            raise _fail(DecodeFailure.BAD_FIELD, "request without parameters", data)
        end = 4 + 6 * n
        if len(data) < end:
            raise _fail(DecodeFailure.TRUNCATED, f"{n} parameter addresses cut short", data)
        with whole_raw(data):
            addresses = tuple(ParameterAddress.decode(data[p : p + 6]) for p in range(4, end, 6))
        values = _decode_blocks(data, end, n) if request_id == RequestId.CHANGE else ()
        if request_id == RequestId.READ and len(data) > end:
            raise _fail(DecodeFailure.TRAILING_BYTES, "bytes after a read request", data)
        if len(values) != (n if request_id == RequestId.CHANGE else 0):
            raise _fail(
                DecodeFailure.TRUNCATED, f"change request has {len(values)} of {n} values", data
            )
        return cls(reference, request_id, addresses, values, axis)


# Response IDs whose blocks must match the parameter count exactly; CHANGE_OK has none;
# CHANGE_ERROR has 1..count (the WEG example sends count 2 with one error block).
_EXACT_BLOCKS: Final = frozenset({ResponseId.READ_OK, ResponseId.READ_ERROR})


@dataclass(frozen=True)
class ParameterResponse:
    """Parameter response in data record 47 (fact sheet 1.11; WEG Table 4.2 / 5.2).

    ``parameter_count`` is the header's number of parameters, kept apart from ``values``
    because a change-OK reply carries no blocks, and the WEG manuals' change-error example
    declares 2 parameters but carries one error block (decoded and encoded as printed).
    """

    reference: int
    response_id: ResponseId
    parameter_count: int
    values: tuple[ValueBlock, ...] = ()
    axis: int = 0

    @property
    def ok(self) -> bool:
        return self.response_id in (ResponseId.READ_OK, ResponseId.CHANGE_OK)

    @property
    def errors(self) -> tuple[tuple[int, int], ...]:
        """(block position, error number) for each ERROR block."""
        return tuple(
            (i, number)
            for i, block in enumerate(self.values)
            if (number := block.error_number) is not None
        )

    @classmethod
    def read_ok(cls, reference: int, values: Sequence[ValueBlock], axis: int = 0) -> Self:
        return cls(reference, ResponseId.READ_OK, len(values), tuple(values), axis)

    @classmethod
    def read_error(cls, reference: int, values: Sequence[ValueBlock], axis: int = 0) -> Self:
        return cls(reference, ResponseId.READ_ERROR, len(values), tuple(values), axis)

    @classmethod
    def change_ok(cls, reference: int, parameter_count: int, axis: int = 0) -> Self:
        return cls(reference, ResponseId.CHANGE_OK, parameter_count, (), axis)

    @classmethod
    def change_error(cls, reference: int, values: Sequence[ValueBlock], axis: int = 0) -> Self:
        """One block per parameter: ZERO for the ones changed, ERROR for the ones refused."""
        return cls(reference, ResponseId.CHANGE_ERROR, len(values), tuple(values), axis)

    def encode(self) -> bytes:
        try:
            response_id = ResponseId(self.response_id)
        except ValueError:
            raise FrameEncodeError(f"unknown response id {self.response_id!r}") from None
        n = require_int("number of parameters", self.parameter_count, 1, 255)
        problem = _block_count_problem(response_id, n, len(self.values))
        if problem:
            raise FrameEncodeError(problem)
        out = bytes(
            (
                require_int("request reference", self.reference, 0, 255),
                response_id,
                require_int("axis", self.axis, 0, 255),
                n,
            )
        ) + b"".join(v.encode() for v in self.values)
        return _check_size(out, "parameter response")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        if len(data) < 4:
            raise _fail(DecodeFailure.TRUNCATED, "parameter response header needs 4 bytes", data)
        reference, raw_id, axis, n = data[0], data[1], data[2], data[3]
        try:
            response_id = ResponseId(raw_id)
        except ValueError:
            raise _fail(
                DecodeFailure.UNKNOWN_FUNCTION, f"unknown response id 0x{raw_id:02X}", data
            ) from None
        if n == 0:
            raise _fail(DecodeFailure.BAD_FIELD, "response without parameters", data)
        values = _decode_blocks(data, 4, n)
        problem = _block_count_problem(response_id, n, len(values))
        if problem:
            raise _fail(DecodeFailure.BAD_LENGTH, problem, data)
        return cls(reference, response_id, n, values, axis)


def _block_count_problem(response_id: ResponseId, n: int, blocks: int) -> str | None:
    if response_id in _EXACT_BLOCKS:
        ok = blocks == n
    elif response_id == ResponseId.CHANGE_OK:
        ok = blocks == 0
    else:
        ok = 1 <= blocks <= n
    return None if ok else f"{response_id.name} with {n} parameters and {blocks} value blocks"


def write_request(request: ParameterRequest, slot: int = DEFAULT_SLOT) -> WriteRequest:
    """Step 1: DS_Write(slot, 47, request) (fact sheet 1.11; WEG 4.2.4 step 1)."""
    return WriteRequest(slot, PARAMETER_INDEX, request.encode())


def read_request(slot: int = DEFAULT_SLOT, length: int = MAX_DATA) -> ReadRequest:
    """Step 2: DS_Read(slot, 47, 240), repeated until the reply is ready (1.11; WEG 4.2.4)."""
    return ReadRequest(slot, PARAMETER_INDEX, length)
