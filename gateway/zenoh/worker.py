"""The I/O thread: the one place where calls that may block on the network are made.

The event loop hands work over in two ways and never waits for the network:

- :meth:`Worker.offer` puts a job into a latest-per-key slot. A newer job for the
  same key replaces one not yet run, so a slow network conflates (newest state of
  each drive wins) and memory stays bounded by the number of keys.
- :meth:`Worker.post` / :meth:`Worker.call` queue a job in order (events, replies,
  liveliness changes); ``call`` returns a future the loop may await.

In each round the thread runs the ordered jobs first, then the slots. :meth:`stop`
lets it finish what was handed over (the newest state is never lost as the last
word), run a final job (closing the session), and exit.
"""

from __future__ import annotations

import collections
import concurrent.futures
import logging
import threading
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

from gateway.errors import GatewayError

log = logging.getLogger(__name__)

T = TypeVar("T")
Job = Callable[[], Any]


class WorkerStopped(GatewayError, RuntimeError):
    """Work handed to a worker that is stopping or stopped."""


class Worker:
    def __init__(self, name: str) -> None:
        self._cond = threading.Condition()
        self._ordered: collections.deque[tuple[Job, concurrent.futures.Future[Any] | None]] = (
            collections.deque()
        )
        self._latest: dict[Hashable, Job] = {}
        self._stopping = False
        self._final: Job | None = None
        self._done: concurrent.futures.Future[None] = concurrent.futures.Future()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.runs = 0  # jobs run (offered jobs that were replaced do not count)
        self.replaced = 0  # offered jobs replaced by a newer one before they ran

    @property
    def thread(self) -> threading.Thread:
        return self._thread

    def start(self) -> None:
        self._thread.start()

    # ------------------------------------------------------------ handing over

    def offer(self, key: Hashable, job: Job) -> None:
        """Run ``job`` soon, unless a newer job for ``key`` comes first. Never blocks."""
        with self._cond:
            if self._stopping:
                raise WorkerStopped("the I/O thread is stopping")
            if key in self._latest:
                self.replaced += 1
            self._latest[key] = job
            self._cond.notify()

    def post(self, job: Job) -> None:
        """Run ``job`` in order; an exception is logged. Never blocks."""
        self._enqueue(job, None)

    def call(self, job: Callable[[], T]) -> concurrent.futures.Future[T]:
        """Run ``job`` in order; the future holds its result or exception."""
        future: concurrent.futures.Future[T] = concurrent.futures.Future()
        self._enqueue(job, future)
        return future

    def _enqueue(self, job: Job, future: concurrent.futures.Future[Any] | None) -> None:
        with self._cond:
            if self._stopping:
                raise WorkerStopped("the I/O thread is stopping")
            self._ordered.append((job, future))
            self._cond.notify()

    def stop(self, final: Job | None = None) -> concurrent.futures.Future[None]:
        """Finish the work handed over, run ``final``, exit; the future is done when it has."""
        with self._cond:
            if not self._stopping:
                self._stopping = True
                self._final = final
                self._cond.notify()
        if not self._thread.is_alive() and not self._done.done():
            self._done.set_result(None)  # never started
        return self._done

    def join(self, timeout: float | None = None) -> None:
        if self._thread.is_alive():
            self._thread.join(timeout)

    # ------------------------------------------------------------ the thread

    def _take(self) -> tuple[list[tuple[Job, Any]], list[Job], bool]:
        with self._cond:
            while not self._ordered and not self._latest and not self._stopping:
                self._cond.wait()
            ordered = list(self._ordered)
            self._ordered.clear()
            latest = list(self._latest.values())
            self._latest.clear()
            return ordered, latest, self._stopping

    def _run(self) -> None:
        try:
            while True:
                ordered, latest, stopping = self._take()
                for job, future in ordered:
                    self._run_one(job, future)
                for job in latest:
                    self._run_one(job, None)
                if stopping and not ordered and not latest:
                    break
            if self._final is not None:
                self._run_one(self._final, None)
        finally:
            self._done.set_result(None)

    def _run_one(self, job: Job, future: concurrent.futures.Future[Any] | None) -> None:
        self.runs += 1
        if future is not None and not future.set_running_or_notify_cancel():
            return
        try:
            result = job()
        except BaseException as exc:
            if future is None:
                log.exception("zenoh I/O job failed")
            else:
                future.set_exception(exc)
            if not isinstance(exc, Exception):
                raise
            return
        if future is not None:
            future.set_result(result)
