"""Chk_Cfg / Get_Cfg configuration identifiers, compact and special format.

Sans-IO codec written from the fact sheet (``reference/protocol-facts.md``) 1.7: encode from
a list of typed identifiers and decode back; byte counts per direction for the I/O image.
:class:`Configuration` is both the Chk_Cfg request data (to SAP 62) and the Get_Cfg
response data (from SAP 59).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Self

from adapters.profibus.codec.fdl import MAX_DU
from adapters.profibus.codec.pdu import bit, bits, fail
from adapters.profibus.errors import DecodeFailure, require_length
from gateway.errors import FrameEncodeError, require_int


class IoDirection(IntEnum):
    """Compact identifier bits 5-4 (fact sheet 1.7)."""

    INPUT = 0b01
    OUTPUT = 0b10
    INPUT_OUTPUT = 0b11


@dataclass(frozen=True)
class CompactId:
    """Compact-format identifier: ``length`` units (1..16) of bytes or words (fact sheet 1.7).

    With INPUT_OUTPUT the length applies to both directions (0xF1 = 2 words in + 2 out).
    """

    direction: IoDirection
    length: int
    words: bool = False
    consistent: bool = False

    @property
    def input_bytes(self) -> int:
        return self._bytes() if self.direction & IoDirection.INPUT else 0

    @property
    def output_bytes(self) -> int:
        return self._bytes() if self.direction & IoDirection.OUTPUT else 0

    def _bytes(self) -> int:
        return self.length * (2 if self.words else 1)

    def encode(self) -> bytes:
        direction = IoDirection(self.direction)
        length = require_int("compact identifier length", self.length, 1, 16)
        return bytes((bits((self.consistent, 7), (self.words, 6)) | direction << 4 | (length - 1),))


@dataclass(frozen=True)
class IoLength:
    """A special-format length byte: 1..64 units, words, consistency (fact sheet 1.7)."""

    length: int
    words: bool = False
    consistent: bool = False

    @property
    def byte_count(self) -> int:
        return self.length * (2 if self.words else 1)

    def encode(self) -> int:
        length = require_int("special identifier length", self.length, 1, 64)
        return bits((self.consistent, 7), (self.words, 6)) | (length - 1)

    @classmethod
    def decode(cls, value: int) -> Self:
        return cls(length=(value & 0x3F) + 1, words=bit(value, 6), consistent=bit(value, 7))


SKIP_CHECK_NIBBLE: Final = 15  # 1.7: "no manufacturer bytes, check may be skipped" (Chk_Cfg)


@dataclass(frozen=True)
class SpecialId:
    """Special-format identifier (fact sheet 1.7).

    ``SpecialId()`` is the free place ``0x00``. ``skip_check`` is low nibble 15 (Chk_Cfg
    only, no manufacturer bytes). Output length comes before input length on the wire.
    """

    output: IoLength | None = None
    input: IoLength | None = None
    manufacturer_data: bytes = b""
    skip_check: bool = False

    @property
    def input_bytes(self) -> int:
        return self.input.byte_count if self.input is not None else 0

    @property
    def output_bytes(self) -> int:
        return self.output.byte_count if self.output is not None else 0

    def encode(self) -> bytes:
        data = require_length("manufacturer data", self.manufacturer_data, 0, 14)
        if self.skip_check and data:
            raise FrameEncodeError("skip_check (nibble 15) carries no manufacturer bytes")
        nibble = SKIP_CHECK_NIBBLE if self.skip_check else len(data)
        head = (self.input is not None) << 6 | (self.output is not None) << 7 | nibble
        lengths = [x.encode() for x in (self.output, self.input) if x is not None]
        return bytes((head, *lengths)) + data


CfgIdentifier = CompactId | SpecialId


def decode_identifiers(data: bytes, *, allow_skip_check: bool = True) -> tuple[CfgIdentifier, ...]:
    """Decode a Chk_Cfg / Get_Cfg byte string (fact sheet 1.7).

    ``allow_skip_check=False`` for Get_Cfg, where nibble 15 is not allowed.
    """
    data = bytes(data)
    result: list[CfgIdentifier] = []
    pos = 0
    while pos < len(data):
        head = data[pos]
        pos += 1
        if head & 0x30:
            result.append(
                CompactId(
                    IoDirection(head >> 4 & 0x03), (head & 0x0F) + 1, bit(head, 6), bit(head, 7)
                )
            )
            continue
        nibble = head & 0x0F
        if nibble == SKIP_CHECK_NIBBLE and not allow_skip_check:
            raise fail(DecodeFailure.BAD_FIELD, "special identifier nibble 15 in Get_Cfg", data)
        n_lengths = bit(head, 6) + bit(head, 7)
        n_manuf = 0 if nibble == SKIP_CHECK_NIBBLE else nibble
        end = pos + n_lengths + n_manuf
        if end > len(data):
            raise fail(DecodeFailure.TRUNCATED, f"special identifier 0x{head:02X} cut short", data)
        lengths = iter(data[pos : pos + n_lengths])
        output = IoLength.decode(next(lengths)) if bit(head, 7) else None
        input_ = IoLength.decode(next(lengths)) if bit(head, 6) else None
        result.append(
            SpecialId(output, input_, data[pos + n_lengths : end], nibble == SKIP_CHECK_NIBBLE)
        )
        pos = end
    return tuple(result)


def encode_identifiers(identifiers: Iterable[CfgIdentifier]) -> bytes:
    """Encode identifiers for Chk_Cfg / Get_Cfg (fact sheet 1.7)."""
    out = b"".join(_encode_identifier(x) for x in identifiers)
    return require_length("configuration", out, 0, MAX_DU)


def _encode_identifier(identifier: CfgIdentifier) -> bytes:
    if not isinstance(identifier, CompactId | SpecialId):
        raise FrameEncodeError(f"not a configuration identifier: {identifier!r}")
    return identifier.encode()


def total_input_bytes(identifiers: Iterable[CfgIdentifier]) -> int:
    return sum(x.input_bytes for x in identifiers)


def total_output_bytes(identifiers: Iterable[CfgIdentifier]) -> int:
    return sum(x.output_bytes for x in identifiers)


@dataclass(frozen=True)
class Configuration:
    """Chk_Cfg request data (master -> SAP 62) and Get_Cfg response data (SAP 59 -> master)."""

    identifiers: tuple[CfgIdentifier, ...]

    @property
    def input_bytes(self) -> int:
        return total_input_bytes(self.identifiers)

    @property
    def output_bytes(self) -> int:
        return total_output_bytes(self.identifiers)

    def encode(self) -> bytes:
        return encode_identifiers(self.identifiers)

    @classmethod
    def decode(cls, data: bytes, *, allow_skip_check: bool = True) -> Self:
        return cls(decode_identifiers(data, allow_skip_check=allow_skip_check))
