"""Bit and length helpers shared by the DP-V0 PDU modules (no protocol facts here)."""

from __future__ import annotations

from adapters.profibus.errors import DecodeFailure, DpDecodeError


def fail(reason: DecodeFailure, message: str, raw: bytes) -> DpDecodeError:
    return DpDecodeError(reason, message, raw)


def need(data: bytes, size: int, what: str) -> None:
    """DpDecodeError(TRUNCATED) unless ``data`` has at least ``size`` bytes."""
    if len(data) < size:
        raise fail(DecodeFailure.TRUNCATED, f"{what} needs {size} bytes, got {len(data)}", data)


def exact(data: bytes, size: int, what: str) -> None:
    """DpDecodeError unless ``data`` has exactly ``size`` bytes."""
    need(data, size, what)
    if len(data) > size:
        raise fail(DecodeFailure.TRAILING_BYTES, f"{what} is {size} bytes, got {len(data)}", data)


def bit(value: int, number: int) -> bool:
    return bool(value >> number & 1)


def bits(*pairs: tuple[bool, int]) -> int:
    """Pack ``(flag, bit number)`` pairs into a byte."""
    return sum(1 << number for flag, number in pairs if flag)
