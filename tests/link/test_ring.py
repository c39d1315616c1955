"""The steady ring (adapters/link/ring.py, docs/decisions/0103): the compiled ring and its
Python fallback run the same plans against the same far end on a real descriptor (a
socket pair, a thread answering as a slave would) and stop at the same things."""

from __future__ import annotations

import asyncio
import errno
import math
import os
import select
import shutil
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

import pytest

from adapters.link import ring
from adapters.link.ringplan import RingPlan, RingResult, RingStop
from adapters.link.timer import loop_next_timer, loop_wake
from tests.support.timing import scaled

TSYN = 0.0002
WAIT = 0.05  # s a reply is awaited (scaled)
REQUESTS = [bytes([0x68, 5, 5, 0x68, n, 2, 0x7D, 0, 0, 0x16]) for n in range(3, 9)]
REPLIES = [bytes([0x68, 5, 5, 0x68, 2, n, 0x08, 1, 2, 0x16]) for n in range(3, 9)]

Answer = Callable[[socket.socket, int], None]  # the far end's answer to request i


def _reply(sock: socket.socket, i: int) -> None:
    sock.sendall(REPLIES[i])


class Runner(Protocol):
    def __call__(self, fd: int, wake: int, plan: RingPlan, priority: int = 0) -> RingResult: ...


def _compiled() -> Runner:
    if ring._native is None:
        # where a C compiler is, the install builds it: not built there is a fault
        assert shutil.which("cc") is None, "adapters/link/_ring.c was not built"
        pytest.skip("no C compiler: the compiled ring is not built here")
    return ring.run


