"""The history store: batches, retention, downsampling, a corrupt file moved aside, and
rows that come back as they went in."""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gateway.errors import HistoryError
from gateway.history.query import parse_range, split_parameters
from gateway.history.store import (
    MINUTE,
    READINGS,
    HistoryDb,
    HistoryEvent,
    HistoryStore,
    Sample,
)
from gateway.history.writer import HistoryWriter, Retention
from tests.support.timing import scaled

T0 = 1_767_225_600.0  # 2026-01-01T00:00:00Z, a whole minute
NONE = (None,) * (len(READINGS) - 1)
KEEP = Retention(max_age=10 * 366 * 86400.0, max_bytes=1 << 30)


def speed(drive: str, t: float, value: float | None) -> Sample:
    return Sample(drive, t, (value, *NONE))


def test_rows_come_back_in_order_and_per_drive(tmp_path: Path) -> None:
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    db.write([speed("a", T0 + i, i) for i in range(10)] + [speed("b", T0, 99.0)], [])
    rows = HistoryStore(tmp_path / "h.sqlite").readings("a", T0 + 2, T0 + 5)
    assert [(r.t, r.values["speed_rpm"]) for r in rows] == [(T0 + 2, 2), (T0 + 3, 3), (T0 + 4, 4)]
    assert rows[0].values["current_a"] is None
    assert set(rows[0].values) == set(READINGS)
    assert HistoryStore(tmp_path / "h.sqlite").readings("nobody", T0, T0 + 10) == []


def test_a_missing_file_has_no_rows(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "none.sqlite")
    assert store.readings("a", T0, T0 + 1) == []
    assert store.events(None, T0, T0 + 1) == []


def test_downsampling_averages_each_bucket_of_the_epoch(tmp_path: Path) -> None:
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    db.write([speed("a", T0 + i, float(i)) for i in range(30)], [])
    rows = HistoryStore(tmp_path / "h.sqlite").readings("a", T0, T0 + 30, step=10)
    assert [(r.t, r.values["speed_rpm"]) for r in rows] == [
        (T0, 4.5),
        (T0 + 10, 14.5),
        (T0 + 20, 24.5),
    ]
    assert all(r.values["power_kw"] is None for r in rows)


@pytest.mark.parametrize(("start", "end"), [(T0, T0 + 3600), (T0 + 17.5, T0 + 3000.25)])
def test_whole_minute_steps_read_the_minute_sums_and_agree_with_the_samples(
    tmp_path: Path, start: float, end: float
) -> None:
    """A step of whole minutes reads the ``minutes`` table for the minutes wholly inside
    the range and the samples at its edges: the same averages as from the samples alone."""
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    samples = [speed("a", T0 + i * 0.5, math.sin(i) * 100) for i in range(2 * 3600)]
    for at in range(0, len(samples), 500):  # several batches: the minute sums add up
        db.write(samples[at : at + 500], [])
    store = HistoryStore(tmp_path / "h.sqlite")
    fast = store.readings("a", start, end, step=5 * MINUTE)
    expected: dict[float, list[float]] = {}
    for s in samples:
        if start <= s.t < end:
            expected.setdefault(math.floor(s.t / 300) * 300.0, []).append(s.values[0] or 0.0)
    assert [r.t for r in fast] == sorted(expected)
    for row in fast:
        want = sum(expected[row.t]) / len(expected[row.t])
        assert row.values["speed_rpm"] == pytest.approx(want, abs=1e-9)


def test_too_many_rows_are_refused_with_the_step_that_fits(tmp_path: Path) -> None:
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    db.write([speed("a", T0 + i, 1.0) for i in range(50)], [])
    store = HistoryStore(tmp_path / "h.sqlite", max_rows=20)
    with pytest.raises(HistoryError, match="give a step"):
        store.readings("a", T0, T0 + 50)
    with pytest.raises(HistoryError, match="a step of at least 3 s"):
        store.readings("a", T0, T0 + 50, step=1)
    assert len(store.readings("a", T0, T0 + 50, step=3)) == 17


