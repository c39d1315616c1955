"""The history's recorder: on the daemon's loop, it takes a sample of every drive every
``history.period`` seconds and every event the hub delivers, and hands them to the writer
thread without waiting (gateway/history/writer.py).

It reads the hub the way the front ends do: ``hub.states()`` and an event subscription
(bounded; a fault, a trip, a safety action and a comm change are never dropped by it).
Nothing of the fieldbus lines or of the hub waits for the file: when the writer falls
behind, its queue refuses what comes and counts it.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

from gateway.adapter import Event, EventKind
from gateway.config import HistorySection
from gateway.history.query import off_loop
from gateway.history.store import HistoryEvent, HistoryStore, samples_of
from gateway.history.writer import HistoryWriter, Retention
from gateway.hub import EventSubscription, Hub

log = logging.getLogger(__name__)

STOP_TIMEOUT = 10.0  # s the writer may take to write its last batch at shutdown


def history_event(ev: Event) -> HistoryEvent:
    return HistoryEvent(ev.ts, ev.drive_id, ev.kind.value, ev.text, dict(ev.data))


class HistoryRecorder:
    """Samples and events of one hub into one history file (module docstring)."""

    def __init__(
        self, hub: Hub, section: HistorySection, clock: Callable[[], float] = time.time
    ) -> None:
        self.hub = hub
        self.section = section
        self.clock = clock
        self.writer = HistoryWriter(
            section.path,
            Retention(section.max_age, int(section.max_size_mb * 1024 * 1024)),
            batch_interval=section.batch_interval,
        )
        self.store = HistoryStore(section.path, counters=self.writer.counters)
        self._loop: asyncio.AbstractEventLoop | None = None

    async def run(self) -> None:
        """Record until cancelled; then write what is left and close the file."""
        loop = self._loop = asyncio.get_running_loop()

        def moved(old: Path, new: Path, why: str) -> None:
            loop.call_soon_threadsafe(self._moved, new, why)

        self.writer.on_moved = moved
        self.writer.start()
        log.info(
            "history in %s: a sample every %g s, written every %g s",
            self.section.path,
            self.section.period,
            self.section.batch_interval,
        )
        events = self.hub.subscribe_events()
        try:
            await self._record(events)
        finally:
            self._take_events(events)
            events.close()
            await off_loop(partial(self.writer.stop, STOP_TIMEOUT))

    async def _record(self, events: EventSubscription) -> None:
        period = self.section.period
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            self.sample()
            self._take_events(events)
            next_at += period
            delay = next_at - loop.time()
            if delay < 0:  # the loop was held up: no burst of samples to catch up
                next_at, delay = loop.time(), 0.0
            await asyncio.sleep(delay)

    def sample(self) -> None:
        """One sample of every drive that gives a reading, handed to the writer."""
        samples = samples_of(self.clock(), self.hub.states())
        if samples:
            self.writer.offer(samples)

    def _take_events(self, events: EventSubscription) -> None:
        for ev in events.drain():
            self.writer.offer(history_event(ev))

    def _moved(self, moved: Path, why: str) -> None:
        """The file was corrupt: every drive's events say so (its history went with it)."""
        for drive_id in self.hub.drive_ids():
            self.hub.event(
                drive_id,
                EventKind.CONFIG,
                f"history database {self.section.path} could not be used ({why}): moved "
                f"aside to {moved.name}; a new one started",
                moved_to=str(moved),
            )
