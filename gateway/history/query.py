"""A history query as every front end takes it: ``start``, ``end`` and ``step`` as text,
checked, and the answer's JSON (docs/decisions/0084-history-served.md).

A time is seconds since the epoch (``1767225600``, ``1767225600.5``), an ISO 8601 date and
time (``2026-01-01T00:00:00Z``, ``2026-01-01T01:00+01:00``; one without an offset is UTC),
``now``, or ``now-<duration>``. A duration (``step``, and after ``now-``) is seconds
(``60``, ``0.5``) or a number with a unit: ``s``, ``m``, ``h``, ``d`` (``15m``, ``1d``).
``events`` (no value) asks for the range's events instead of the readings. Without
``end`` the range ends now; without ``start`` it begins :data:`DEFAULT_SPAN`
before its end; without ``step`` every sample is answered. Anything else is refused with a
:class:`~gateway.errors.HistoryError` that names the parameter, what it got and the forms
it takes, and nothing is read.
"""

from __future__ import annotations

import asyncio
import math
import re
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, TypeVar

from gateway.errors import HistoryError
from gateway.history.store import READINGS, HistoryEvent, HistoryRow, HistoryStore, check_range

T = TypeVar("T")
DEFAULT_SPAN = 3600.0  # s of a query without start
PARAMETERS = ("start", "end", "step", "events")
_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)\s*([smhd]?)")
_NUMBER = re.compile(r"[+-]?(\d+(?:\.\d*)?|\.\d+)")
TIME_FORMS = (
    "seconds since the epoch (1767225600), ISO 8601 (2026-01-01T00:00:00Z), now, or "
    "now-<duration> (now-1h)"
)
DURATION_FORMS = "seconds (60) or a number with s, m, h or d (15m)"


@dataclass(frozen=True, slots=True)
class HistoryRange:
    start: float
    end: float
    step: float | None = None
    events: bool = False
    """The events of the range instead of the readings (``events`` without a value)."""


def parse_duration(text: str, name: str) -> float:
    match = _DURATION.fullmatch(text.strip())
    if match is None:
        raise HistoryError(f"{name}={text!r} is not a duration: {DURATION_FORMS}")
    value = float(match.group(1)) * _UNITS[match.group(2) or "s"]
    if not math.isfinite(value) or value <= 0:
        raise HistoryError(f"{name}={text!r}: a duration above 0 is needed")
    return value


def parse_time(text: str, name: str, now: float) -> float:
    """A time parameter in seconds since the epoch (forms: the module docstring)."""
    value = text.strip()
    if value == "now":
        return now
    if value.startswith("now-"):
        return now - parse_duration(value[4:], name)
    if _NUMBER.fullmatch(value):
        return float(value)
    try:
        when = datetime.fromisoformat(value)
    except ValueError:
        raise HistoryError(f"{name}={text!r} is not a time: {TIME_FORMS}") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.timestamp()


def split_parameters(text: str) -> dict[str, str]:
    """``start=...;end=...;step=...`` (a Zenoh selector's parameters; ``&`` too)."""
    out: dict[str, str] = {}
    for part in re.split(r"[;&]", text):
        if part:
            name, _, value = part.partition("=")
            out[name.strip()] = value
    return out


def parse_range(params: Mapping[str, str], now: float) -> HistoryRange:
    """The range a query asks for; HistoryError naming what is wrong."""
    unknown = sorted(set(params) - set(PARAMETERS))
    if unknown:
        raise HistoryError(
            f"unknown parameter(s) {', '.join(unknown)}: a history query takes start, end, "
            "step and events"
        )
    events = "events" in params
    if events and (params["events"] or params.get("step")):
        raise HistoryError("events takes no value and no step: the events of a range, each one")
    end = parse_time(params["end"], "end", now) if params.get("end") else now
    start = parse_time(params["start"], "start", now) if params.get("start") else end - DEFAULT_SPAN
    step = parse_duration(params["step"], "step") if params.get("step") else None
    check_range(start, end, step)
    return HistoryRange(start, end, step, events)


def events_json(
    drive_id: str, asked: HistoryRange, events: Sequence[HistoryEvent]
) -> dict[str, Any]:
    """The answer to an events query: each event as the events key published it."""
    return {
        "drive": drive_id,
        "start": asked.start,
        "end": asked.end,
        "events": [e.to_json() for e in events],
    }


def columns_json(drive_id: str, asked: HistoryRange, rows: Sequence[HistoryRow]) -> dict[str, Any]:
    """The answer, column by column: ``t`` and one list per reading (readings no row gives
    are left out)."""
    names = [n for n in READINGS if any(r.values.get(n) is not None for r in rows)]
    return {
        "drive": drive_id,
        "start": asked.start,
        "end": asked.end,
        "step": asked.step,
        "t": [r.t for r in rows],
        "values": {n: [r.values.get(n) for r in rows] for n in names},
    }


async def off_loop(fn: Callable[[], T]) -> T:
    """``fn()`` (a query of the file) on a thread of its own, awaited from the loop: the
    loop never waits on the file, and no pool of threads outlives the front end."""
    loop = asyncio.get_running_loop()
    done: asyncio.Future[T] = loop.create_future()

    def settle(result: T | None, error: BaseException | None) -> None:
        if done.done():
            return
        if error is not None:
            done.set_exception(error)
        else:
            done.set_result(result)  # type: ignore[arg-type]

    def work() -> None:
        try:
            result = fn()
        except Exception as exc:
            loop.call_soon_threadsafe(settle, None, exc)
        else:
            loop.call_soon_threadsafe(settle, result, None)

    threading.Thread(target=work, name="history-query", daemon=True).start()
    return await done


def answer(store: HistoryStore, drive_id: str, asked: HistoryRange) -> dict[str, Any]:
    """The JSON answer to a history query of one drive (on a thread: it reads the file)."""
    if asked.events:
        return events_json(drive_id, asked, store.events(drive_id, asked.start, asked.end))
    rows = store.readings(drive_id, asked.start, asked.end, asked.step)
    return columns_json(drive_id, asked, rows)
