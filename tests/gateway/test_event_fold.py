"""A burst of identical events is one event with a count (gateway/eventlog.py): the first at
once, the count when the window is over or before the drive's next different event; a
different event is never held back; the table of runs is bounded. Stepped with an injected
clock."""

from __future__ import annotations

import logging

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.adapter import Event, EventKind
from gateway.eventlog import REPEATS, EventLog
from gateway.model import CommState, DriveStatus
from gateway.ratelimit import FOLD_MAX_KEYS, FOLD_WINDOW, RunFold, Told
from tests.gateway.test_hub import Clock, make_hub
from tests.gateway.test_hub_clients import Recorder

EMCY = "EMCY 0x2310 continuous over current (error register 0x03: generic error, current)"


def test_a_burst_of_identical_faults_is_one_event_then_one_with_the_count() -> None:
    hub, clock = make_hub()
    rec = Recorder(hub)
    for _ in range(1000):
        hub.event("d", EventKind.FAULT, EMCY, code=0x2310)
    (first,) = rec.all()
    assert first.text == EMCY and REPEATS not in first.data
    clock.t += FOLD_WINDOW / 2
    hub.tick()
    assert len(rec.all()) == 1  # the window is not over
    clock.t += FOLD_WINDOW / 2
    hub.tick()
    first, told = rec.all()
    assert told.kind is EventKind.FAULT and told.text == EMCY
    assert told.data == {"code": 0x2310, REPEATS: 999}
    assert hub.events_folded == 999
    hub.tick()
    assert len(rec.all()) == 2  # told once


def test_a_different_fault_in_a_burst_is_delivered_at_once_after_the_count() -> None:
    hub, _clock = make_hub()
    rec = Recorder(hub)
    for _ in range(500):
        hub.event("d", EventKind.FAULT, EMCY, code=0x2310)
    hub.event("d", EventKind.FAULT, "EMCY 0x4310 excess temperature", code=0x4310)
    for _ in range(500):
        hub.event("d", EventKind.FAULT, EMCY, code=0x2310)
    seen = [(e.text[:11], e.data.get(REPEATS)) for e in rec.all()]
    # nothing waits for a tick: the new code comes at once, the run it ended told before it
    old, new = "EMCY 0x2310", "EMCY 0x4310"
    assert seen == [(old, None), (old, 499), (new, None), (old, None)]
    assert hub.events_folded == 499 + 499


def test_the_same_fault_after_another_event_of_the_drive_is_delivered() -> None:
    """A fault announced again after the drive came back is news, not a repeat."""
    hub, _clock = make_hub()
    rec = Recorder(hub)
    hub.update("d", status=DriveStatus.FAULTED, fault_code=21)
    hub.update("d", comm=CommState.OFFLINE)
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.FAULTED, fault_code=21)
    assert rec.texts(EventKind.FAULT) == ["fault 21", "fault 21"]
    assert hub.events_folded == 0


def test_each_drive_has_its_own_run() -> None:
    hub, clock = make_hub()
    rec = Recorder(hub)
    for _ in range(10):
        for drive in ("a", "b"):
            hub.event(drive, EventKind.BUS, "bad EMCY: EMCY of 3 bytes (8 expected)")
    assert [e.drive_id for e in rec.all()] == ["a", "b"]
    clock.t += FOLD_WINDOW
    hub.tick()
    told = rec.all()[2:]
    assert sorted((e.drive_id, e.data[REPEATS]) for e in told) == [("a", 9), ("b", 9)]


def test_a_flood_that_goes_on_is_told_once_per_window() -> None:
    hub, clock = make_hub()
    rec = Recorder(hub)
    steps = 2000  # 10 s of 200 a second, the hub ticking every 50 ms
    for i in range(steps):
        hub.event("d", EventKind.BUS, "a device tried to claim the scanner's MAC ID 0")
        clock.t += 0.005
        if i % 10 == 9:
            hub.tick()
    clock.t += FOLD_WINDOW
    hub.tick()
    events = rec.all()
    assert len(events) <= 1 + 10 / FOLD_WINDOW + 1  # the first, then one per window
    assert 1 + sum(e.data.get(REPEATS, 0) for e in events[1:]) == steps


