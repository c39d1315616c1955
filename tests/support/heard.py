"""Waiting on simulated Profibus slaves: a test wakes after each telegram a slave takes
(``SlaveCounters.watchers``), never on a timer."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from types import TracebackType

from adapters.profibus.sim.slave import SlaveCounters


class Heard:
    """``with Heard(counters, ...) as heard``: ``await heard.next()`` returns after the next
    telegram any of the slaves took (or at once if one came since the last call)."""

    def __init__(self, *counters: SlaveCounters) -> None:
        self._counters = counters
        self._event = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None

    def _wake(self) -> None:
        assert self._loop is not None
        self._loop.call_soon_threadsafe(self._event.set)  # the simulator may run elsewhere

    def __enter__(self) -> Heard:
        self._loop = asyncio.get_running_loop()
        for counters in self._counters:
            counters.watchers.append(self._wake)
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for counters in self._counters:
            counters.watchers.remove(self._wake)

    async def next(self) -> None:
        await self._event.wait()
        self._event.clear()

    async def until(self, cond: Callable[[], bool]) -> None:
        """Until ``cond`` holds, checked after each telegram (unbounded: bound the caller)."""
        while not cond():
            await self.next()
