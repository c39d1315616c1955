"""The demo's Profibus line: the WEG and MCD 600 profiles on their own simulators.

A contract check between the master and the device packages (adapters/profibus/weg,
adapters/mcd600).
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

from adapters.profibus.adapter import ProfibusAdapter
from gateway.config import parse
from gateway.model import CommState
from gateway.runtime.daemon import build_hub
from tests.support import simulated

DRIVES: list[dict[str, Any]] = [
    {"id": "cfw11", "device": "CFW-11", "address": 3, "data_profile": "profidrive", "frame": 20},
    {"id": "cfw700", "device": "CFW700", "address": 4, "words": 4, "words_in": [3, 49]},
    {"id": "cfw320", "device": "CFW320", "address": 5},
    {"id": "mcd600", "device": "MCD 600", "address": 6, "mode": "extended"},
]


async def test_every_device_of_the_demo_line_comes_online_and_leaves_with_clear() -> None:
    table = {"adapter": "profibus", "simulate": True, "latency": 0.02, "drives": DRIVES}
    config = parse({"buses": {"profibus": table}}, "demo-line.toml")
    hub = build_hub(config)
    adapter = simulated.profibus(ProfibusAdapter, config.buses[0])
    hub.attach_params([d["id"] for d in DRIVES], adapter)
    task = asyncio.create_task(adapter.run(hub))
    try:
        async with asyncio.timeout(10):
            for d in DRIVES:
                await hub.wait_for(d["id"], lambda s: s.comm is CommState.ONLINE)
        diag = adapter.diagnostics()
        assert all(v["configured"] for v in diag["drives"].values())
        assert await hub.read_param("cfw700", 100) >= 0  # DP-V1 record 47 on the WEG sim
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    line = simulated.sim_line(adapter)
    assert line is not None
    assert all(line[a].counters.clears >= 1 for a in (3, 4, 5, 6))
