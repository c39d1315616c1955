"""The DeviceNet line's CAN link: the shared python-can link (:mod:`adapters.link.can`)
carrying :class:`~adapters.devicenet.codec.frame.CanFrame` (11-bit identifier, at most 8 data
bytes: fact sheet 2.13), and the real line's link factory (:class:`DeviceNetBus`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

import can

from adapters.devicenet.codec.frame import CanFrame
from adapters.link.can import (
    REFUSED_INTERFACES,
    CanConfig,
    CanEvent,
    CanLinks,
    RxBad,
    RxError,
    RxFailed,
    RxFrame,
)
from adapters.link.can import CanLink as SharedCanLink
from adapters.link.can import convert as convert_message

__all__ = [
    "REFUSED_INTERFACES",
    "CanLink",
    "DeviceNetBus",
    "Link",
    "LinkConfig",
    "LinkEvent",
    "RxBad",
    "RxError",
    "RxFailed",
    "RxFrame",
    "convert",
    "make_frame",
]

LinkConfig: TypeAlias = CanConfig
LinkEvent: TypeAlias = CanEvent[CanFrame]
Link: TypeAlias = SharedCanLink[CanFrame]
"""Any CAN link carrying DeviceNet frames (a link factory's)."""


def make_frame(arbitration_id: int, data: bytes, is_extended_id: bool) -> CanFrame:
    """A received frame; InvalidCanFrame (a FrameDecodeError) if DeviceNet cannot carry it."""
    return CanFrame.from_bus(arbitration_id, data, is_extended_id=is_extended_id)


def convert(msg: can.Message) -> LinkEvent:
    """A python-can message as the DeviceNet codec sees it; never raises."""
    return convert_message(msg, make_frame)


class CanLink(SharedCanLink[CanFrame]):
    """The shared CAN link with DeviceNet frames. Use ``async with CanLink(cfg) as link``."""

    def __init__(self, config: LinkConfig) -> None:
        super().__init__(config, make_frame)


@dataclass(frozen=True)
class DeviceNetBus(CanLinks[CanFrame]):
    """The real line: the configured interface and channel."""

    config: LinkConfig

    def link(self) -> CanLink:
        return CanLink(self.config)
