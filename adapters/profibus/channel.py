"""DP-V1 record access for the profiles: the :class:`RecordChannel` of one slave, over the
record jobs the adapter has the master run (MSAC_C1 read and write).

A job waits for its :class:`RecordDone` from the master; its outcome is the data read, or
the error the RecordChannel contract names (the profile's own texts for DP-V1 error codes
where it has them, a timeout, the slave offline). Cancelling the wait cancels the job.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Protocol

from adapters.profibus.contract import DpProfile, RecordAccessError
from adapters.profibus.driver import LineDriver
from adapters.profibus.master import Master, RecordDone, RecordFailure
from gateway.errors import DriveOffline, GatewayTimeout

Submit = Callable[[Master, float], int]
"""Submits one DP-V1 job to the master at a time; the job's number."""


class Slave(Protocol):
    """What a record job needs of a slave: its drive id, its address, whether it is in
    data exchange, and its profile (the texts of the DP-V1 error codes)."""

    @property
    def id(self) -> str: ...

    @property
    def address(self) -> int: ...

    @property
    def up(self) -> bool: ...

    @property
    def profile(self) -> DpProfile: ...


class RecordJobs:
    """The DP-V1 jobs the master runs for the adapter, each awaited until its RecordDone.

    ``driver``: the line's driver now (None while the port is closed: no job then).
    """

    def __init__(self, master: Master, driver: Callable[[], LineDriver | None]) -> None:
        self.master = master
        self._driver = driver
        self._futures: dict[int, asyncio.Future[RecordDone]] = {}

    async def run(self, slave: Slave, submit: Submit) -> bytes:
        """Submit a job for ``slave`` and wait for its outcome."""
        loop = asyncio.get_running_loop()
        driver = self._driver()
        if driver is None or not slave.up:
            raise DriveOffline(f"drive {slave.id} is not in data exchange")
        future: asyncio.Future[RecordDone] = loop.create_future()
        job = submit(self.master, loop.time())
        self._futures[job] = future
        driver.poke()
        try:
            done = await future
        except asyncio.CancelledError:
            self.master.cancel_record(job)
            raise
        finally:
            self._futures.pop(job, None)
        return record_result(slave, done)

    def done(self, action: RecordDone) -> None:
        """The master finished a job: its waiter gets the outcome."""
        future = self._futures.pop(action.job, None)
        if future is not None and not future.done():
            future.set_result(action)

    def cancel(self) -> None:
        """The adapter leaves the line: every waiter is cancelled."""
        for future in self._futures.values():
            if not future.done():
                future.cancel()


class Channel:
    """DP-V1 MSAC_C1 access to one slave (the profiles' RecordChannel)."""

    def __init__(self, jobs: RecordJobs, slave: Slave) -> None:
        self._jobs = jobs
        self._slave = slave

    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        address = self._slave.address
        return await self._jobs.run(
            self._slave, lambda m, now: m.read_record(address, slot, index, length, now)
        )

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        address = self._slave.address
        await self._jobs.run(
            self._slave, lambda m, now: m.write_record(address, slot, index, data, now)
        )


def record_result(slave: Slave, done: RecordDone) -> bytes:
    """The data of a finished DP-V1 job, or the error the RecordChannel contract names."""
    if done.error is not None:
        table = slave.profile.record_error_texts
        text = done.error.text_in(table) if table else done.error.text
        raise RecordAccessError(
            text, done.error.error_code_1, done.error.error_code_2, done.error.error_decode
        )
    if done.failure is RecordFailure.TIMEOUT:
        raise GatewayTimeout(done.text)
    if done.failure in (RecordFailure.OFFLINE, RecordFailure.CANCELLED):
        raise DriveOffline(done.text)
    if done.failure is not None:
        raise RecordAccessError(done.text, 0, 0, 0)
    return done.data or b""
