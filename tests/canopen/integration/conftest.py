"""The CANopen integration rig: the adapter (master engine + link) and simulated CiA 402
drives (the simulator's runner) on a python-can ``virtual`` channel of their own, with the
real hub."""

from __future__ import annotations

import asyncio
import contextlib
import uuid
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.sim.node import SimNodeConfig
from adapters.canopen.sim.runner import SimRunner
from adapters.canopen.sim.simulated import sim_configs
from gateway.adapter import Event
from gateway.config import parse, shipped_file
from gateway.hub import EventSubscription, Hub
from gateway.model import DriveState
from gateway.runtime.daemon import build_hub
from tests.support.timing import scaled

EDS = str(shipped_file("eds/cia402-drive.eds"))
# The rig's line timing; every timer grows with the suite's time scale.
FAST_BUS: dict[str, Any] = {
    "sync_period": scaled(0.02),
    "pdo_period": scaled(0.02),
    "sdo_timeout": scaled(0.3),
    "retry": scaled(0.2),
    "boot_timeout": scaled(1.0),
    "heartbeat": round(scaled(100)),
}


def drive(node: int, **keys: Any) -> dict[str, Any]:
    return {
        "id": f"d{node}",
        "device": "CiA 402",
        "address": node,
        "eds": EDS,
        "max_rpm": 1800.0,
        "heartbeat": round(scaled(100)),
        "sim_ramp_time": 0.2,
        **keys,
    }


@dataclass
class Rig:
    hub: Hub
    adapter: CanOpenAdapter
    sim: SimRunner
    events: EventSubscription
    task: asyncio.Task[None]
    seen: list[Event] = field(default_factory=list)

    async def wait(
        self, drive_id: str, predicate: Callable[[DriveState], bool], within: float = 10.0
    ) -> DriveState:
        return await asyncio.wait_for(self.hub.wait_for(drive_id, predicate), scaled(within))

    async def until(self, predicate: Callable[[], bool], within: float = 10.0) -> None:
        await asyncio.wait_for(self.sim.until(predicate), scaled(within))

    async def event(self, predicate: Callable[[Event], bool], within: float = 10.0) -> Event:
        async def find() -> Event:
            while True:
                ev = await self.events.get()
                self.seen.append(ev)
                if predicate(ev):
                    return ev

        for ev in self.seen:
            if predicate(ev):
                return ev
        return await asyncio.wait_for(find(), scaled(within))


def gateway_side(
    drives: list[dict[str, Any]], channel: str, bus: dict[str, Any] | None = None
) -> tuple[Hub, CanOpenAdapter]:
    """A hub and a CANopen adapter for ``drives`` on ``channel`` (not running)."""
    table = {
        "adapter": "canopen",
        "interface": "virtual",
        "channel": channel,
        **FAST_BUS,
        **(bus or {}),
        "drives": drives,
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": table}},
        "test.toml",
    )
    hub = build_hub(config)
    adapter = CanOpenAdapter(config.buses[0])
    hub.attach_params([d["id"] for d in drives], adapter)
    return hub, adapter


@contextlib.asynccontextmanager
async def rig(
    drives: list[dict[str, Any]],
    *,
    bus: dict[str, Any] | None = None,
    sims: list[SimNodeConfig] | None = None,
) -> AsyncIterator[Rig]:
    channel = f"co-{uuid.uuid4().hex[:10]}"
    hub, adapter = gateway_side(drives, channel, bus)
    runner = SimRunner("virtual", channel, sim_configs(adapter.bus) if sims is None else sims)
    sim_task = asyncio.create_task(runner.run(), name="sim")
    await asyncio.wait_for(runner.started.wait(), scaled(5))
    with hub.subscribe_events() as events:
        task = asyncio.create_task(adapter.run(hub), name="adapter")
        try:
            yield Rig(hub, adapter, runner, events, task)
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            runner.stop()
            await asyncio.gather(sim_task, return_exceptions=True)
