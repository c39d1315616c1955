"""The steady ring on a line as the daemon runs it (docs/decisions/0103): with the slaves
answering apart from the line's loop, the steady exchanges go round in rings, compiled or
in Python; a run and a stop from the hub still go out with the slave's next exchanges; a
callback handed to the line's loop from another thread ends a ring; ``off`` runs none."""

from __future__ import annotations

import asyncio
import errno
import logging
import os

import pytest

from adapters.link import ring
from tests.profibus.integration.test_steady_burst import (
    LIMIT,
    _exchanges,
    commands_go_out_at_once,
    line_apart,
)
from tests.support.timing import scaled


@pytest.mark.parametrize("mode", ["compiled", "python"])
async def test_steady_exchanges_go_round_in_rings_and_commands_end_them(
    mode: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    if mode == "python":
        monkeypatch.setenv("DRIVE_GATEWAY_RING", "python")
    else:
        monkeypatch.delenv("DRIVE_GATEWAY_RING", raising=False)
        if ring._native is None:
            pytest.skip("the compiled ring is not built here (tests/link/test_ring.py)")
    assert ring.compiled() is (mode == "compiled")
    async with line_apart() as (hub, adapter, sim, line), asyncio.timeout(scaled(LIMIT)):
        for drive in ("a", "b"):
            await hub.wait_for(drive, lambda s: s.online)
        await _exchanges(sim, 3, 200)
        driver = adapter._driver
        assert driver is not None
        assert driver.rings > 0 and driver.ring_taken > driver.rings  # more than one each
        await commands_go_out_at_once(hub, sim)
        # a callback handed to the line's loop from another thread while a ring runs
        # ends it (the loop's self-pipe is the ring's wake descriptor), and the line
        # goes on
        for _ in range(500):
            if driver.rings_woken:
                break
            await line.call(lambda: None)
        assert driver.rings_woken > 0
        await _exchanges(sim, 3, 50)
        assert adapter.master.line_diagnostics()["timeouts"] == 0


async def test_no_rings_when_turned_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DRIVE_GATEWAY_RING", "off")
    async with line_apart() as (hub, adapter, sim, _line), asyncio.timeout(scaled(LIMIT)):
        for drive in ("a", "b"):
            await hub.wait_for(drive, lambda s: s.online)
        await _exchanges(sim, 3, 100)
        driver = adapter._driver
        assert driver is not None
        assert driver.rings == 0 and driver.burst_taken > 0


async def test_a_ring_priority_not_permitted_is_said_once_and_the_line_goes_on(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """ring_priority (decision 0104) where the process may not use SCHED_FIFO (the rings in
    Python here, whose scheduler call a test can refuse)."""

    def refuse(pid: int, policy: int, param: os.sched_param) -> None:
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setenv("DRIVE_GATEWAY_RING", "python")
    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with caplog.at_level(logging.WARNING, logger="adapters.link.stream"):
        async with (
            line_apart(ring_priority=10) as (hub, adapter, sim, _line),
            asyncio.timeout(scaled(LIMIT)),
        ):
            for drive in ("a", "b"):
                await hub.wait_for(drive, lambda s: s.online)
            await _exchanges(sim, 3, 200)
            driver = adapter._driver
            assert driver is not None
            assert driver.rings > 1
    said = [r.getMessage() for r in caplog.records if "SCHED_FIFO" in r.getMessage()]
    assert len(said) == 1
    assert said[0].endswith(
        "steady rings at ordinary priority: SCHED_FIFO 10 not permitted (Operation not "
        "permitted); allow it with LimitRTPRIO=10 in the unit (docs/operations.md) or set "
        "ring_priority = 0"
    )
