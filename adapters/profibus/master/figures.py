"""Counters and timing figures of a Profibus line and of each slave (the master's diagnostics).

Plain data kept by the master engine; ``to_json()`` gives the form the adapter publishes
(times in milliseconds). Minimum and maximum are over the whole run, the median over the
last :data:`WINDOW` samples.
"""

from __future__ import annotations

import math
from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Final

WINDOW: Final = 256


class Samples:
    """Durations in seconds: last, all-time min/max, median of the last ``size``.

    The last ``size`` are kept twice: in arrival order (the oldest leaves first) and
    sorted, kept so by each :meth:`add` (a binary search and a move of at most ``size``
    references), so the median costs nothing to read: a line's diagnostics read every
    slave's several times a second, and sorting each window there took most of their
    build."""

    def __init__(self, size: int = WINDOW) -> None:
        self._recent: deque[float] = deque(maxlen=size)
        self._ranked: list[float] = []  # the same values, ascending
        self.count = 0
        self.last = math.nan
        self.min = math.inf
        self.max = 0.0

    def add(self, value: float) -> None:
        recent, ranked = self._recent, self._ranked
        if math.isnan(value):  # no place in an order (never a measured duration)
            return
        if len(recent) == recent.maxlen:
            del ranked[bisect_left(ranked, recent[0])]
        recent.append(value)
        insort(ranked, value)
        self.count += 1
        self.last = value
        self.min = min(self.min, value)
        self.max = max(self.max, value)

    @property
    def median(self) -> float:
        """The median of the last ``size`` (the mean of the middle two for an even count)."""
        ranked = self._ranked
        n = len(ranked)
        if not n:
            return math.nan
        half = n // 2
        return ranked[half] if n % 2 else (ranked[half - 1] + ranked[half]) / 2

    def to_json(self) -> dict[str, float] | None:
        """``{"last", "min", "median", "max"}`` in ms, or None before the first sample."""
        if not self.count:
            return None
        return {
            "last": round(self.last * 1e3, 3),
            "min": round(self.min * 1e3, 3),
            "median": round(self.median * 1e3, 3),
            "max": round(self.max * 1e3, 3),
        }


@dataclass
class ErrorCounters:
    """What went wrong on the line, counted where it was seen."""

    retries: int = 0  # requests repeated after no reply or a garbled one
    timeouts: int = 0  # waits that ended without a valid reply
    fcs_errors: int = 0  # telegrams with a bad checksum
    framing_errors: int = 0  # other undecodable bytes (delimiters, lengths, FC)
    invalid_replies: int = 0  # well-formed telegrams that do not answer the request

    def counters(self) -> dict[str, int]:
        return {
            "retries": self.retries,
            "timeouts": self.timeouts,
            "fcs_errors": self.fcs_errors,
            "framing_errors": self.framing_errors,
            "invalid_replies": self.invalid_replies,
        }


@dataclass
class SlaveFigures(ErrorCounters):
    requests: int = 0
    exchanges: int = 0  # successful Data_Exchange cycles
    restarts: int = 0  # times the slave left data exchange
    response: Samples = field(default_factory=Samples)  # request sent -> reply received

    def to_json(self) -> dict[str, Any]:
        return {
            "requests": self.requests,
            "exchanges": self.exchanges,
            "restarts": self.restarts,
            **self.counters(),
            "response_ms": self.response.to_json(),
        }


@dataclass
class LineFigures(ErrorCounters):
    cycles: int = 0
    telegrams: int = 0  # requests and broadcasts sent
    discarded_bytes: int = 0
    unexpected: int = 0  # telegrams nobody waited for (late replies, other stations)
    low_deferred: int = 0  # low-priority telegrams left for a later cycle (its budget spent)
    cycle: Samples = field(default_factory=Samples)  # first request -> end of the cycle

    def to_json(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles,
            "telegrams": self.telegrams,
            **self.counters(),
            "discarded_bytes": self.discarded_bytes,
            "unexpected_telegrams": self.unexpected,
            "low_priority_deferred": self.low_deferred,
            "cycle_ms": self.cycle.to_json(),
        }
