"""The I/O thread: ordered jobs, latest-per-key slots, flush on stop."""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from functools import partial

import pytest

from gateway.zenoh.worker import Worker, WorkerStopped
from tests.support.timing import scaled

WAIT = scaled(20.0)


@pytest.fixture
def worker() -> Iterator[Worker]:
    w = Worker("test-io")
    w.start()
    yield w
    w.stop().result(WAIT)
    w.join(WAIT)


def test_ordered_jobs_run_in_order_and_calls_return_results(worker: Worker) -> None:
    seen: list[int] = []
    for i in range(50):
        worker.post(partial(seen.append, i))
    assert worker.call(lambda: 42).result(WAIT) == 42
    assert seen == list(range(50))
    with pytest.raises(ZeroDivisionError):
        worker.call(lambda: 1 / 0).result(WAIT)


def test_offers_conflate_while_the_thread_is_busy(worker: Worker) -> None:
    release = threading.Event()
    busy = threading.Event()

    def hang() -> None:
        busy.set()
        release.wait(WAIT)

    worker.post(hang)
    assert busy.wait(WAIT)
    seen: list[tuple[str, int]] = []
    for i in range(1000):  # never blocks, though the thread is stuck
        worker.offer("a", partial(seen.append, ("a", i)))
        worker.offer("b", partial(seen.append, ("b", i)))
    release.set()
    worker.call(lambda: None).result(WAIT)
    worker.call(lambda: None).result(WAIT)  # the slots run after the ordered jobs of a round
    assert sorted(seen) == [("a", 999), ("b", 999)]
    assert worker.replaced == 2 * 999


def test_stop_flushes_what_was_handed_over_then_runs_the_final_job() -> None:
    w = Worker("test-io")
    release = threading.Event()
    w.start()
    seen: list[str] = []
    w.post(lambda: release.wait(WAIT))
    w.offer("state", lambda: seen.append("old"))
    w.offer("state", lambda: seen.append("newest"))
    w.post(lambda: seen.append("event"))
    done = w.stop(final=lambda: seen.append("closed"))
    with pytest.raises(WorkerStopped):
        w.offer("state", lambda: seen.append("too late"))
    with pytest.raises(WorkerStopped):
        w.post(lambda: None)
    release.set()
    done.result(WAIT)
    w.join(WAIT)
    assert seen == ["event", "newest", "closed"]
    assert not w.thread.is_alive()


def test_a_failing_job_is_logged_and_the_thread_goes_on(
    worker: Worker, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.ERROR, logger="gateway.zenoh.worker"):
        worker.post(lambda: 1 / 0)
        worker.offer("k", partial(dict[str, int]().__getitem__, "missing"))
        assert worker.call(lambda: "alive").result(WAIT) == "alive"
        worker.call(lambda: None).result(WAIT)
    assert [r.exc_info[0] for r in caplog.records if r.exc_info] == [ZeroDivisionError, KeyError]


def test_stopping_a_worker_that_never_started() -> None:
    w = Worker("never")
    assert w.stop().done()
    w.join(WAIT)