@pytest.fixture(params=["compiled", "python"])
def runner(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Runner:
    monkeypatch.delenv("DRIVE_GATEWAY_RING", raising=False)
    return _compiled() if request.param == "compiled" else ring.run_python


@contextmanager
def far_end(answers: list[Answer | None]) -> Iterator[tuple[int, list[bytes]]]:
    """Our end's descriptor (non-blocking) and the requests the far end read. Reply 0 is
    sent at once (its request is on the line); after request i, ``answers[i]`` (None: no
    answer, the far end stops)."""
    ours, theirs = socket.socketpair()
    ours.setblocking(False)
    heard: list[bytes] = []

    def serve() -> None:
        theirs.settimeout(scaled(5.0))
        try:
            if answers[0] is None:
                return
            answers[0](theirs, 0)
            for i in range(1, len(answers)):
                heard.append(theirs.recv(64))
                answer = answers[i]
                if answer is None:
                    return
                answer(theirs, i)
        except OSError:
            return

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield ours.fileno(), heard
    finally:
        thread.join(scaled(10.0))
        ours.close()
        theirs.close()


def _plan(n: int, **changes: object) -> RingPlan:
    now = time.monotonic()
    values: dict[str, object] = {
        "deadline": now + scaled(WAIT),
        "expected": tuple(REPLIES[:n]),
        "requests": tuple(REQUESTS[1:n]),
        "tsyn": TSYN,
        "reply_wait": scaled(WAIT),
        "t_char": 11 / 1.5e6,
        "idle_since": now,
        "busy_until": now,
        "horizon": now + 60.0,
    }
    values.update(changes)
    return RingPlan(**values)  # type: ignore[arg-type]


def test_a_steady_line_goes_round_to_the_end(runner: Runner) -> None:
    with far_end([_reply] * 5) as (fd, heard):
        result = runner(fd, -1, _plan(5))
    assert result.stop is RingStop.END
    assert (result.taken, result.written) == (5, 4)
    assert heard == REQUESTS[1:5]  # each request once, in order
    assert list(result.times) == sorted(result.times)
    for j in range(4):  # each request after its reply and TSYN
        assert result.times[2 * j + 1] - result.times[2 * j] >= TSYN
    assert (result.bytes_in, result.bytes_out) == (50, 40)
    assert result.rest == b""


def test_a_reply_other_than_expected_stops_the_ring_untaken(runner: Runner) -> None:
    def other(sock: socket.socket, i: int) -> None:
        sock.sendall(REPLIES[i][:-2] + b"\x09\x16")

    with far_end([_reply, _reply, other]) as (fd, _heard):
        result = runner(fd, -1, _plan(5))
    assert result.stop is RingStop.DIFFER
    assert (result.taken, result.written) == (2, 2)
    assert result.rest == REPLIES[2][:-2] + b"\x09\x16"
    assert result.rest_at >= result.times[-1]


def test_no_reply_stops_the_ring_at_its_deadline(runner: Runner) -> None:
    with far_end([_reply, None]) as (fd, _heard):
        result = runner(fd, -1, _plan(3))
        after = time.monotonic()
    assert result.stop is RingStop.TIMEOUT
    assert (result.taken, result.written) == (1, 1)
    written = result.times[1]
    assert after >= written + scaled(WAIT)  # never before the deadline


def test_a_reply_in_pieces_is_taken_whole(runner: Runner) -> None:
    def pieces(sock: socket.socket, i: int) -> None:
        sock.sendall(REPLIES[i][:3])
        time.sleep(0.002)
        sock.sendall(REPLIES[i][3:])

    with far_end([_reply, pieces, _reply]) as (fd, _heard):
        result = runner(fd, -1, _plan(3))
    assert result.stop is RingStop.END
    assert result.taken == 3


def test_no_request_goes_out_past_the_horizon(runner: Runner) -> None:
    with far_end([_reply]) as (fd, _heard):
        result = runner(fd, -1, _plan(3, horizon=time.monotonic()))
    assert result.stop is RingStop.HORIZON
    assert (result.taken, result.written) == (1, 0)
    assert result.bytes_out == 0


def test_bytes_in_an_idle_time_are_left_unread(runner: Runner) -> None:
    def with_noise(sock: socket.socket, i: int) -> None:
        sock.sendall(REPLIES[i])
        time.sleep(0.005)
        sock.sendall(b"\xff")

    with far_end([with_noise]) as (fd, _heard):
        result = runner(fd, -1, _plan(3, tsyn=scaled(1.0)))
        assert select.select([fd], [], [], scaled(5.0))[0]
        assert os.read(fd, 16) == b"\xff"  # still there for the loop's reader
    assert result.stop is RingStop.BYTES
    assert (result.taken, result.written) == (1, 0)


def test_the_wake_descriptor_stops_the_ring_before_it_reads(runner: Runner) -> None:
    r, w = os.pipe()
    try:
        os.write(w, b"x")
        with far_end([_reply]) as (fd, _heard):
            result = runner(fd, r, _plan(3))
            assert select.select([fd], [], [], scaled(5.0))[0]
            assert os.read(fd, 64) == REPLIES[0]  # not read: the loop's reader takes it
    finally:
        os.close(r)
        os.close(w)
    assert result.stop is RingStop.WAKE
    assert result.taken == 0


def test_a_far_end_gone_stops_the_ring(runner: Runner) -> None:
    ours, theirs = socket.socketpair()
    ours.setblocking(False)
    theirs.close()
    try:
        result = runner(ours.fileno(), -1, _plan(3))
    finally:
        ours.close()
    assert result.stop is RingStop.PORT
    assert result.taken == 0


def test_a_plan_of_the_wrong_shape_is_refused(runner: Runner) -> None:
    with pytest.raises(ValueError):
        runner(0, -1, _plan(3, requests=(REQUESTS[1],)))


def test_a_callback_handed_to_a_loop_from_another_thread_wakes_its_descriptor() -> None:
    """What a ring waits on beside the port: asyncio's self-pipe (private to asyncio:
    this fails if a Python version moves it), and the loop's earliest timer."""
    loop = asyncio.new_event_loop()
    try:
        wake = loop_wake(loop)
        assert wake >= 0
        woken = threading.Event()
        thread = threading.Thread(target=lambda: loop.call_soon_threadsafe(woken.set))
        thread.start()
        thread.join()
        r, _, _ = select.select([wake], [], [], scaled(5.0))
        assert r == [wake]
        assert loop_next_timer(loop) == float("inf")
        handle = loop.call_later(10.0, lambda: None)
        assert loop_next_timer(loop) == handle.when()
        handle.cancel()
    finally:
        loop.close()


def _fifo_permitted() -> bool:
    """Whether a thread of this process may use SCHED_FIFO (root, CAP_SYS_NICE or an
    RLIMIT_RTPRIO of 10 or more); the probe's thread ends with it."""
    permitted: list[bool] = []

    def probe() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        except OSError:
            permitted.append(False)
            return
        permitted.append(True)

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    return permitted[0]


def test_a_ring_runs_at_its_priority_and_gives_it_back(runner: Runner) -> None:
    """ring_priority (decision 0104): the ring's thread under SCHED_FIFO while the ring runs
    (seen by the far end), its own scheduling again after it."""
    if not _fifo_permitted():
        pytest.skip("this process may not use SCHED_FIFO (no CAP_SYS_NICE, RLIMIT_RTPRIO)")
    seen: list[int] = []
    ringing: list[int] = []
    after: list[int] = []

    def look(sock: socket.socket, i: int) -> None:
        seen.append(os.sched_getscheduler(ringing[0]))
        _reply(sock, i)

    results: list[RingResult] = []
    with far_end([_reply, look, look]) as (fd, _heard):

        def ring_thread() -> None:
            ringing.append(threading.get_native_id())
            results.append(runner(fd, -1, _plan(3), 10))
            after.append(os.sched_getscheduler(0))

        thread = threading.Thread(target=ring_thread)
        thread.start()
        thread.join(scaled(10.0))
    assert results[0].stop is RingStop.END and results[0].realtime == 1
    assert seen == [os.SCHED_FIFO, os.SCHED_FIFO]
    assert after == [os.SCHED_OTHER]


def test_a_ring_refused_its_priority_runs_all_the_same(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(pid: int, policy: int, param: os.sched_param) -> None:
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with far_end([_reply] * 3) as (fd, _heard):
        result = ring.run_python(fd, -1, _plan(3), 10)
    assert result.stop is RingStop.END and result.taken == 3
    assert result.realtime == -errno.EPERM


def test_a_broadcast_in_a_ring_is_answered_by_nobody(runner: Runner) -> None:
    """An exchange expecting no reply (a Global_Control): written, then the line is free
    TSYN after its end; the ring goes on."""
    broadcast = bytes([0x68, 5, 5, 0x68, 0x7F, 2, 0x73, 0, 0, 0x16])

    def silent(sock: socket.socket, i: int) -> None:
        return

    def second(sock: socket.socket, i: int) -> None:
        sock.sendall(REPLIES[1])

    # (an idle time the far end reads the broadcast in, apart from the request after it)
    plan = _plan(
        3,
        expected=(REPLIES[0], b"", REPLIES[1]),
        requests=(broadcast, REQUESTS[1]),
        tsyn=scaled(0.02),
    )
    with far_end([_reply, silent, second]) as (fd, heard):
        result = runner(fd, -1, plan)
    assert result.stop is RingStop.END and result.taken == 3
    assert heard == [broadcast, REQUESTS[1]]
    written, free, next_written = result.times[1], result.times[2], result.times[3]
    assert free == written + len(broadcast) * plan.t_char  # the broadcast's end
    assert next_written >= free + plan.tsyn


def test_a_broadcast_not_due_is_left_out_and_one_due_is_written(runner: Runner) -> None:
    """A Global_Control in the plan goes out only when, the line free for it, it is due
    (``gc_due``, then ``gc_period`` after each one written, docs/decisions/0110); one not
    due is left out (NaN for its two times) and the next request follows in its place."""
    broadcast = bytes([0x68, 5, 5, 0x68, 0x7F, 2, 0x73, 0, 0, 0x16])

    def silent(sock: socket.socket, i: int) -> None:
        return

    def reply(n: int) -> Answer:
        def answer(sock: socket.socket, i: int) -> None:
            sock.sendall(REPLIES[n])

        return answer

    # reply 0, [broadcast: due], reply 1, [broadcast: not due a period after], reply 2
    plan = _plan(
        5,
        expected=(REPLIES[0], b"", REPLIES[1], b"", REPLIES[2]),
        requests=(broadcast, REQUESTS[1], broadcast, REQUESTS[2]),
        gc_due=time.monotonic(),
        gc_period=60.0,
    )
    with far_end([_reply, silent, reply(1), reply(2)]) as (fd, heard):
        result = runner(fd, -1, plan)
    assert result.stop is RingStop.END and result.taken == 5 and result.left_out == 1
    assert heard == [broadcast, REQUESTS[1], REQUESTS[2]]
    times = result.times
    assert not any(map(math.isnan, times[:5])) and all(map(math.isnan, times[5:7]))
    assert times[7] >= times[4]  # the next request at once, no broadcast's line time before
