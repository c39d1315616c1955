"""The steady ring: a run of request/reply exchanges whose bytes are known beforehand
(what it is given and gives back, sans-IO: :mod:`adapters.link.ringplan`).

An engine whose line is at rest (each reply the same as the last, each next request fixed)
plans a ring (:class:`RingPlan`): for each exchange the reply it would take whole and
the request that follows it, the line's idle time and reply wait as numbers. The ring
runs it on the port's descriptor without the engine: reads each reply until it is whole,
takes it when it is the one expected, waits the idle time, writes the next request (a
broadcast only when it is due then: ``RingPlan.gc_due``, docs/decisions/0110), and
stops at the first anything else, before acting on it (:class:`RingStop`). The engine is
then brought up to date once for the whole run (:class:`RingResult`: when each reply came
and each request went) instead of once per exchange (docs/decisions/0103-steady-ring.md).

The ring runs in compiled code (``adapters/link/_ring.c``, built by the project's
``setup.py`` where a C compiler is; the GIL released, so the line's thread holds no lock
another thread wants while it waits for the line) or, where that is not built, in
:func:`run_python`: the same steps in Python. Both are run by the same tests
(``tests/link/test_ring.py``); ``DRIVE_GATEWAY_RING=python`` chooses the fallback,
``DRIVE_GATEWAY_RING=off`` no ring at all (comparisons).

A wake descriptor (the line loop's self-pipe: something was handed to the loop from
another thread, a command among them) stops the ring before its next read or write.

With a priority (a line's ``ring_priority``) a ring runs under ``SCHED_FIFO`` at it, and
its thread's own scheduling is put back after it (docs/decisions/0104): a reply wakes the
ring before the box's other work, however busy. A ring blocks on the port between
telegrams and lasts at most to its horizon, so a real-time thread can never hold a CPU the
way a line's Python, busy flat out, would.
"""

from __future__ import annotations

import errno
import math
import os
import select
import time
from collections.abc import Callable
from typing import Final

from adapters.link.ringplan import REPLY_MAX, RingPlan, RingResult, RingStop

_Native = Callable[..., tuple[int, tuple[float, ...], bytes, float, float, int, int, int, int]]

try:
    from adapters.link import _ring  # type: ignore[attr-defined]

    _native: _Native | None = _ring.run
except ImportError:  # not built (no C compiler where it was installed): the fallback
    _native = None

SELECT_LIMIT: Final = 1024  # FD_SETSIZE on Linux


def enabled() -> bool:
    """Whether drivers run steady rings (``DRIVE_GATEWAY_RING=off``: never, for a
    comparison; the exchanges then go one by one through the engine)."""
    return os.environ.get("DRIVE_GATEWAY_RING") != "off"


def compiled() -> bool:
    """Whether the compiled ring is built and chosen (``DRIVE_GATEWAY_RING=python``: the
    fallback)."""
    return _native is not None and os.environ.get("DRIVE_GATEWAY_RING") != "python"


def ring_mode() -> str:
    """ "compiled", "python" or "off" (for the figures of a benchmark)."""
    if not enabled():
        return "off"
    return "compiled" if compiled() else "python"


def run(fd: int, wake: int, plan: RingPlan, priority: int = 0) -> RingResult:
    """Run ``plan`` on the port ``fd`` (non-blocking), stopping when ``wake`` (a descriptor,
    -1 for none) becomes readable, under SCHED_FIFO at ``priority`` (0: the thread's own
    scheduling); compiled where it is built."""
    native = _native if compiled() else None
    if native is not None:
        stop, times, rest, rest_at, idle, partial, n_in, n_out, rt = native(
            fd,
            wake,
            plan.deadline,
            plan.expected,
            plan.requests,
            plan.tsyn,
            plan.reply_wait,
            plan.t_char,
            plan.idle_since,
            plan.busy_until,
            plan.horizon,
            priority,
            plan.gc_due,
            plan.gc_period,
        )
        return RingResult(RingStop(stop), times, rest, rest_at, idle, partial, n_in, n_out, rt)
    return run_python(fd, wake, plan, priority)


# ---------------------------------------------------------------------------------------
# The fallback: the same steps as _ring.c


def run_python(fd: int, wake: int, plan: RingPlan, priority: int = 0) -> RingResult:
    """:func:`run` in Python (the steps of ``_ring.c``, one for one)."""
    ring = _PyRing(fd, wake, plan)
    realtime, was = _raise(priority)
    try:
        stop = ring.run()
    finally:
        if was is not None:
            os.sched_setscheduler(0, *was)
    return RingResult(
        stop,
        tuple(ring.times),
        bytes(ring.rest),
        ring.rest_at,
        ring.idle_since,
        ring.partial,
        ring.bytes_in,
        ring.bytes_out,
        realtime,
    )


