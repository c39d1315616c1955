"""The MCD 600 profile on the Profibus DP master against its simulator on a simulated line
(pty pair, ``simulate = true``): what only the whole path shows (diagnosis reads, resets)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.mcd600.trips import MOTOR_OVERLOAD
from adapters.profibus.adapter import ProfibusAdapter
from gateway.adapter import EventKind
from gateway.config import parse
from gateway.hub import EventSubscription, Hub
from gateway.model import CommState, DriveCommand, DriveStatus, Source
from gateway.runtime.daemon import build_hub
from tests.support import simulated

ADDRESS = 6
WITHIN = 8.0


@dataclass
class Line:
    hub: Hub
    adapter: ProfibusAdapter
    events: EventSubscription

    @property
    def sim(self) -> Mcd600Sim:
        line = simulated.sim_line(self.adapter)
        assert line is not None
        device = line[ADDRESS].device
        assert isinstance(device, Mcd600Sim)
        return device

    async def event(self, kind: EventKind, text: str) -> Any:
        async with asyncio.timeout(WITHIN):
            while True:
                ev = await self.events.get()
                if ev.kind is kind and text in ev.text and "address" in ev.data:
                    return ev

    async def state(self, predicate: Any) -> Any:
        async with asyncio.timeout(WITHIN):
            return await self.hub.wait_for("ss", predicate)


@contextlib.asynccontextmanager
async def line(**drive: Any) -> AsyncIterator[Line]:
    table = {
        "adapter": "profibus",
        "simulate": True,
        "baudrate": 1500000,
        "cycle_time": 0.002,
        "live_list_period": 0.0,
        "drives": [{"id": "ss", "device": "MCD 600", "address": ADDRESS, **drive}],
    }
    config = parse({"buses": {"pb": table}}, "line.toml")
    hub = build_hub(config)
    adapter = simulated.profibus(ProfibusAdapter, config.buses[0])
    hub.attach_params(["ss"], adapter)
    task = asyncio.create_task(adapter.run(hub))
    try:
        with hub.subscribe_events() as events:
            async with asyncio.timeout(WITHIN):
                await hub.wait_for("ss", lambda s: s.comm is CommState.ONLINE)
            yield Line(hub, adapter, events)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_basic_mode_reports_the_same_trip_again_after_a_reset() -> None:
    """Basic mode has only the diagnosis telegram for the code (5.1.1); after a reset the
    telegram is cleared, so the same trip again is the same three bytes, and a new trip."""
    async with line(mode="basic", reset_pulse=0.02) as ln:
        for reset in (1, 2):
            ln.sim.trip(MOTOR_OVERLOAD)
            ev = await ln.event(EventKind.TRIP, "Motor overload")
            assert ev.data["code"] == MOTOR_OVERLOAD
            tripped = await ln.state(lambda s: s.fault_code == MOTOR_OVERLOAD)
            assert tripped.status is DriveStatus.TRIPPED and tripped.fault_text == "Motor overload"
            ln.hub.submit("ss", Source.ZENOH, DriveCommand(fault_reset=True))
            ready = await ln.state(lambda s: s.status is DriveStatus.READY)
            assert ready.fault_code is None and ln.sim.reset_edges == reset


async def test_the_simulated_starter_is_the_one_the_drive_table_describes() -> None:
    async with line(
        mode="extended", flc_a=52.0, sim_params={"4": 2, "9": 3}, sim_time_scale=8.0
    ) as ln:
        sim = ln.sim
        assert (sim.mode.value, sim.params[2], sim.params[4], sim.params[9]) == (
            "extended",
            52,  # motor FLC from flc_a
            2,
            3,
        )
        assert sim.params[11] == ADDRESS and sim.time_scale == 8.0  # 12-7 PROFIBUS address
        ln.hub.submit("ss", Source.ZENOH, DriveCommand(run=True))
        running = await ln.state(lambda s: s.status is DriveStatus.RUNNING)
        assert running.current_a is not None  # flc_a known: %FLC x 52 A