def test_events_of_one_drive_or_all(tmp_path: Path) -> None:
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    events = [
        HistoryEvent(T0 + 1, "a", "fault", "F021 undervoltage", {"code": 21}),
        HistoryEvent(T0 + 2, "b", "comm", "online", {}),
    ]
    db.write([], events)
    store = HistoryStore(tmp_path / "h.sqlite")
    assert store.events(None, T0, T0 + 10) == events
    assert store.events("a", T0, T0 + 10) == events[:1]
    assert events[0].to_json()["code"] == 21


def test_events_by_pages_oldest_or_newest_first(tmp_path: Path) -> None:
    """A page of ``limit`` events and the one after it (where the next page starts); the
    newest first for a read backwards; never more than max_rows, never an error."""
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    events = [HistoryEvent(T0 + i, "a", "command", f"e{i}") for i in range(12)]
    db.write([], events)
    store = HistoryStore(tmp_path / "h.sqlite", max_rows=10)
    assert store.events("a", T0, T0 + 20, limit=4) == events[:5]
    assert store.events("a", T0, T0 + 20, limit=4, newest=True) == events[::-1][:5]
    assert store.events("a", T0, T0 + 20, limit=50) == events[:11]  # max_rows + 1
    with pytest.raises(HistoryError, match="more than 10 events"):
        store.events("a", T0, T0 + 20)


def test_retention_by_age_and_by_size(tmp_path: Path) -> None:
    db = HistoryDb.open_checked(tmp_path / "h.sqlite")
    day = [speed("a", T0 + i, float(i)) for i in range(0, 86400, 2)]
    db.write(day, [HistoryEvent(T0, "a", "comm", "online")])
    store = HistoryStore(tmp_path / "h.sqlite")
    db.prune(T0 + 86400, max_age=3600, max_bytes=1 << 30)
    kept = store.readings("a", T0, T0 + 86400)
    assert kept[0].t >= T0 + 86400 - 3600
    assert store.events(None, T0, T0 + 86400) == []
    db.write(day, [])
    big = db.used_bytes()
    db.prune(T0 + 86400, max_age=10 * 86400, max_bytes=big // 3)
    assert db.used_bytes() <= big // 3
    left = store.readings("a", T0, T0 + 86400)
    assert left and left[-1].t == day[-1].t  # the newest rows stay
    assert left[0].t > T0


def test_the_writer_commits_in_batches_and_counts_what_the_full_queue_refused(
    tmp_path: Path,
) -> None:
    path = tmp_path / "h.sqlite"
    writer = HistoryWriter(path, KEEP, batch_interval=0.05, limit=3)
    for i in range(5):  # not started: the queue fills
        writer.offer([speed("a", T0 + i, float(i))])
    assert writer.counters.samples_dropped == 2
    writer.start()
    assert writer.opened.wait(scaled(10))
    writer.stop(scaled(10))  # what waited is written before the thread ends
    store = HistoryStore(path)
    assert [r.t for r in store.readings("a", T0, T0 + 10)] == [T0, T0 + 1, T0 + 2]
    assert writer.counters.samples == 3
    assert writer.counters.batches >= 1


def test_a_corrupt_file_is_moved_aside_and_a_new_one_started(tmp_path: Path) -> None:
    path = tmp_path / "h.sqlite"
    path.write_bytes(b"this is no SQLite database, it only has the name of one" * 100)
    moved: list[tuple[Path, str]] = []
    writer = HistoryWriter(
        path,
        KEEP,
        batch_interval=0.05,
        on_moved=lambda old, new, why: moved.append((new, why)),
    )
    writer.start()
    assert writer.opened.wait(scaled(10))
    writer.offer([speed("a", T0, 1.0)])
    writer.stop(scaled(10))
    assert len(moved) == 1
    aside, why = moved[0]
    assert aside.name.startswith("h.sqlite.corrupt-")
    assert aside.read_bytes().startswith(b"this is no SQLite")
    assert "not a database" in why
    assert [r.t for r in HistoryStore(path).readings("a", T0, T0 + 1)] == [T0]
    assert writer.counters.moved_aside == 1


def test_a_damaged_page_is_found_at_open(tmp_path: Path) -> None:
    path = tmp_path / "h.sqlite"
    db = HistoryDb.open_checked(path)
    db.write([speed("a", T0 + i, float(i)) for i in range(20000)], [])
    db.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    db.close()
    raw = bytearray(path.read_bytes())
    page = 4096
    for at in range(3 * page, len(raw) - page, 7 * page):  # scribble over pages of the B-tree
        raw[at + 8 : at + page] = b"\xa5" * (page - 8)
    path.write_bytes(bytes(raw))
    with pytest.raises(sqlite3.DatabaseError):
        HistoryDb.open_checked(path)


VALUE = st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False, width=32))


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    rows=st.dictionaries(
        st.floats(min_value=0, max_value=1e6, allow_nan=False).map(lambda x: round(x, 3)),
        st.tuples(*(VALUE for _ in READINGS)),
        max_size=50,
    )
)
def test_every_row_comes_back_as_it_went_in(
    tmp_path_factory: pytest.TempPathFactory, rows: dict[float, tuple[float | None, ...]]
) -> None:
    path = tmp_path_factory.mktemp("h") / "h.sqlite"
    db = HistoryDb.open_checked(path)
    db.write([Sample("d", T0 + t, values) for t, values in rows.items()], [])
    db.close()
    back = HistoryStore(path).readings("d", T0, T0 + 2e6)
    assert [(r.t, tuple(r.values[n] for n in READINGS)) for r in back] == sorted(
        (T0 + t, v) for t, v in rows.items()
    )


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("start=yesterday", "start='yesterday' is not a time"),
        ("end=5;start=10", "end (5) is before start (10)"),
        ("step=0", "step='0': a duration above 0"),
        ("step=-5", "step='-5' is not a duration"),
        ("step=nan", "step='nan' is not a duration"),
        ("start=now-x", "start='x' is not a duration"),
        ("limit=5", "unknown parameter(s) limit"),
        ("events;step=60", "events takes no value and no step"),
        ("events=yes", "events takes no value and no step"),
    ],
)
def test_bad_parameters_are_refused_by_name(text: str, error: str) -> None:
    with pytest.raises(HistoryError) as caught:
        parse_range(split_parameters(text), T0)
    assert error in str(caught.value)


