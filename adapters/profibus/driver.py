"""Runs a sans-IO Profibus engine (the master or a live-list scan) on a serial link.

The driver loop is the shared one (:class:`adapters.link.stream.StreamDriver`: stepping,
precise timers on the loop, late reply deadlines); this module gives it the FDL
stream codec (:class:`FdlStream`: a whole telegram per read, or the streaming decoder with
its noise and "receiving" events) and says which master actions are requests
(:class:`~adapters.profibus.master.events.Transmit`, confirmed with
:class:`~adapters.profibus.master.events.Written`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from adapters.link.serial import SerialLink
from adapters.link.stream import ReplyEngine, StreamDriver, Transmission
from adapters.profibus.codec.fdl import (
    DataTelegram,
    Discarded,
    NeedMore,
    ShortAck,
    TelegramDecoder,
    TokenTelegram,
)
from adapters.profibus.master import Event, FrameIn, LineNoise, Receiving, Transmit, Written

__all__ = ["FdlStream", "LineDriver"]

_TELEGRAMS: Final = (DataTelegram, ShortAck, TokenTelegram)
_RECEIVING: Final = Receiving()


class FdlStream:
    """The FDL telegram stream as the driver loop sees it (fact sheet 1.1)."""

    def __init__(self) -> None:
        self.decoder = TelegramDecoder()

    def whole(self, data: bytes) -> Event | None:
        telegram = self.decoder.whole(data)
        return None if telegram is None else FrameIn(telegram, data)

    def feed(self, data: bytes) -> list[Event]:
        self.decoder.feed(data)
        return self._events()

    def receiving(self) -> Event | None:
        return _RECEIVING if self.decoder.buffered else None

    def idle(self) -> list[Event]:
        # 1.1: the line was idle before this request; nothing before it is a telegram
        self.decoder.mark_idle()
        if not self.decoder.buffered:
            return []
        return [event for event in self._events() if isinstance(event, LineNoise)]

    def transmission(self, action: Any) -> Transmission | None:
        return action if isinstance(action, Transmit) else None

    def written(self, at: float) -> Event:
        return Written(at)

    def _events(self) -> list[Event]:
        out: list[Event] = []
        while True:
            item = self.decoder.next_frame()
            if isinstance(item, NeedMore):
                return out
            if isinstance(item, Discarded):
                out.append(LineNoise(item.error))
            elif isinstance(item, _TELEGRAMS):
                out.append(FrameIn(item))


class LineDriver(StreamDriver[Event]):
    """The shared stream driver with the FDL codec (see the module docstring)."""

    def __init__(
        self,
        engine: ReplyEngine[Event],
        link: SerialLink,
        on_action: Callable[[Any], None] = lambda action: None,
        on_noise: Callable[[LineNoise], None] = lambda noise: None,
        on_stepped: Callable[[], None] = lambda: None,
        *,
        bursts: bool = False,
        ring_priority: int = 0,
    ) -> None:
        self.stream = FdlStream()
        super().__init__(
            engine,
            link,
            self.stream,
            on_action=on_action,
            on_flushed=_noise(on_noise),
            on_stepped=on_stepped,
            bursts=bursts,
            ring_priority=ring_priority,
        )

    @property
    def decoder(self) -> TelegramDecoder:
        return self.stream.decoder


def _noise(on_noise: Callable[[LineNoise], None]) -> Callable[[Event], None]:
    def flushed(event: Event) -> None:
        if isinstance(event, LineNoise):
            on_noise(event)

    return flushed
