"""The CAN frame as the DeviceNet codec sees it: 11-bit identifier, 0-8 data bytes.

Fact sheet 2.13 (standard CAN 2.0A frame, 11-bit id, at most 8 data bytes): the frame of
every bus on CAN (:class:`adapters.can.frame.CanFrame`), whose :meth:`~CanFrame.from_bus`
raises :class:`~adapters.devicenet.errors.InvalidCanFrame` for what DeviceNet cannot carry.
"""

from __future__ import annotations

from typing import ClassVar

from adapters.can import frame as can_frame
from adapters.devicenet.errors import InvalidCanFrame
from gateway.errors import FrameDecodeError


class CanFrame(can_frame.CanFrame):
    """One classic CAN data frame with an 11-bit identifier, on DeviceNet."""

    __slots__ = ()
    invalid: ClassVar[type[FrameDecodeError]] = InvalidCanFrame
