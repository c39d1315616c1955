"""The MCD 600 parameter sequencer, stepped with a fake clock (issue 21).

The sequencer decides what output bytes 3-6 carry each cycle and when a request has waited
too long; these tests step it cycle by cycle with a number for the clock: its timeout is
reached by advancing that number, with no event loop and no real waiting. The last test
runs the async wrapper on an injected clock with no bus at all: a real-clock channel would
wait its whole timeout (an hour) there.
"""

from __future__ import annotations

import asyncio

import pytest

from adapters.mcd600.params import ParamChannel, ParamDone, ParamLost, ParamSequencer
from adapters.mcd600.programming import IDLE, ParamReply, ParamRequest
from gateway.errors import DriveOffline, GatewayTimeout, ParameterError
from tests.support.timing import scaled

READ_6 = ParamRequest(6, read=True)  # guide 4.4.1 table 7: parameter 6, read
READ_7 = ParamRequest(7, read=True)


def test_a_request_waits_for_a_clear_echo_then_goes_out_until_it_is_echoed() -> None:
    seq = ParamSequencer(timeout=2.0)
    job = seq.submit(READ_6, 0.0)
    assert seq.output() == IDLE  # the echo may still be 6 from an earlier request
    assert seq.step(0.05, ParamReply(echo=6, value=1)) == []  # an old echo: not taken
    assert seq.output() == IDLE
    assert seq.step(0.10, ParamReply(echo=0)) == []  # cleared
    assert seq.output() == READ_6
    assert seq.step(0.15, ParamReply(echo=0)) == []  # not answered yet
    assert seq.step(0.20, ParamReply(echo=6, value=350)) == [ParamDone(job, 350)]
    assert not seq.busy and seq.output() == IDLE


def test_the_timeout_is_reached_by_advancing_the_clock() -> None:
    seq = ParamSequencer(timeout=2.0, name="MCD 600 ss1")
    job = seq.submit(READ_6, 10.0)
    assert seq.next_deadline() == pytest.approx(12.0)
    now = 10.0
    while now < 11.9:  # cycles go on, the starter never echoes
        now += 0.1
        assert seq.step(now, ParamReply(echo=0)) == []
        seq.output()
    [done] = seq.step(12.0)  # the deadline passes: a step without a cycle is enough
    assert done.job == job and isinstance(done.error, GatewayTimeout)
    assert str(done.error) == "MCD 600 ss1: no answer to parameter 6 in 2 s"
    assert not seq.busy and seq.next_deadline() is None and seq.output() == IDLE


def test_requests_run_one_after_the_other_each_with_its_own_time() -> None:
    seq = ParamSequencer(timeout=1.0)
    first = seq.submit(READ_6, 0.0)
    second = seq.submit(READ_7, 0.5)
    assert seq.next_deadline() == pytest.approx(1.0)  # the first is on the bus
    seq.step(0.6, ParamReply(echo=0))
    assert seq.output() == READ_6
    assert seq.step(0.8, ParamReply(echo=6, value=350)) == [ParamDone(first, 350)]
    # the second begins when the first ended: its second counts from there
    assert seq.next_deadline() == pytest.approx(1.8)
    assert seq.step(1.7) == []
    [done] = seq.step(1.8)
    assert done.job == second and isinstance(done.error, GatewayTimeout)


def test_a_refusal_ends_the_request_with_the_starters_text() -> None:
    seq = ParamSequencer(timeout=1.0)
    job = seq.submit(ParamRequest(200, read=True), 0.0)
    seq.step(0.1, ParamReply(echo=0))
    seq.output()
    [done] = seq.step(0.2, ParamReply(echo=200, invalid_number=True))
    assert done.job == job and isinstance(done.error, ParameterError)
    assert (done.error.code, done.error.text) == (1, "parameter 200: invalid parameter number")


def test_lost_communication_ends_the_request_in_progress_only() -> None:
    seq = ParamSequencer(timeout=1.0)
    first = seq.submit(READ_6, 0.0)
    second = seq.submit(READ_7, 0.0)
    lost = DriveOffline("communication lost")
    assert seq.step(0.3, ParamLost(lost)) == [ParamDone(first, error=lost)]
    assert seq.next_deadline() == pytest.approx(1.3)  # the second begins, with its time
    seq.cancel(second, 0.4)
    assert not seq.busy and seq.step(5.0) == []


def test_a_cancelled_request_gives_the_bus_to_the_next() -> None:
    seq = ParamSequencer(timeout=1.0)
    first = seq.submit(READ_6, 0.0)
    seq.submit(READ_7, 0.0)
    seq.step(0.1, ParamReply(echo=0))
    assert seq.output() == READ_6
    seq.cancel(first, 0.2)
    assert seq.next_deadline() == pytest.approx(1.2)
    assert seq.output() == IDLE  # the next waits for its clear echo first


class Ticking:
    """A fake clock that moves ``tick`` seconds each time it is read."""

    def __init__(self, tick: float) -> None:
        self.now = 0.0
        self.tick = tick

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


async def test_the_channel_times_out_on_its_injected_clock() -> None:
    clock = Ticking(3600.0)  # each look at the clock: an hour later
    channel = ParamChannel(timeout=3600.0, name="MCD 600 ss1", clock=clock)
    async with asyncio.timeout(scaled(5.0)):
        with pytest.raises(GatewayTimeout, match="no answer to parameter 6 in 3600 s"):
            await channel.transact(READ_6)  # no bus cycles: only the clock moves
    assert clock.now >= 2 * 3600.0
    assert not channel.busy and channel.output() == IDLE


async def test_a_cancelled_transaction_leaves_the_channel_free() -> None:
    channel = ParamChannel(timeout=60.0)
    task = asyncio.create_task(channel.transact(READ_6))
    await asyncio.sleep(0)
    assert channel.busy
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert not channel.busy and channel.output() == IDLE
