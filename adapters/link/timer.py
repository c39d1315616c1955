"""A precise one-shot timer the event loop sleeps on: a Linux timerfd, read by ``add_reader``.

asyncio's own timers wake the loop through ``epoll_wait``, whose timeout is whole
milliseconds (rounded up): a wait of 66 us (Profibus TSYN at 500 kbit/s) would last 1 ms.
A timerfd (timerfd_create(2)) is a file descriptor that becomes readable at a time given
to the nanosecond; the loop waits on it like on any port, so it sleeps until then and
wakes with the kernel's hrtimer precision (tens of microseconds on a loaded machine),
without spinning. Python 3.11 has no ``os.timerfd_create`` (3.13 has), so the three libc
calls go through ctypes.

The timer is armed with an absolute ``CLOCK_MONOTONIC`` time (``TFD_TIMER_ABSTIME``): the
clock of asyncio's ``loop.time()`` (``time.monotonic``), so a deadline the engine computed
from ``loop.time()`` is given as is; the kernel never fires before it. Re-arming or
disarming resets the expiration count, so a timer that expired and was re-armed before its
callback ran reads nothing (``EAGAIN``) and its callback does not run: only the time last
set ever fires.

Where there is no timerfd (not Linux, no libc through ctypes), :func:`loop_timer` falls back
to ``loop.call_at`` (:class:`CallAtTimer`): as correct (never early), up to a millisecond
late.
"""

from __future__ import annotations

import asyncio
import collections
import ctypes
import ctypes.util
import logging
import math
import os
import time
from collections.abc import Callable, Sized
from typing import Final, Protocol

log = logging.getLogger(__name__)

TFD_TIMER_ABSTIME: Final = 1  # timerfd_settime(2): the time is absolute
TFD_NONBLOCK: Final = os.O_NONBLOCK  # timerfd_create(2): the flags are the open(2) ones
TFD_CLOEXEC: Final = os.O_CLOEXEC
NS: Final = 1_000_000_000


class LoopTimer(Protocol):
    """One callback at one time, set again or cancelled at will."""

    @property
    def at(self) -> float | None:
        """The time armed (``loop.time()``'s clock), None when not armed."""
        ...

    def set(self, when: float) -> None:
        """Call back at ``when`` (never before it), instead of any time set before."""
        ...

    def cancel(self) -> None: ...

    def close(self) -> None:
        """Cancel and release (the timer is not used again)."""
        ...


class _Timespec(ctypes.Structure):
    _fields_ = (("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long))


class _Itimerspec(ctypes.Structure):
    _fields_ = (("it_interval", _Timespec), ("it_value", _Timespec))


class _Libc:
    """timerfd_create and timerfd_settime from the C library (glibc, musl)."""

    def __init__(self) -> None:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        self.create = libc.timerfd_create  # AttributeError where there is none
        self.create.argtypes = (ctypes.c_int, ctypes.c_int)
        self.create.restype = ctypes.c_int
        # Called once per message: without argtypes, whose conversions took 2.2 us of the
        # call's 2.9 on the test machine. Every argument is one ctypes passes as it is:
        # the descriptor and the flags (Python ints: C int), a byref() of the
        # itimerspec and None (NULL) for the old value.
        self.settime = libc["timerfd_settime"]  # a function object of its own
        self.settime.restype = ctypes.c_int


PR_SET_TIMERSLACK: Final = 29  # prctl(2)
TIMER_SLACK: Final = 1000  # ns: the slack of the loop thread's sleeps (see precise_sleeps)


def precise_sleeps() -> None:
    """Give the calling thread (the loop's) a timer slack of 1 us instead of 50 us.

    prctl(2) PR_SET_TIMERSLACK: the kernel may end a sleep of this thread (select, epoll,
    nanosleep: not a timerfd, whose expiry is exact) up to its timer slack late, 50 us by
    default, to group wake-ups. The stream driver sleeps idle times under its
    ``SLEEP_LIMIT`` in a select holding the loop (500 kbit/s TSYN: 66 us); with the default
    slack that hold was 128 us at the median on the shared test machine, 78 us with 1 us.
    Nothing where prctl is missing (not Linux): those sleeps are as late as they were."""
    try:
        prctl = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True).prctl
    except (OSError, AttributeError):
        return
    prctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong)
    prctl.restype = ctypes.c_int
    if prctl(PR_SET_TIMERSLACK, TIMER_SLACK, 0, 0, 0) < 0:
        log.debug("no timer slack set: %s", os.strerror(ctypes.get_errno()))


_libc: _Libc | None = None
_no_timerfd: str | None = None  # why timerfds are not used here (found out once)


def _get_libc() -> _Libc:
    global _libc
    if _libc is None:
        _libc = _Libc()
    return _libc


