"""The CANopen line's CAN link: the shared python-can link (:mod:`adapters.link.can`)
carrying :class:`~adapters.canopen.codec.frames.CanFrame` (11-bit COB-ID, at most 8 data
bytes: CiA 301 uses the base frame format), and the real line's link factory
(:class:`CanOpenBus`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

from adapters.canopen.codec.frames import CanFrame
from adapters.link.can import CanConfig, CanEvent, CanLinks
from adapters.link.can import CanLink as SharedCanLink

LinkConfig: TypeAlias = CanConfig
LinkEvent: TypeAlias = CanEvent[CanFrame]
Link: TypeAlias = SharedCanLink[CanFrame]
"""Any CAN link carrying CANopen frames (a link factory's)."""


def make_frame(arbitration_id: int, data: bytes, is_extended_id: bool) -> CanFrame:
    """A received frame; InvalidCobId (a FrameDecodeError) if CANopen cannot carry it."""
    return CanFrame.from_bus(arbitration_id, data, is_extended_id=is_extended_id)


class CanLink(SharedCanLink[CanFrame]):
    """The shared CAN link with CANopen frames. Use ``async with CanLink(cfg) as link``."""

    def __init__(self, config: LinkConfig) -> None:
        super().__init__(config, make_frame)


@dataclass(frozen=True)
class CanOpenBus(CanLinks[CanFrame]):
    """The real line: the configured interface and channel."""

    config: LinkConfig

    def link(self) -> CanLink:
        return CanLink(self.config)
