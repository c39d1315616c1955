"""The CAN frame as the DeviceNet codec sees it: 11-bit identifier, 0-8 data bytes.

Fact sheet 2.13 (standard CAN 2.0A frame, 11-bit id, at most 8 data bytes). The
codec never imports python-can; the link converts ``can.Message`` with
:meth:`CanFrame.from_bus` (which raises a typed decode error) and back with the two
fields.
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.devicenet.errors import InvalidCanFrame
from gateway.errors import FrameEncodeError

MAX_ARBITRATION_ID = 0x7FF  # 11-bit identifier (fact sheet 2.1, 2.13)
MAX_DATA_LENGTH = 8  # classic CAN (fact sheet 2.13)

_new = object.__new__  # from_bus builds a checked frame without checking it again
_set = object.__setattr__


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One classic CAN data frame with an 11-bit identifier.

    Building one with an out-of-range id or more than 8 bytes raises
    :class:`FrameEncodeError`; use :meth:`from_bus` for received frames.
    """

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
        object.__setattr__(self, "data", data)

    @classmethod
    def from_bus(
        cls, arbitration_id: int, data: bytes | bytearray, *, is_extended_id: bool = False
    ) -> CanFrame:
        """A frame as received; anything DeviceNet cannot carry is an :class:`InvalidCanFrame`."""
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
            raise InvalidCanFrame("extended (29-bit) identifier", raw)
        if (
            isinstance(arbitration_id, bool)
            or not isinstance(arbitration_id, int)
            or not 0 <= arbitration_id <= MAX_ARBITRATION_ID
        ):
            raise InvalidCanFrame(f"identifier {arbitration_id!r} is not 11-bit", raw)
        if len(raw) > MAX_DATA_LENGTH:
            raise InvalidCanFrame(f"{len(raw)} data bytes (at most 8)", raw)
        return cls(arbitration_id, raw)

    def __str__(self) -> str:
        return f"{self.arbitration_id:03X}#{self.data.hex().upper()}"
