"""Register types, null sentinels and Modbus exception codes (sans-IO).

A register holds ``round(value * scale)``. A value the device cannot give
(``None``) is the type's null sentinel, never 0 pretending to be a reading:
``0x8000`` for int16, ``0xFFFF`` for uint16, ``0xFFFFFFFF`` for uint32.
Readings beyond the range saturate at the largest value that is not the
sentinel. Counters (``uint32 counter``) wrap modulo 2**32 and have no null.
32-bit values are two registers, high word first.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Generic, TypeVar

from gateway.errors import GatewayError


class ExceptionCode(IntEnum):
    """The Modbus exception codes the front end answers with (Modbus Application
    Protocol V1.1b3, section 7)."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    GATEWAY_TARGET_FAILED = 0x0B


EXCEPTION_USES: dict[ExceptionCode, str] = {
    ExceptionCode.ILLEGAL_FUNCTION: (
        "a function code the gateway does not serve; any write to a writable register "
        "while `modbus.read_only` is true"
    ),
    ExceptionCode.ILLEGAL_DATA_ADDRESS: (
        "a read or write touching an unmapped address, a write touching a read-only register, "
        "any coil or discrete-input access"
    ),
    ExceptionCode.ILLEGAL_DATA_VALUE: (
        "a written value out of range: reserved command bits set, a speed beyond the drive's "
        "scale, both speed references in one write"
    ),
    ExceptionCode.SERVER_DEVICE_FAILURE: (
        "a valid command the hub refuses: drive not online, another source has control "
        "(`control`), a command the device cannot take (e.g. direction on a soft starter), "
        "run and fault reset in the same write"
    ),
    ExceptionCode.GATEWAY_TARGET_FAILED: "a unit id that is neither the gateway nor a drive",
}
"""When each exception code is sent (rendered into docs/modbus-map.md)."""


class WriteRefused(GatewayError, ValueError):
    """A register write refused before anything of it was applied."""

    def __init__(self, code: ExceptionCode, reason: str) -> None:
        self.code = code
        self.reason = reason
        super().__init__(f"exception {int(code)} ({code.name.lower()}): {reason}")


Value = float | int | None


@dataclass(frozen=True, slots=True)
class RegType:
    """How a value is laid out in one or two 16-bit registers."""

    name: str
    words: int
    signed: bool
    null: int | None  # raw value meaning "no value"; None: the type has no null
    wraps: bool = False  # counters wrap instead of saturating

    @property
    def bits(self) -> int:
        return 16 * self.words

    @property
    def lo(self) -> int:
        """Smallest reading (the null sentinel excluded)."""
        if not self.signed:
            return 0
        return -(1 << (self.bits - 1)) + (1 if self.null is not None else 0)

    @property
    def hi(self) -> int:
        """Largest reading (the null sentinel excluded)."""
        top = (1 << (self.bits - 1)) - 1 if self.signed else (1 << self.bits) - 1
        return top - 1 if self.null == top else top

    def encode(self, value: Value, scale: float = 1.0) -> tuple[int, ...]:
        """``value * scale`` as registers (high word first); None is the null sentinel."""
        if value is None or not math.isfinite(value):
            if self.null is None:
                raise ValueError(f"{self.name} has no null value")
            return self._words(self.null)
        raw = round(value * scale)
        if self.wraps:
            return self._words(raw & ((1 << self.bits) - 1))
        raw = min(max(raw, self.lo), self.hi)
        return self._words(raw & ((1 << self.bits) - 1))

    def decode(self, words: Sequence[int], scale: float = 1.0) -> float | None:
        """Inverse of :meth:`encode` (None for the null sentinel)."""
        if len(words) != self.words or any(not 0 <= w <= 0xFFFF for w in words):
            raise ValueError(f"{self.name} takes {self.words} register(s) of 0..65535")
        raw = 0
        for w in words:
            raw = (raw << 16) | w
        if self.null is not None and raw == self.null:
            return None
        if self.signed and raw >= 1 << (self.bits - 1):
            raw -= 1 << self.bits
        return raw / scale

    def _words(self, raw: int) -> tuple[int, ...]:
        return tuple((raw >> (16 * (self.words - 1 - i))) & 0xFFFF for i in range(self.words))


INT16 = RegType("int16", 1, signed=True, null=0x8000)
UINT16 = RegType("uint16", 1, signed=False, null=0xFFFF)
UINT32 = RegType("uint32", 2, signed=False, null=0xFFFFFFFF)
CODE16 = RegType("uint16", 1, signed=False, null=None)  # codes, counts, settings: never null
BITS16 = RegType("uint16 bits", 1, signed=False, null=None)
COUNTER32 = RegType("uint32 counter", 2, signed=False, null=None, wraps=True)

NULL_INT16 = 0x8000
"""The int16 null: in a speed reference holding register it means "not given"."""


def to_signed16(raw: int) -> int:
    """A register value (0..65535) read as two's complement int16."""
    return raw - 0x10000 if raw >= 0x8000 else raw


V = TypeVar("V")


@dataclass(frozen=True, slots=True)
class Field(Generic[V]):
    """One value in the register map: ``register = round(value * scale)``."""

    address: int
    name: str
    type: RegType
    unit: str
    doc: str
    get: Callable[[V], Value]
    scale: float = 1.0

    @property
    def words(self) -> int:
        return self.type.words

    def encode(self, view: V) -> tuple[int, ...]:
        return self.type.encode(self.get(view), self.scale)


def encode_block(fields: Sequence[Field[V]], view: V) -> list[int]:
    """The registers of a contiguous table starting at address 0."""
    out: list[int] = []
    for f in fields:
        out.extend(f.encode(view))
    return out


def block_size(fields: Sequence[Field[V]]) -> int:
    return sum(f.words for f in fields)
