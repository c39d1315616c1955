"""The record 47/48 parameter sequence, stepped with a fake clock (issue 21).

The sequence decides every DS_Write and DS_Read, and waits between two DS_Reads by its
deadline: these tests step it through its retries and timeouts by advancing a number,
with no event loop and no real waiting. The last ones run the async wrapper with an
injected clock that a slow channel advances: a real-clock sequence would sleep for
minutes there.
"""

from __future__ import annotations

import asyncio

import pytest

from adapters.profibus.contract import RecordAccessError
from adapters.profibus.weg.records import (
    ParamSequence,
    ReadRecord,
    RecordParams,
    RecordRead,
    RecordRefused,
    RecordWritten,
    WriteRecord,
)
from gateway.errors import GatewayTimeout, ParameterError
from tests.profibus.weg.test_records import READ_P2_P3, READ_P2_P3_OK, WRITE_OK, WRITE_P100, b
from tests.support.timing import scaled

BUSY = RecordRefused(RecordAccessError("resource error", 0xC3))  # 4.2.3: not available yet
READ_47 = ReadRecord(0, 47, 240)


def deadline_of(seq: ParamSequence) -> float:
    deadline = seq.next_deadline()
    assert deadline is not None, "the sequence waits for nothing"
    return deadline


def test_a_read_waits_between_ds_reads_by_its_deadline() -> None:
    seq = RecordParams(retry_delay=0.5).reading([(2, 0), (3, 0)])
    assert seq.step(10.0) == WriteRecord(0, 47, READ_P2_P3)
    assert seq.step(10.01, RecordWritten()) == READ_47
    assert seq.step(10.02, BUSY) is None
    deadline = deadline_of(seq)
    assert deadline == pytest.approx(10.52)
    assert seq.step(10.5) is None  # not yet: nothing asked
    assert seq.step(deadline) == READ_47
    assert seq.next_deadline() is None  # a DS_Read is out: its answer steps it
    assert seq.step(10.53, RecordRead(READ_P2_P3_OK)) is None
    assert seq.done and seq.error is None and seq.values == [100, 50]


def test_the_retries_end_in_a_timeout_reached_by_the_fake_clock() -> None:
    seq = RecordParams(retries=2, retry_delay=1.0).reading([(2, 0)])
    now = 0.0
    assert isinstance(seq.step(now), WriteRecord)
    assert seq.step(now, RecordWritten()) == READ_47
    reads = 1
    while True:
        assert seq.step(now, BUSY) is None  # the drive has no answer yet
        deadline = deadline_of(seq)
        assert deadline == pytest.approx(now + 1.0)
        now = deadline  # the fake clock jumps to the deadline
        access = seq.step(now)
        if access is None:
            break
        assert access == READ_47
        reads += 1
    assert reads == 3  # the first DS_Read and its two retries
    assert now == pytest.approx(3.0)  # a retry_delay after each of the three
    assert seq.done and isinstance(seq.error, GatewayTimeout)
    assert str(seq.error) == "no answer to parameter request 1 in time"


def test_a_stale_answer_is_read_again_after_the_delay() -> None:
    seq = RecordParams(retry_delay=0.2).reading([(2, 0)])
    seq.step(0.0)
    seq.step(0.0, RecordWritten())
    stale = b(9, 1, 0, 1, 0x42, 1, 0, 7)  # another request's reference
    assert seq.step(0.1, RecordRead(stale)) is None
    deadline = deadline_of(seq)
    assert deadline == pytest.approx(0.3)
    assert seq.step(deadline) == READ_47
    assert seq.step(0.4, RecordRead(b(1, 1, 0, 1, 0x42, 1, 0, 8))) is None
    assert seq.values == [8]


def test_a_write_is_the_request_then_reads_until_the_answer() -> None:
    seq = RecordParams().writing(100, 85)
    assert seq.step(0.0) == WriteRecord(0, 47, WRITE_P100)
    assert seq.step(0.0, RecordWritten()) == READ_47
    assert seq.step(0.0, RecordRead(WRITE_OK)) is None
    assert seq.done and seq.error is None and seq.values == []


def test_a_refused_write_ends_the_sequence_with_the_drives_text() -> None:
    seq = RecordParams().writing(100, 85)
    seq.step(0.0)
    refused = RecordAccessError("whatever the master says", 0xB8)
    assert seq.step(0.0, RecordRefused(refused)) is None
    assert seq.done and isinstance(seq.error, ParameterError)
    assert seq.error.text == "access error - invalid parameter number"
    assert seq.error.__cause__ is refused
    assert seq.next_deadline() is None
    assert seq.step(100.0) is None  # done: stays done


def test_record_48_reads_one_parameter_after_the_other() -> None:
    seq = RecordParams(record=48, retry_delay=0.05).reading([(100, 0), (101, 1)])
    assert seq.step(0.0) == WriteRecord(0, 48, b(0, 100))
    assert seq.step(0.0, RecordWritten()) == ReadRecord(0, 48, 240)
    assert seq.step(0.0, BUSY) is None
    assert seq.step(0.05) == ReadRecord(0, 48, 240)
    # the second address has a subindex: refused when its turn comes, after the first
    assert seq.step(0.06, RecordRead(b(0, 85))) is None
    assert seq.done and seq.values == [85]
    assert isinstance(seq.error, ParameterError)
    assert "no subindex" in seq.error.text


def test_a_sequence_of_several_requests_takes_references_as_it_goes() -> None:
    params = RecordParams()
    addresses = [(n, 0) for n in range(1, 41)]  # 40: one request of 39, one of 1
    seq = params.reading(addresses)
    first = seq.step(0.0)
    assert isinstance(first, WriteRecord) and first.data[0] == 1
    assert params.next_reference() == 2  # the second request has not started yet


# --------------------------------------------------------------------------- the wrapper


class Busy:
    """A drive that never has the answer ready (4.2.3: Error_Code_1 C3h)."""

    def __init__(self) -> None:
        self.reads = 0

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        return

    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        self.reads += 1
        raise RecordAccessError("resource error", 0xC3)


class Ticking:
    """A fake clock that moves ``tick`` seconds each time it is read."""

    def __init__(self, tick: float) -> None:
        self.now = 0.0
        self.tick = tick

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


async def test_the_wrapper_waits_on_the_injected_clock() -> None:
    # 20 retries 60 s apart: 20 minutes on a real clock; the injected clock passes each
    # deadline by the time the wrapper looks again, so it never sleeps
    channel, clock = Busy(), Ticking(60.0)
    params = RecordParams(retries=20, retry_delay=60.0, clock=clock)
    async with asyncio.timeout(scaled(5.0)):
        with pytest.raises(GatewayTimeout, match="no answer to parameter request 1"):
            await params.read(channel, 2)
    assert channel.reads == 21
    assert clock.now >= 21 * 60.0


async def test_a_sequence_runs_on_any_channel() -> None:
    seq = RecordParams(retry_delay=0.0).reading([(2, 0)])
    assert isinstance(seq, ParamSequence)

    class Answering(Busy):
        async def read_record(self, slot: int, index: int, length: int) -> bytes:
            return b(1, 1, 0, 1, 0x42, 1, 0, 8)

    assert await RecordParams().run(Answering(), seq) == [8]
