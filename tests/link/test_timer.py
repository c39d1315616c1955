"""The precise loop timer: fires once, never before its time, at the time last set."""

from __future__ import annotations

import asyncio
import ctypes
import sys
import threading
from collections.abc import Callable

import pytest

from adapters.link import timer as timer_module
from adapters.link.timer import CallAtTimer, LoopTimer, TimerFd, loop_timer
from tests.support.timing import scaled

Factory = Callable[[asyncio.AbstractEventLoop, Callable[[], None]], LoopTimer]
KINDS: list[Factory] = [TimerFd, CallAtTimer]


@pytest.mark.parametrize("kind", KINDS)
async def test_a_timer_fires_once_never_before_its_time(kind: Factory) -> None:
    loop = asyncio.get_running_loop()
    fired: list[float] = []
    done = asyncio.Event()

    def callback() -> None:
        fired.append(loop.time())
        done.set()

    timer = kind(loop, callback)
    try:
        when = loop.time() + 0.0003  # a TSYN-sized wait
        timer.set(when)
        assert timer.at == when
        await asyncio.wait_for(done.wait(), scaled(5))
        assert fired[0] >= when and timer.at is None
        done.clear()
        timer.set(loop.time() + 0.001)
        await asyncio.wait_for(done.wait(), scaled(5))
        assert len(fired) == 2
    finally:
        timer.close()


@pytest.mark.parametrize("kind", KINDS)
async def test_only_the_time_last_set_fires_and_cancel_stops_it(kind: Factory) -> None:
    loop = asyncio.get_running_loop()
    fired: list[str] = []
    other = asyncio.Event()

    def on_second() -> None:
        fired.append("second")
        other.set()

    first = kind(loop, lambda: fired.append("first"))
    second = kind(loop, on_second)
    try:
        first.set(loop.time() + 0.0002)
        first.set(loop.time() + 0.002)  # moved later: fires once, at the later time
        cancelled = kind(loop, lambda: fired.append("cancelled"))
        cancelled.set(loop.time() + 0.0001)
        cancelled.cancel()
        assert cancelled.at is None
        second.set(loop.time() + 0.01)
        await asyncio.wait_for(other.wait(), scaled(5))
        assert fired == ["first", "second"]
        cancelled.close()
    finally:
        first.close()
        second.close()


async def test_a_timer_that_expired_and_was_set_again_waits_for_the_new_time() -> None:
    """Expired, not yet read by the loop, set later: the expiry is dropped (EAGAIN)."""
    loop = asyncio.get_running_loop()
    fired: list[float] = []
    done = asyncio.Event()

    def callback() -> None:
        fired.append(loop.time())
        done.set()

    timer = TimerFd(loop, callback)
    try:
        timer.set(loop.time())  # due at once; the loop has not run yet
        later = loop.time() + 0.005
        timer.set(later)
        await asyncio.wait_for(done.wait(), scaled(5))
        assert len(fired) == 1 and fired[0] >= later
    finally:
        timer.close()


async def test_without_timerfd_the_loops_timers_are_used(monkeypatch: pytest.MonkeyPatch) -> None:
    loop = asyncio.get_running_loop()

    def no_timerfd() -> None:
        raise AttributeError("timerfd_create")

    monkeypatch.setattr(timer_module, "_get_libc", no_timerfd)
    monkeypatch.setattr(timer_module, "_no_timerfd", None)
    timer = loop_timer(loop, lambda: None)
    assert isinstance(timer, CallAtTimer)
    assert timer_module._no_timerfd == "timerfd_create"
    timer.close()


async def test_a_closed_timer_ignores_set() -> None:
    loop = asyncio.get_running_loop()
    timer = TimerFd(loop, lambda: None)
    timer.close()
    timer.set(loop.time())  # a step after the driver stopped: nothing happens, no error
    assert timer.at is None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(2) is Linux's")
def test_precise_sleeps_sets_the_calling_threads_timer_slack() -> None:
    """prctl(2) PR_GET_TIMERSLACK in a thread of its own (the test process keeps its own)."""
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    prctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong)
    got: list[int] = []

    def work() -> None:
        prctl(timer_module.PR_SET_TIMERSLACK, 50_000, 0, 0, 0)  # the kernel's default
        got.append(prctl(30, 0, 0, 0, 0))  # PR_GET_TIMERSLACK
        timer_module.precise_sleeps()
        got.append(prctl(30, 0, 0, 0, 0))

    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    assert got == [50_000, timer_module.TIMER_SLACK]