def test_the_forms_of_a_time() -> None:
    asked = parse_range(
        split_parameters("start=2026-01-01T00:00:00Z;end=2026-01-01T02:00:00+01:00;step=15m"), 0
    )
    assert (asked.start, asked.end, asked.step) == (T0, T0 + 3600, 900)
    asked = parse_range(split_parameters("start=now-1d;step=60"), T0)
    assert (asked.start, asked.end, asked.step) == (T0 - 86400, T0, 60)
    assert parse_range({}, T0).start == T0 - 3600
    assert parse_range(split_parameters("events;start=now-1h"), T0).events
    assert parse_range(split_parameters(f"start={T0}&end=2026-01-01T00:00:10"), 0).end == T0 + 10


def test_the_writer_prunes_by_age_as_it_goes(tmp_path: Path) -> None:
    path = tmp_path / "h.sqlite"
    now = T0 + 10 * 86400
    writer = HistoryWriter(
        path, Retention(max_age=86400, max_bytes=1 << 30), batch_interval=0.05, clock=lambda: now
    )
    writer.offer([speed("a", T0, 1.0), speed("a", now - 60, 2.0)])
    writer.offer(HistoryEvent(T0, "a", "comm", "online"))
    writer.start()
    writer.stop(scaled(10))
    store = HistoryStore(path)
    assert [r.t for r in store.readings("a", 0, now)] == [now - 60]
    assert store.events(None, 0, now) == []
    assert writer.counters.pruned == 2
