"""A drive's states never go backwards on the wire.

The loop puts each change at once (DROP); the I/O thread puts the newest state again
(BLOCK) when it settles and on every heartbeat. Both sends of one drive must never race:
a settle put prepared before a change and sent after it would show a subscriber an
older ``seq`` after a newer one. These tests step the front end's two sides by hand,
with recording publishers in place of Zenoh's, so each interleaving is shown exactly.
"""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Iterator
from typing import Any

from gateway.zenoh.frontend import ZenohFrontEnd
from gateway.zenoh.keys import KeyKind
from tests.support.net import zenoh_endpoint
from tests.zenoh.test_frontend import make_runtime

DRIVE = "d1"


class Recorder:
    """Stands for the loop's DROP publisher and the I/O thread's link: the seqs put."""

    def __init__(self, wire: list[tuple[str, int]], how: str) -> None:
        self.wire = wire
        self.how = how

    def put(self, payload: bytes) -> None:
        self.wire.append((self.how, json.loads(payload)["seq"]))

    def publish_state(self, drive_id: str, payload: bytes) -> None:
        self.put(payload)


def front_end() -> tuple[ZenohFrontEnd, list[tuple[str, int]]]:
    fe = ZenohFrontEnd(make_runtime(zenoh_endpoint()))
    wire: list[tuple[str, int]] = []
    fe._changes = {DRIVE: Recorder(wire, "drop")}
    fe._link = Recorder(wire, "block")  # type: ignore[assignment]
    return fe, wire


def change(fe: ZenohFrontEnd, speed: float) -> Any:
    """A reading changes in the hub and the loop forwards it."""
    state = fe.hub.update(DRIVE, speed_rpm=speed)
    fe._send_state(state, 0.0)
    return state


def settle_job(fe: ZenohFrontEnd) -> Any:
    """The job the loop handed to the I/O thread for the drive's BLOCK put."""
    return fe.worker._latest.pop((KeyKind.STATE, DRIVE))


@contextlib.contextmanager
def thread_in_its_put(fe: ZenohFrontEnd, job: Any) -> Iterator[None]:
    """Run the I/O thread's ``job`` in a thread, held inside its first put (with the
    drive's lock) while the body runs; then let it finish."""
    in_put = threading.Event()
    go_on = threading.Event()
    block = fe._link

    class SlowLink:
        def __init__(self) -> None:
            self.calls = 0

        def publish_state(self, drive_id: str, payload: bytes) -> None:
            self.calls += 1
            if self.calls == 1:
                in_put.set()
                go_on.wait(5)
            block.publish_state(drive_id, payload)  # type: ignore[union-attr]

    fe._link = SlowLink()  # type: ignore[assignment]
    thread = threading.Thread(target=job)
    thread.start()
    try:
        assert in_put.wait(5)
        yield
    finally:
        go_on.set()
        thread.join(5)
    assert not thread.is_alive()


def seqs(wire: list[tuple[str, int]]) -> list[int]:
    return [seq for _, seq in wire]


def test_a_settle_put_prepared_before_a_change_never_sends_the_older_state() -> None:
    fe, wire = front_end()
    first = change(fe, 100.0)
    fe._confirm(DRIVE, 0.0)  # the heartbeat hands the state over...
    job = settle_job(fe)
    second = change(fe, 200.0)  # ...a change is put before the I/O thread runs
    job()
    assert seqs(wire) == [first.seq, second.seq, second.seq]
    assert seqs(wire) == sorted(seqs(wire))


def test_a_change_while_the_thread_puts_is_put_by_the_thread_after_its_own() -> None:
    fe, wire = front_end()
    first = change(fe, 100.0)
    fe._confirm(DRIVE, 0.0)
    with thread_in_its_put(fe, settle_job(fe)):
        second = change(fe, 200.0)  # the loop neither waits for the thread nor overtakes it
        assert seqs(wire) == [first.seq]
    # nothing lost, nothing backwards: the thread put the change right after its own put
    assert wire == [("drop", first.seq), ("block", first.seq), ("block", second.seq)]


def test_a_state_older_than_the_newest_handed_over_is_never_put() -> None:
    fe, wire = front_end()
    lagging = fe.hub.update(DRIVE, speed_rpm=100.0)  # still queued in the subscription
    newer = fe.hub.update(DRIVE, speed_rpm=200.0)
    fe._confirm(DRIVE, 0.0)  # nothing put yet: the heartbeat takes the hub's newest state
    settle_job(fe)()
    fe._send_state(lagging, 0.0)  # the subscription catches up
    fe._send_state(newer, 0.0)
    assert seqs(wire) == [newer.seq]


def test_a_heartbeat_repeats_what_was_put_not_what_waits_in_the_subscription() -> None:
    fe, wire = front_end()
    first = change(fe, 100.0)
    waiting = fe.hub.update(DRIVE, speed_rpm=200.0)  # committed, not yet forwarded
    fe._confirm(DRIVE, 0.0)  # the heartbeat runs first in this turn of the loop
    job = settle_job(fe)
    fe._send_state(waiting, 0.0)  # then the forwarder: the state gets its own put
    newer = change(fe, 300.0)  # the next change comes before the I/O thread runs
    job()
    # every committed state reached the wire, in order (the slot's job put the newest)
    assert seqs(wire) == [first.seq, waiting.seq, newer.seq, newer.seq]


def test_every_change_while_the_thread_holds_the_lock_reaches_the_wire_in_order() -> None:
    """The I/O thread can hold a drive's lock for milliseconds (it must win the GIL back
    from a busy loop to return from ``put``): each change made meanwhile gets its own put."""
    fe, wire = front_end()
    first = change(fe, 100.0)
    fe._confirm(DRIVE, 0.0)
    with thread_in_its_put(fe, settle_job(fe)):
        meanwhile = [change(fe, 200.0 + i) for i in range(3)]
        assert seqs(wire) == [first.seq]
    assert wire == [("drop", first.seq), ("block", first.seq)] + [
        ("block", s.seq) for s in meanwhile
    ]


def test_a_deferred_change_goes_out_before_the_loops_next_one() -> None:
    fe, wire = front_end()
    first = change(fe, 100.0)
    lock = fe._put_locks[DRIVE]
    with lock:  # the I/O thread's put is under way...
        deferred = change(fe, 200.0)
    # ...and it let the lock go before it looked again: the loop's next change comes first
    latest = change(fe, 300.0)
    assert wire == [("drop", first.seq), ("drop", deferred.seq), ("drop", latest.seq)]
    fe._confirm(DRIVE, 0.0)
    settle_job(fe)()  # the settle put repeats the newest, and nothing older comes after it
    assert seqs(wire) == [first.seq, deferred.seq, latest.seq, latest.seq]