def test_a_burst_is_two_log_lines(caplog: pytest.LogCaptureFixture) -> None:
    hub, clock = make_hub()
    with caplog.at_level(logging.INFO, logger="gateway.hub"):
        for _ in range(1000):
            hub.event("d", EventKind.FAULT, EMCY)
        clock.t += FOLD_WINDOW
        hub.tick()
    lines = [r.getMessage() for r in caplog.records if "EMCY" in r.getMessage()]
    assert lines == [
        f"d: fault: {EMCY}",
        f"d: fault: {EMCY} (999 more like it since the last line)",
    ]


def test_many_drives_keep_the_table_bounded_and_no_count_is_lost() -> None:
    hub, clock = make_hub()
    rec = Recorder(hub)
    drives = 3 * FOLD_MAX_KEYS
    for n in range(drives):
        for _ in range(3):
            hub.event(f"x{n}", EventKind.BUS, "frame beyond the budget")
    assert hub._event_log.runs <= FOLD_MAX_KEYS
    clock.t += FOLD_WINDOW
    hub.tick()
    events = rec.all()
    firsts = [e for e in events if REPEATS not in e.data]
    told = [e for e in events if REPEATS in e.data]
    assert len(firsts) == drives
    # the oldest runs were dropped as the table filled: their counts were told then
    assert sorted(e.drive_id for e in told) == sorted(f"x{n}" for n in range(drives))
    assert sum(e.data[REPEATS] for e in told) == hub.events_folded == 2 * drives


def test_the_fold_alone_evicts_the_oldest_run_with_its_count() -> None:
    fold: RunFold[str] = RunFold(window=1.0, max_keys=2)
    assert fold.offer("a", 1, "a1", 0.0) == (Told("a1"),)
    assert fold.offer("a", 1, "a1 again", 0.1) == ()
    assert fold.offer("b", 1, "b1", 0.2) == (Told("b1"),)
    # a is the oldest: dropped, its repeat told before the new run's first item
    assert fold.offer("c", 1, "c1", 0.3) == (Told("a1 again", 1), Told("c1"))
    assert len(fold) == 2
    assert fold.offer("a", 1, "a1", 0.4) == (Told("a1"),)  # a new run


def test_a_repeat_after_the_window_before_a_flush_tells_the_count_with_it() -> None:
    fold: RunFold[str] = RunFold(window=1.0)
    fold.offer("a", 1, "first", 0.0)
    assert fold.offer("a", 1, "r1", 0.5) == ()
    assert fold.offer("a", 1, "r2", 1.5) == (Told("r2", 2),)  # no tick came: told now
    assert fold.offer("a", 1, "r3", 1.6) == ()  # the next window counts on
    assert fold.flush(2.5) == [Told("r3", 1)]
    assert fold.offer("a", 1, "alone", 9.0) == (Told("alone"),)  # a lone repeat, much later


# ------------------------------------------------------------------ the property

events = st.lists(
    st.tuples(
        st.sampled_from(["a", "b"]),
        st.sampled_from([EventKind.FAULT, EventKind.COMM]),
        st.sampled_from(["x", "y"]),
        st.sampled_from([0.0, 0.0, 0.01, 0.3, 1.2]),  # time to the next event
        st.booleans(),  # the hub ticks then
    ),
    max_size=60,
)


@settings(max_examples=200, deadline=None)
@given(events, st.integers(min_value=2, max_value=4))
def test_nothing_is_lost_reordered_or_delayed_when_it_differs(
    stream: list[tuple[str, EventKind, str, float, bool]], max_keys: int
) -> None:
    """Each drive's events, every told count expanded, are exactly what happened, in order;
    an event that differs from its drive's event before it is delivered at once."""
    clock = Clock()
    out: list[Event] = []
    log = EventLog(logging.getLogger("test.fold"), clock, out.append, max_keys=max_keys)
    last: dict[str, tuple[EventKind, str]] = {}
    for drive, kind, text, dt, tick in stream:
        ev = Event(drive, kind, text, clock.t)
        log.offer(ev)
        if last.get(drive) != (kind, text):
            assert out[-1] is ev  # never held back
        last[drive] = (kind, text)
        clock.t += dt
        if tick:
            log.flush()
    clock.t += FOLD_WINDOW
    log.flush()
    for drive in ("a", "b"):
        sent = [(k, t) for d, k, t, _dt, _tick in stream if d == drive]
        got: list[tuple[EventKind, str]] = []
        for e in out:
            if e.drive_id == drive:
                got += [(e.kind, e.text)] * e.data.get(REPEATS, 1)
        assert got == sent
    assert log.folded == sum(e.data.get(REPEATS, 0) for e in out)
