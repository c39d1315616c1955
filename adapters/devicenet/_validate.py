"""Range checks shared by the DeviceNet encoders: every failure is a FrameEncodeError."""

from __future__ import annotations

from gateway.errors import FrameEncodeError


def check_int(name: str, value: object, low: int, high: int) -> int:
    """``value`` if it is an int (not a bool) in ``low..high``, else FrameEncodeError."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise FrameEncodeError(f"{name} must be an int, not {value!r}")
    if not low <= value <= high:
        raise FrameEncodeError(f"{name} {value} out of {low}..{high}")
    return value


def check_bytes(name: str, value: object, max_length: int | None = None) -> bytes:
    """``value`` as immutable bytes, optionally bounded in length, else FrameEncodeError."""
    if not isinstance(value, bytes | bytearray | memoryview):
        raise FrameEncodeError(f"{name} must be bytes, not {type(value).__name__}")
    data = bytes(value)
    if max_length is not None and len(data) > max_length:
        raise FrameEncodeError(f"{name} of {len(data)} bytes (at most {max_length})")
    return data
