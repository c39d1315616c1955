"""The front end's heartbeat loop ends when cancelled, even as its wake-up fires.

On Python 3.11 ``asyncio.wait_for`` returns the inner result instead of raising when the
cancellation and the inner completion land in the same loop iteration; the shutdown then
waited on a heartbeat that never ended (and the Zenoh session was never closed).
"""

from __future__ import annotations

import asyncio
import contextlib
from types import SimpleNamespace
from typing import Any

from gateway.zenoh.frontend import ZenohFrontEnd


def fake_front_end() -> Any:
    """What ``_heartbeat`` reads of its front end: no drives, a long heartbeat."""
    loop = asyncio.get_running_loop()
    return SimpleNamespace(
        section=SimpleNamespace(heartbeat=60.0),
        _now=loop.time,
        _drive_ids=(),
        _changed_at={},
        _confirmed_at={},
        _wake=asyncio.Event(),
    )


async def test_a_cancel_that_meets_the_wake_up_ends_the_heartbeat() -> None:
    fe = fake_front_end()
    task = asyncio.create_task(ZenohFrontEnd._heartbeat(fe))
    for _ in range(3):
        await asyncio.sleep(0)  # the loop is waiting for its wake-up now
    fe._wake.set()  # the wake-up and the cancellation in the same loop iteration
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await asyncio.wait_for(asyncio.shield(task), 2.0)
    assert task.cancelled()
