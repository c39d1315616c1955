"""Repeats held back and counted, per key (sans-IO: the caller passes the time).

:class:`LogRateLimit`: a flood of identical refusals (one client hammering one drive with
the same bad command) must not fill a disk: the first line of a key is written, the
repeats within ``period`` are counted, and the next line of that key (or :meth:`flush`
once the period is over) says how many were held back. The keys are bounded too, so a
client that varies its input cannot grow the table: the oldest key is dropped, and its
held-back count is reported by :meth:`flush` first.

:class:`RunFold`: a run of one value per key (the same event of a drive, again and again)
becomes its first item, passed on at once, and one item with the count of the repeats
after it: when the window is over (:meth:`RunFold.flush`) or when the key's next item
differs (returned before it, so the order of the items is kept). A different value is
never held back. The keys are bounded the same way.
"""

from __future__ import annotations

import collections
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Generic, TypeVar, cast

DEFAULT_PERIOD = 10.0  # s: one line per key per period
DEFAULT_MAX_KEYS = 1024
FOLD_WINDOW = 1.0  # s: a run's repeats are told at most this long after its first item
FOLD_MAX_KEYS = 4096  # runs remembered (one per drive in the hub)

T = TypeVar("T")


@dataclass(slots=True)
class _Entry:
    since: float  # when the last line of this key was written
    held: int = 0  # repeats held back since


class LogRateLimit:
    """One line per key and period; the repeats in between are counted."""

    def __init__(self, period: float = DEFAULT_PERIOD, max_keys: int = DEFAULT_MAX_KEYS) -> None:
        self.period = period
        self.max_keys = max_keys
        self._entries: collections.OrderedDict[Hashable, _Entry] = collections.OrderedDict()
        self._dropped: list[tuple[Hashable, int]] = []

    def admit(self, key: Hashable, now: float, count: int = 1) -> int | None:
        """None: hold this line back (it stands for ``count`` occurrences, all counted).
        Else write it, saying that the returned number of occurrences of the same key were
        held back since the last one."""
        entry = self._entries.get(key)
        if entry is not None and now - entry.since < self.period:
            entry.held += count
            return None
        held = 0 if entry is None else entry.held
        self._entries[key] = _Entry(since=now)
        self._entries.move_to_end(key)
        while len(self._entries) > self.max_keys:
            old_key, old = self._entries.popitem(last=False)
            if old.held:
                self._dropped.append((old_key, old.held))
        return held

    def flush(self, now: float) -> list[tuple[Hashable, int]]:
        """The keys whose period is over with lines held back, and how many; those
        counts start again from zero (the caller writes one summary line each)."""
        out, self._dropped = self._dropped, []
        for key, entry in self._entries.items():
            if entry.held and now - entry.since >= self.period:
                out.append((key, entry.held))
                entry.held = 0
                entry.since = now
        return out

    def __len__(self) -> int:
        return len(self._entries)


@dataclass(slots=True)
class _Run(Generic[T]):
    value: Hashable  # what a repeat has the same of
    since: float  # when its window began (its first item let through, or its last count)
    held: int = 0  # repeats held back since
    last: T | None = None  # the last of them


@dataclass(frozen=True, slots=True)
class Told(Generic[T]):
    """An item let through: ``repeats`` 0, the item itself; else it tells that many repeats
    held back, of which it is the last."""

    item: T
    repeats: int = 0


class RunFold(Generic[T]):
    """Runs of one value per key folded into their first item and a count (see the module
    docstring). ``folded`` counts every item held back."""

    def __init__(self, window: float = FOLD_WINDOW, max_keys: int = FOLD_MAX_KEYS) -> None:
        self.window = window
        self.max_keys = max_keys
        self.folded = 0
        self._runs: collections.OrderedDict[Hashable, _Run[T]] = collections.OrderedDict()
        self._holding: dict[Hashable, _Run[T]] = {}  # the runs with repeats held back

    def offer(self, key: Hashable, value: Hashable, item: T, now: float) -> tuple[Told[T], ...]:
        """What to let through now, in order; nothing: ``item`` repeats its key's run within
        the window, held back and counted. An item of another value ends its key's run (the
        run's count first, when it has repeats); a new key may end the oldest run (the
        table is bounded). A repeat after the window, before :meth:`flush` came, is told at
        once with the count it ends."""
        run = self._runs.get(key)
        if run is None:
            self._runs[key] = _Run(value, now)
            if len(self._runs) > self.max_keys:
                return (*self._evict(), Told(item))
            return (Told(item),)
        if run.value == value and (run.held or now - run.since < self.window):
            run.held += 1
            run.last = item
            self.folded += 1
            if now - run.since < self.window:
                if run.held == 1:
                    self._holding[key] = run
                return ()
            run.since = now
            return (self._told(key, run),)
        ended = (self._told(key, run),) if run.held else ()
        run.value, run.since = value, now
        self._runs.move_to_end(key)
        return (*ended, Told(item))

    def flush(self, now: float) -> list[Told[T]]:
        """The counts of the runs whose window is over with repeats held back, each once;
        their next window begins now (a flood that goes on is told once per window)."""
        out: list[Told[T]] = []
        for key, run in tuple(self._holding.items()):
            if now - run.since >= self.window:
                out.append(self._told(key, run))
                run.since = now
        return out

    def _told(self, key: Hashable, run: _Run[T]) -> Told[T]:
        told = Told(cast(T, run.last), run.held)  # held > 0: the last repeat is there
        run.held, run.last = 0, None
        del self._holding[key]
        return told

    def _evict(self) -> tuple[Told[T], ...]:
        key, run = self._runs.popitem(last=False)
        return (self._told(key, run),) if run.held else ()

    def __len__(self) -> int:
        return len(self._runs)