def _raise(priority: int) -> tuple[int, tuple[int, os.sched_param] | None]:
    """The calling thread under SCHED_FIFO at ``priority``: (1, what to put back), (0,
    None) not asked, (-errno, None) refused."""
    if priority <= 0:
        return 0, None
    try:
        was = (os.sched_getscheduler(0), os.sched_getparam(0))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return -(exc.errno or errno.EPERM), None
    return 1, was


class _PyRing:
    def __init__(self, fd: int, wake: int, plan: RingPlan) -> None:
        if len(plan.requests) + 1 != len(plan.expected):
            raise ValueError("a ring of n exchanges: n replies, n - 1 requests")
        self.fd, self.wake, self.plan = fd, wake, plan
        self.deadline = plan.deadline
        self.idle_since = plan.idle_since
        self.busy_until = plan.busy_until
        self.last_end = plan.idle_since
        self.gc_due = plan.gc_due
        self.skipped = False  # the last broadcast was not due: left out
        self.times: list[float] = []
        self.rest = bytearray()
        self.rest_at = 0.0
        self.partial = -1
        self.bytes_in = self.bytes_out = 0
        self._fds = [fd] if wake < 0 else [fd, wake]
        self._select = max(self._fds) < SELECT_LIMIT
        self._poll = select.poll()
        for each in self._fds:
            self._poll.register(each, select.POLLIN)

    def run(self) -> RingStop:
        n = len(self.plan.expected)
        for i in range(n):
            stop = self._take_reply(i)
            if stop is not None:
                return stop
            if i + 1 == n:
                return RingStop.END
            stop = self._send_request(i)
            if stop is not None:
                return stop
        return RingStop.END

    def _wait(self, until: float) -> int:
        """0 time over (never before it), 1 port readable, 2 wake readable, -1 port error."""
        while True:
            left = max(until - time.monotonic(), 0.0)
            if self._select:  # to the microsecond (an idle time of 22 us)
                ready = select.select(self._fds, [], self._fds, left)
                if self.wake in ready[0]:
                    return 2
                if ready[2]:
                    return -1
                if ready[0]:
                    return 1
            else:  # descriptors above select's limit: poll, to the millisecond
                events = dict(self._poll.poll(math.ceil(left * 1000)))
                if self.wake >= 0 and events.get(self.wake):
                    return 2
                port = events.get(self.fd, 0)
                if port & select.POLLIN:
                    return 1
                if port:
                    return -1
            if time.monotonic() >= until:
                return 0

    def _take_reply(self, i: int) -> RingStop | None:
        self.rest.clear()
        want = self.plan.expected[i]
        if not want and self.skipped:  # a broadcast left out: nothing on the line
            self.skipped = False
            self.times.append(math.nan)
            return None
        if not want:  # a broadcast: nobody answers, the line free TSYN after its end
            self.busy_until = max(self.busy_until, self.last_end + self.plan.tsyn)
            self.times.append(self.last_end)
            return None
        while True:
            w = self._wait(self.deadline)
            if w == 0:
                return RingStop.TIMEOUT
            if w == 2:
                return RingStop.WAKE
            if w < 0:
                return RingStop.PORT
            try:
                got = os.read(self.fd, REPLY_MAX - len(self.rest))
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR):
                    continue
                return RingStop.PORT
            if not got:
                return RingStop.PORT
            self.rest += got
            self.bytes_in += len(got)
            self.rest_at = time.monotonic()
            if len(self.rest) < len(want) and want.startswith(self.rest):
                continue
            if self.rest != want:
                return RingStop.DIFFER
            self.rest.clear()
            self.times.append(self.rest_at)
            self.idle_since = max(self.idle_since, self.rest_at)
            return None

    def _send_request(self, i: int) -> RingStop | None:
        plan = self.plan
        free = max(self.busy_until, self.idle_since + plan.tsyn)
        if free > plan.horizon:
            return RingStop.HORIZON
        if free > time.monotonic():
            w = self._wait(free)
            if w == 1:
                return RingStop.BYTES
            if w == 2:
                return RingStop.WAKE
            if w < 0:
                return RingStop.PORT
        broadcast = not plan.expected[i + 1]
        if broadcast and time.monotonic() < self.gc_due:  # not due: the next follows
            self.skipped = True
            self.times.append(math.nan)
            return None
        data = plan.requests[i]
        try:
            put = os.write(self.fd, data)
        except OSError:
            put = -1
        at = time.monotonic()
        if broadcast:
            self.gc_due = at + plan.gc_period
        self.times.append(at)
        if put != len(data):
            self.partial = max(put, 0)
            self.bytes_out += self.partial
            return RingStop.WRITE
        self.bytes_out += put
        end = self.last_end = at + len(data) * plan.t_char
        self.idle_since = max(self.idle_since, end)
        self.deadline = end + plan.reply_wait
        return None
