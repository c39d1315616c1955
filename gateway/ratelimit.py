"""Repeated log lines, rate-limited per key (sans-IO: the caller passes the time).

A flood of identical refusals (one client hammering one drive with the same bad
command) must not fill a disk: the first line of a key is written, the repeats
within ``period`` are counted, and the next line of that key (or :meth:`flush`
once the period is over) says how many were held back. The keys are bounded
too, so a client that varies its input cannot grow the table: the oldest key
is dropped, and its held-back count is reported by :meth:`flush` first.
"""

from __future__ import annotations

import collections
from collections.abc import Hashable
from dataclasses import dataclass

DEFAULT_PERIOD = 10.0  # s: one line per key per period
DEFAULT_MAX_KEYS = 1024


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

    def admit(self, key: Hashable, now: float) -> int | None:
        """None: hold this line back. Else write it, saying that the returned
        number of lines of the same key were held back since the last one."""
        entry = self._entries.get(key)
        if entry is not None and now - entry.since < self.period:
            entry.held += 1
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
