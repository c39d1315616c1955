"""Heartbeats due within a tenth of the period go out together (no wake-up per drive)."""

from __future__ import annotations

import asyncio
import contextlib
from types import SimpleNamespace
from typing import Any

from gateway.zenoh.frontend import DIAG_BATCH, HEARTBEAT_BATCH, ZenohFrontEnd

PERIOD = 1.0
DRIVES = 20


def fake_front_end(clock: list[float]) -> Any:
    """What ``_heartbeat`` reads of its front end, on a clock the test moves."""
    fe: Any = SimpleNamespace(
        section=SimpleNamespace(heartbeat=PERIOD),
        _now=lambda: clock[0],
        _drive_ids=[f"d{i}" for i in range(DRIVES)],
        _changed_at={},
        # the drives' last puts spread over a fifth of a period
        _confirmed_at={f"d{i}": i * 0.01 for i in range(DRIVES)},
        _wake=asyncio.Event(),
        _send_diag=lambda drive_id, wall: None,
        confirmed=[],
    )
    fe._due = lambda *args: ZenohFrontEnd._due(fe, *args)

    def confirm(drive_id: str, now: float) -> None:
        fe.confirmed.append((now, drive_id))
        fe._confirmed_at[drive_id] = now

    fe._confirm = confirm
    return fe


async def passes_at(fe: Any, clock: list[float], now: float) -> None:
    clock[0] = now
    fe._wake.set()
    for _ in range(5):
        await asyncio.sleep(0)


async def test_heartbeats_due_soon_go_with_the_one_due_now() -> None:
    clock = [0.5]
    fe = fake_front_end(clock)
    task = asyncio.create_task(ZenohFrontEnd._heartbeat(fe))
    try:
        await passes_at(fe, clock, 0.5)
        assert fe.confirmed == []  # nobody's heartbeat is near
        await passes_at(fe, clock, PERIOD)  # d0's is due: those due within 0.1 s come along
        batch = {d for _, d in fe.confirmed}
        assert batch == {f"d{i}" for i in range(DRIVES) if i * 0.01 <= HEARTBEAT_BATCH * PERIOD}
        fe.confirmed.clear()
        await passes_at(fe, clock, PERIOD + 0.11)  # d11's is due: the rest, together
        assert {d for _, d in fe.confirmed} == {f"d{i}" for i in range(11, DRIVES)}
        fe.confirmed.clear()
        await passes_at(fe, clock, 2 * PERIOD)  # two groups now, a wake-up for each
        assert {d for _, d in fe.confirmed} == {f"d{i}" for i in range(11)}
        await passes_at(fe, clock, 2 * PERIOD + 0.11)
        assert len(fe.confirmed) == DRIVES
        await passes_at(fe, clock, 2 * PERIOD + 0.5)
        assert len(fe.confirmed) == DRIVES  # never twice within the period's 0.9
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_diagnostics_of_many_drives_let_the_loop_run_between_batches() -> None:
    clock = [0.0]
    fe = fake_front_end(clock)
    fe._drive_ids = [f"d{i}" for i in range(5 * DIAG_BATCH)]
    sent: list[str] = []
    fe._send_diag = lambda drive_id, wall: sent.append(drive_id)
    seen: list[int] = []

    async def probe() -> None:
        while len(sent) < len(fe._drive_ids):
            seen.append(len(sent))
            await asyncio.sleep(0)

    prober = asyncio.create_task(probe())
    task = asyncio.create_task(ZenohFrontEnd._heartbeat(fe))
    try:
        await asyncio.wait_for(prober, 5.0)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    assert sent == fe._drive_ids  # every drive's diagnostics, once, in order
    # other tasks ran while the pass was under way, a batch apart
    assert {n for n in seen if 0 < n < len(sent)} == {DIAG_BATCH * k for k in range(1, 5)}
