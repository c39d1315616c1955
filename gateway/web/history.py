"""The trend history: a bounded ring of samples per drive, kept in the daemon.

Sans-IO: :meth:`TrendHistory.sample` takes the time and the states it is given; the web
front end calls it every :data:`SAMPLE_PERIOD` seconds. A drive keeps at most
``span / period`` samples (10 minutes at 2 Hz: 1,200), the oldest giving way, so memory
is bounded whatever the page's clients do.

A sample is ``(t, speed_rpm, speed_ref_rpm, current)``: ``t`` in seconds since the epoch,
``None`` where the drive gives no such reading (a soft starter has no speed). The current
is in A, or in % of the motor's full-load current for a drive that reports only that
(``current_unit`` says which).
"""

from __future__ import annotations

import collections
from collections.abc import Iterable
from typing import Any

from gateway.history.query import HistoryRange
from gateway.model import DriveState

SAMPLE_PERIOD = 0.5  # s between samples (2 Hz)
SPAN = 600.0  # s of history kept per drive (10 minutes)

Sample = tuple[float, float | None, float | None, float | None]


def _rounded(value: float | None, digits: int) -> float | None:
    return None if value is None else round(value, digits)


def current_unit(state: DriveState) -> str:
    """What the trend's current is in for this drive: "A" or "%FLC"."""
    return "%FLC" if state.current_a is None and state.current_pct_flc is not None else "A"


def sample_of(t: float, state: DriveState) -> Sample:
    current = state.current_a if state.current_a is not None else state.current_pct_flc
    return (
        round(t, 3),
        _rounded(state.speed_rpm, 1),
        _rounded(state.speed_ref_rpm, 1),
        _rounded(current, 2),
    )


class TrendHistory:
    """Per drive: the last ``span`` seconds of samples taken every ``period`` seconds."""

    def __init__(self, period: float = SAMPLE_PERIOD, span: float = SPAN) -> None:
        self.period = period
        self.span = span
        self.capacity = max(1, round(span / period))
        self._rings: dict[str, collections.deque[Sample]] = {}
        self._units: dict[str, str] = {}

    def sample(self, t: float, states: Iterable[DriveState]) -> dict[str, Sample]:
        """Take one sample of every drive at ``t``; returns them by drive id."""
        taken: dict[str, Sample] = {}
        for state in states:
            ring = self._rings.get(state.id)
            if ring is None:
                ring = self._rings[state.id] = collections.deque(maxlen=self.capacity)
            point = sample_of(t, state)
            ring.append(point)
            self._units[state.id] = current_unit(state)
            taken[state.id] = point
        return taken

    def points(self, drive_id: str) -> list[Sample]:
        return list(self._rings.get(drive_id, ()))

    def to_json(self, drive_id: str) -> dict[str, Any]:
        """One drive's history, column by column (compact for the page)."""
        ring = self._rings.get(drive_id, ())
        return {
            "current_unit": self._units.get(drive_id, "A"),
            "t": [p[0] for p in ring],
            "speed": [p[1] for p in ring],
            "ref": [p[2] for p in ring],
            "current": [p[3] for p in ring],
        }

    def all_json(self) -> dict[str, Any]:
        return {
            "period": self.period,
            "span": self.span,
            "drives": {drive_id: self.to_json(drive_id) for drive_id in self._rings},
        }


def ring_json(history: TrendHistory, drive_id: str, asked: HistoryRange) -> dict[str, Any]:
    """The ring's samples in ``asked`` as the history store answers (columns; no
    downsampling: the ring holds 10 minutes), for a gateway without ``[history]``."""
    points = [p for p in history.points(drive_id) if asked.start <= p[0] < asked.end]
    names = ("speed_rpm", "speed_ref_rpm", "current_a")
    return {
        "drive": drive_id,
        "start": asked.start,
        "end": asked.end,
        "step": None,
        "t": [p[0] for p in points],
        "values": {name: [p[i + 1] for p in points] for i, name in enumerate(names)},
    }
