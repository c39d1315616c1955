"""The history's writer thread: batches from a bounded queue, retention, a corrupt file
moved aside.

The recorder (gateway/history/recorder.py, on the daemon's loop) hands samples and events
over with :meth:`HistoryWriter.offer`, which never waits: when :data:`QUEUE_LIMIT` items
wait, the item is dropped and counted (``dropped``). The thread writes what waited, in
one transaction, every ``batch_interval`` seconds, and checkpoints the WAL after it (in WAL
mode ``synchronous=NORMAL`` syncs at checkpoints only): a power cut loses at most that
batch.
Every :data:`PRUNE_EVERY` seconds (and once at start) it deletes what is older than
``max_age`` and, while the file uses more than ``max_size_mb``, the oldest tenth.

A database that cannot be opened or checked, or that fails a write as corrupt, is moved
aside (``<name>.corrupt-<UTC time>``) and a new one started; ``on_moved(old, new, why)``
tells it (the recorder raises an event of every drive with it). Any other failure of a
batch is logged (once per :data:`LOG_PERIOD`) and the batch dropped and counted; the
thread goes on.
"""

from __future__ import annotations

import logging
import queue
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gateway.history.store import HistoryDb, HistoryEvent, Sample, WriterCounters, move_aside

log = logging.getLogger(__name__)

QUEUE_LIMIT = 10_000
"""Items (one sampling of every drive, or one event) waiting for the writer."""
PRUNE_EVERY = 60.0  # s between retention passes
LOG_PERIOD = 60.0  # s between two log lines of failing batches

Item = list[Sample] | HistoryEvent
OnMoved = Callable[[Path, Path, str], None]


@dataclass(frozen=True, slots=True)
class Retention:
    max_age: float  # s
    max_bytes: int


_CORRUPT_CODES = (sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB)


def _is_corrupt(exc: BaseException) -> bool:
    """A file that is no sound history database (not one that is locked or unreadable)."""
    if not isinstance(exc, sqlite3.DatabaseError):
        return False
    code = getattr(exc, "sqlite_errorcode", None)
    if code is not None:
        return code & 0xFF in _CORRUPT_CODES
    return not isinstance(exc, sqlite3.OperationalError)  # the schema checks of HistoryDb


class HistoryWriter:
    """Owns the history file: one thread writes it in batches (module docstring)."""

    def __init__(
        self,
        path: Path,
        retention: Retention,
        *,
        batch_interval: float = 1.0,
        on_moved: OnMoved | None = None,
        limit: int = QUEUE_LIMIT,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.path = path
        self.retention = retention
        self.batch_interval = batch_interval
        self.on_moved = on_moved
        self.clock = clock
        self.counters = WriterCounters()
        self._queue: queue.Queue[Item | None] = queue.Queue(limit)
        self._thread: threading.Thread | None = None
        self._db: HistoryDb | None = None
        self._next_prune = 0.0
        self._logged_at = -LOG_PERIOD
        self.opened = threading.Event()
        """Set once the file is open (or moved aside and a new one started)."""

    # ------------------------------------------------------------ any thread

    def offer(self, item: Item) -> bool:
        """Hand samples or an event to the writer without waiting; False (counted) when
        the queue is full."""
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            if isinstance(item, HistoryEvent):
                self.counters.events_dropped += 1
            else:
                self.counters.samples_dropped += len(item)
            return False
        return True

    @property
    def waiting(self) -> int:
        """Items handed over and not yet taken by the thread."""
        return self._queue.qsize()

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="history-writer", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Write what waits, close the file, end the thread (within ``timeout``)."""
        thread = self._thread
        if thread is None:
            return
        try:
            self._queue.put(None, timeout=timeout)
        except queue.Full:
            log.warning("history writer: queue full at stop; the last batch may be lost")
        thread.join(timeout)
        self._thread = None

    # ------------------------------------------------------------ the thread

    def _run(self) -> None:
        self._open()
        try:
            while self._batch():
                pass
        finally:
            if self._db is not None:
                self._db.close()
                self._db = None

    def _open(self) -> None:
        try:
            self._db = HistoryDb.open_checked(self.path)
        except sqlite3.Error as exc:
            if _is_corrupt(exc):
                self._move_aside(str(exc))
            else:
                log.error("history: cannot open %s: %s; no history is kept", self.path, exc)
        except OSError as exc:
            log.error("history: cannot open %s: %s; no history is kept", self.path, exc)
        self.opened.set()

    def _move_aside(self, why: str) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None
        try:
            moved = move_aside(self.path, self.clock())
            self._db = HistoryDb.open_checked(self.path)
        except (OSError, sqlite3.Error) as exc:
            log.error("history: cannot start a new %s: %s; no history is kept", self.path, exc)
            return
        self.counters.moved_aside += 1
        log.error(
            "history: %s cannot be used (%s): moved aside to %s; a new one started",
            self.path,
            why,
            moved,
        )
        if self.on_moved is not None:
            self.on_moved(self.path, moved, why)

    def _batch(self) -> bool:
        """Wait out one batch interval, write what came; False once told to stop."""
        deadline = time.monotonic() + self.batch_interval
        samples: list[Sample] = []
        events: list[HistoryEvent] = []
        go_on = True
        while True:
            remaining = deadline - time.monotonic()
            try:
                item = (
                    self._queue.get(timeout=remaining)
                    if remaining > 0
                    else (self._queue.get_nowait())
                )
            except queue.Empty:
                break
            if item is None:
                go_on = False
                self._drain_into(samples, events)
                break
            if isinstance(item, HistoryEvent):
                events.append(item)
            else:
                samples.extend(item)
        self._write(samples, events)
        self._maybe_prune()
        return go_on

    def _drain_into(self, samples: list[Sample], events: list[HistoryEvent]) -> None:
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return
            if isinstance(item, HistoryEvent):
                events.append(item)
            elif item is not None:
                samples.extend(item)

    def _write(self, samples: list[Sample], events: list[HistoryEvent]) -> None:
        if (not samples and not events) or self._db is None:
            self._failed(samples, events)
            return
        try:
            self._db.write(samples, events)
            self._db.checkpoint()  # synchronous=NORMAL syncs the WAL at checkpoints only
        except sqlite3.Error as exc:
            self._failed(samples, events)
            if _is_corrupt(exc):
                self._move_aside(str(exc))
            else:
                self._log_failure(exc)
            return
        self.counters.batches += 1
        self.counters.samples += len(samples)
        self.counters.events += len(events)

    def _failed(self, samples: list[Sample], events: list[HistoryEvent]) -> None:
        self.counters.samples_failed += len(samples)
        self.counters.events_failed += len(events)

    def _maybe_prune(self) -> None:
        now = self.clock()
        if self._db is None or now < self._next_prune:
            return
        self._next_prune = now + PRUNE_EVERY
        try:
            self.counters.pruned += self._db.prune(
                now, self.retention.max_age, self.retention.max_bytes
            )
        except sqlite3.Error as exc:
            if _is_corrupt(exc):
                self._move_aside(str(exc))
            else:
                self._log_failure(exc)

    def _log_failure(self, exc: BaseException) -> None:
        now = time.monotonic()
        if now - self._logged_at >= LOG_PERIOD:
            self._logged_at = now
            log.error("history: a batch could not be written to %s: %s", self.path, exc)
