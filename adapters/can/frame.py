"""The classic CAN data frame as a codec on CAN sees it, sans-IO: an 11-bit identifier and
0-8 data bytes (ISO 11898-1 base frame format; DeviceNet fact sheet 2.13, CiA 301).

A codec never imports python-can: the link builds a received frame with
:meth:`CanFrame.from_bus` (through the bus's ``make_frame``) and sends one by its two
fields. Each bus subclasses :class:`CanFrame` only to name the decode error of its own
codec (:attr:`CanFrame.invalid`), which ``from_bus`` raises for a frame the bus cannot
carry; building a frame with an identifier or data out of range is a
:class:`~gateway.errors.FrameEncodeError` on every bus.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from gateway.errors import FrameDecodeError, FrameEncodeError

MAX_ARBITRATION_ID = 0x7FF  # 11-bit identifier
MAX_DATA_LENGTH = 8  # classic CAN

_new = object.__new__  # from_bus builds a checked frame without checking it again
_set = object.__setattr__


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One classic CAN data frame with an 11-bit identifier.

    Building one with an out-of-range id or more than 8 bytes raises
    :class:`FrameEncodeError`; use :meth:`from_bus` for received frames.
    """

    invalid: ClassVar[type[FrameDecodeError]] = FrameDecodeError
    """What :meth:`from_bus` raises for a frame the bus cannot carry (the bus's codec
    error, a :class:`FrameDecodeError`)."""

    arbitration_id: int
    data: bytes = b""

    def __post_init__(self) -> None:
        if isinstance(self.arbitration_id, bool) or not isinstance(self.arbitration_id, int):
            raise FrameEncodeError(f"CAN id must be an int, not {self.arbitration_id!r}")
        if not 0 <= self.arbitration_id <= MAX_ARBITRATION_ID:
            raise FrameEncodeError(f"CAN id {self.arbitration_id:#x} is not 11-bit")
        if not isinstance(self.data, bytes | bytearray | memoryview):
            raise FrameEncodeError(f"CAN data must be bytes, not {type(self.data).__name__}")
        data = bytes(self.data)
        if len(data) > MAX_DATA_LENGTH:
            raise FrameEncodeError(f"CAN data of {len(data)} bytes (at most 8)")
        _set(self, "data", data)

    @classmethod
    def from_bus(
        cls, arbitration_id: int, data: bytes | bytearray, *, is_extended_id: bool = False
    ) -> Self:
        """A frame as received; anything an 11-bit bus of classic frames cannot carry is
        :attr:`invalid`."""
        raw = bytes(data)
        if (
            not is_extended_id
            and type(arbitration_id) is int
            and 0 <= arbitration_id <= MAX_ARBITRATION_ID
            and len(raw) <= MAX_DATA_LENGTH
        ):  # every frame received: one test for the usual case (checked once, not twice)
            frame = _new(cls)
            _set(frame, "arbitration_id", arbitration_id)
            _set(frame, "data", raw)
            return frame
        if is_extended_id:
            raise cls.invalid("extended (29-bit) identifier", raw)
        if (
            isinstance(arbitration_id, bool)
            or not isinstance(arbitration_id, int)
            or not 0 <= arbitration_id <= MAX_ARBITRATION_ID
        ):
            raise cls.invalid(f"identifier {arbitration_id!r} is not 11-bit", raw)
        if len(raw) > MAX_DATA_LENGTH:
            raise cls.invalid(f"{len(raw)} data bytes (at most 8)", raw)
        return cls(arbitration_id, raw)  # an int subclass as identifier

    def __str__(self) -> str:
        return f"{self.arbitration_id:03X}#{self.data.hex().upper()}"
