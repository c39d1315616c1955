"""Checks shared by the DeviceNet encoders: every failure is a FrameEncodeError (the range
check is :func:`gateway.errors.require_int`, shared by every encoder)."""

from __future__ import annotations

from gateway.errors import FrameEncodeError


def check_bytes(name: str, value: object, max_length: int | None = None) -> bytes:
    """``value`` as immutable bytes, optionally bounded in length, else FrameEncodeError."""
    if not isinstance(value, bytes | bytearray | memoryview):
        raise FrameEncodeError(f"{name} must be bytes, not {type(value).__name__}")
    data = bytes(value)
    if max_length is not None and len(data) > max_length:
        raise FrameEncodeError(f"{name} of {len(data)} bytes (at most {max_length})")
    return data
