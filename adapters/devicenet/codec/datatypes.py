"""CIP elementary data types, little-endian (USINT, UINT, UDINT, SINT, INT, DINT,
BYTE, WORD, DWORD) and SHORT_STRING (length byte, then one byte per character).

Fact sheet 2.3 (UINT/UDINT little-endian), 2.7 (Set value little-endian),
2.12 (Identity attribute types, SHORT_STRING product name). Characters are
ISO 8859-1, which decodes any byte.
"""

from __future__ import annotations

from enum import Enum, auto

from adapters.devicenet.errors import DataTypeDecodeError
from gateway.errors import FrameEncodeError

AttributeValue = int | str | bytes | tuple[int, int]
"""A decoded attribute value: an integer, a SHORT_STRING, opaque bytes, or a revision
(major, minor)."""


class CipType(Enum):
    """Fixed-size integer types of CIP."""

    USINT = auto()
    UINT = auto()
    UDINT = auto()
    SINT = auto()
    INT = auto()
    DINT = auto()
    BYTE = auto()  # bit strings: unsigned on the wire
    WORD = auto()
    DWORD = auto()

    @property
    def size(self) -> int:
        return _LAYOUT[self][0]

    @property
    def signed(self) -> bool:
        return _LAYOUT[self][1]

    @property
    def minimum(self) -> int:
        return -(1 << (8 * self.size - 1)) if self.signed else 0

    @property
    def maximum(self) -> int:
        bits = 8 * self.size - (1 if self.signed else 0)
        return (1 << bits) - 1


# (size in bytes, signed)
_LAYOUT: dict[CipType, tuple[int, bool]] = {
    CipType.USINT: (1, False),
    CipType.UINT: (2, False),
    CipType.UDINT: (4, False),
    CipType.SINT: (1, True),
    CipType.INT: (2, True),
    CipType.DINT: (4, True),
    CipType.BYTE: (1, False),
    CipType.WORD: (2, False),
    CipType.DWORD: (4, False),
}


def encode_value(cip_type: CipType, value: int) -> bytes:
    """``value`` as ``cip_type``, little-endian; FrameEncodeError when out of range."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise FrameEncodeError(f"{cip_type.name} value must be an int, not {value!r}")
    if not cip_type.minimum <= value <= cip_type.maximum:
        raise FrameEncodeError(f"{value} out of {cip_type.name} range")
    return value.to_bytes(cip_type.size, "little", signed=cip_type.signed)


def read_value(cip_type: CipType, data: bytes, offset: int = 0) -> tuple[int, int]:
    """The value at ``offset`` and the offset after it; DataTypeDecodeError if short."""
    end = offset + cip_type.size
    if offset < 0 or end > len(data):
        raise DataTypeDecodeError(f"{cip_type.name} at offset {offset}: data too short", data)
    value = int.from_bytes(data[offset:end], "little", signed=cip_type.signed)
    return value, end


def decode_value(cip_type: CipType, data: bytes) -> int:
    """A whole attribute value of ``cip_type``: the length must match exactly."""
    raw = bytes(data)
    if len(raw) != cip_type.size:
        raise DataTypeDecodeError(
            f"{cip_type.name} needs {cip_type.size} bytes, got {len(raw)}", raw
        )
    return read_value(cip_type, raw)[0]


SHORT_STRING_MAX = 255
_CHARSET = "latin-1"


def encode_short_string(text: str) -> bytes:
    """SHORT_STRING: one length byte, then the characters (fact sheet 2.12)."""
    try:
        body = text.encode(_CHARSET)
    except UnicodeEncodeError as exc:
        raise FrameEncodeError(f"SHORT_STRING {text!r} has characters outside ISO 8859-1") from exc
    if len(body) > SHORT_STRING_MAX:
        raise FrameEncodeError(f"SHORT_STRING of {len(body)} characters (at most 255)")
    return bytes((len(body),)) + body


def read_short_string(data: bytes, offset: int = 0) -> tuple[str, int]:
    """The SHORT_STRING at ``offset`` and the offset after it."""
    if offset < 0 or offset >= len(data):
        raise DataTypeDecodeError(f"SHORT_STRING at offset {offset}: no length byte", data)
    length = data[offset]
    end = offset + 1 + length
    if end > len(data):
        raise DataTypeDecodeError(
            f"SHORT_STRING of {length} characters, {len(data) - offset - 1} present", data
        )
    return bytes(data[offset + 1 : end]).decode(_CHARSET), end


def decode_short_string(data: bytes) -> str:
    """A whole SHORT_STRING attribute value: nothing may follow it."""
    raw = bytes(data)
    text, end = read_short_string(raw)
    if end != len(raw):
        raise DataTypeDecodeError(f"{len(raw) - end} bytes after the SHORT_STRING", raw)
    return text