class TimerFd:
    """A timerfd on the loop (see the module docstring)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, callback: Callable[[], None]) -> None:
        self._libc = libc = _get_libc()
        fd = libc.create(time.CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
        if fd < 0:
            err = ctypes.get_errno()
            raise OSError(err, f"timerfd_create: {os.strerror(err)}")
        self._fd = fd
        self._loop = loop
        self._callback = callback
        self._spec = _Itimerspec()
        self._value = self._spec.it_value  # a view into _spec: set in place
        self._ref = ctypes.byref(self._spec)
        self._settime_c = libc.settime
        self._at: float | None = None
        try:
            loop.add_reader(fd, self._fired)
        except BaseException:
            os.close(fd)
            raise

    @property
    def at(self) -> float | None:
        return self._at

    def set(self, when: float) -> None:
        if self._fd < 0:
            return  # closed
        ns = max(math.ceil(when * NS), 1)  # rounded up: never before `when`; 0 would disarm
        value = self._value
        value.tv_sec, value.tv_nsec = divmod(ns, NS)
        if self._settime_c(self._fd, TFD_TIMER_ABSTIME, self._ref, None) < 0:
            self._settime_failed()
        self._at = when

    def cancel(self) -> None:
        if self._at is None or self._fd < 0:
            return
        self._value.tv_sec = self._value.tv_nsec = 0  # an all-zero value disarms
        self._settime()
        self._at = None

    def close(self) -> None:
        if self._fd < 0:
            return
        self._at = None
        self._loop.remove_reader(self._fd)
        os.close(self._fd)
        self._fd = -1

    def _settime(self) -> None:
        if self._settime_c(self._fd, TFD_TIMER_ABSTIME, self._ref, None) < 0:
            self._settime_failed()

    @staticmethod
    def _settime_failed() -> None:
        err = ctypes.get_errno()
        raise OSError(err, f"timerfd_settime: {os.strerror(err)}")

    def _fired(self) -> None:
        try:
            os.read(self._fd, 8)  # the expiration count: clears the readiness
        except (BlockingIOError, InterruptedError):
            return  # re-armed or cancelled after it expired: not this time
        self._at = None
        self._callback()


class CallAtTimer:
    """The fallback: ``loop.call_at`` (up to a millisecond late, never early)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, callback: Callable[[], None]) -> None:
        self._loop = loop
        self._callback = callback
        self._handle: asyncio.TimerHandle | None = None
        self._at: float | None = None

    @property
    def at(self) -> float | None:
        return self._at

    def set(self, when: float) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._at = when
        self._handle = self._loop.call_at(when, self._fired)

    def cancel(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._handle = None
        self._at = None

    def close(self) -> None:
        self.cancel()

    def _fired(self) -> None:
        self._handle = None
        self._at = None
        self._callback()


def loop_timer(loop: asyncio.AbstractEventLoop, callback: Callable[[], None]) -> LoopTimer:
    """A :class:`TimerFd` on ``loop``, else (no timerfd here) a :class:`CallAtTimer`."""
    global _no_timerfd
    if _no_timerfd is None:
        try:
            return TimerFd(loop, callback)
        except (OSError, AttributeError, NotImplementedError) as exc:
            # NotImplementedError: a loop without add_reader (Windows' proactor)
            _no_timerfd = str(exc) or type(exc).__name__
            log.warning("no timerfd (%s): waits use the loop's timers (up to 1 ms late)", exc)
    return CallAtTimer(loop, callback)


def loop_clock(loop: asyncio.AbstractEventLoop) -> Callable[[], float]:
    """``loop.time`` as a callable read several times per message: ``time.monotonic``
    itself when the loop's clock is asyncio's own (one Python frame less per read), the
    loop's method when a loop has a clock of its own (a test's)."""
    if getattr(type(loop), "time", None) is asyncio.BaseEventLoop.time:
        return time.monotonic
    return loop.time


class _NeverReady:
    """No callback is ever seen waiting (a loop without asyncio's ready queue)."""

    def __bool__(self) -> bool:
        return False


def loop_ready(loop: asyncio.AbstractEventLoop) -> Sized | _NeverReady:
    """Something true while callbacks wait to run in ``loop`` (those given to
    ``call_soon`` and ``call_soon_threadsafe``, a timer's once it is due): asyncio's own
    queue of them, read without a call, so a driver that keeps the loop for a while can
    see at once that something else wants it. A loop without that queue (not asyncio's
    own) gives something never true: the driver keeps the loop only as long as its own
    bound. ``tests/link/test_stream_burst.py`` checks the queue is where this looks."""
    ready = getattr(loop, "_ready", None)  # asyncio.BaseEventLoop's deque of handles
    if isinstance(ready, collections.deque):
        return ready
    return _NeverReady()


def loop_wake(loop: asyncio.AbstractEventLoop) -> int:
    """The descriptor that becomes readable when a callback is handed to ``loop`` from
    another thread (``call_soon_threadsafe`` writes to it): the read end of asyncio's
    self-pipe; -1 for a loop without one. A steady ring waits on it beside the port, so a
    command ends the ring before its next request (``tests/link/test_ring.py`` checks
    it is where this looks)."""
    ssock = getattr(loop, "_ssock", None)  # asyncio.BaseSelectorEventLoop's self-pipe
    fileno = getattr(ssock, "fileno", None)
    if fileno is None:
        return -1
    fd = fileno()
    return fd if isinstance(fd, int) else -1


def loop_next_timer(loop: asyncio.AbstractEventLoop) -> float:
    """When the earliest of ``loop``'s timers (``call_at``, ``call_later``) is due, in the
    loop's time (inf: none, or a loop that does not say): a driver that keeps the loop
    stops before it."""
    scheduled = getattr(loop, "_scheduled", None)  # asyncio.BaseEventLoop's heap
    if isinstance(scheduled, list) and scheduled:
        when = getattr(scheduled[0], "when", None)
        if when is not None:
            value = when()
            if isinstance(value, float):
                return value
    return math.inf
