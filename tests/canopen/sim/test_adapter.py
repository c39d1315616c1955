"""The gateway's CANopen adapter against the simulator in-process on ``virtual`` (the
daemon's ``simulate = true`` line, :class:`SimulatedBus`); the same against
``drive-gateway sim canopen`` in a process of its own is in test_vcan.py."""

from __future__ import annotations

import asyncio
import contextlib
import uuid
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.codec.cia402 import State
from adapters.canopen.sim.simulated import SimulatedBus
from gateway.config import parse
from gateway.hub import Hub
from gateway.model import CommState, Direction, DriveCommand, DriveState, Source
from gateway.runtime.daemon import build_hub
from tests.support.timing import scaled

Z = Source.ZENOH


def drive(node_id: int, **keys: Any) -> dict[str, Any]:
    return {
        "id": f"d{node_id}",
        "device": "CiA 402",
        "address": node_id,
        "eds": "eds/cia402-drive.eds",
        "max_rpm": 1800.0,
        "sim_ramp_time": 0.3,
        **keys,
    }


@dataclass
class Rig:
    hub: Hub
    adapter: CanOpenAdapter
    line: SimulatedBus | None
    task: asyncio.Task[None]

    async def wait(
        self, drive_id: str, predicate: Callable[[DriveState], bool], within: float = 5.0
    ) -> DriveState:
        return await asyncio.wait_for(self.hub.wait_for(drive_id, predicate), scaled(within))


@contextlib.asynccontextmanager
async def rig(
    drives: list[dict[str, Any]],
    *,
    interface: str = "virtual",
    channel: str | None = None,
    bus: dict[str, Any] | None = None,
) -> AsyncIterator[Rig]:
    simulate = interface == "virtual"
    table = {
        "adapter": "canopen",
        "interface": interface,
        "channel": channel or f"co-{uuid.uuid4().hex[:8]}",
        "simulate": simulate,
        **(bus or {}),
        "drives": drives,
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": table}},
        "test.toml",
    )
    hub = build_hub(config)
    line = SimulatedBus(config.buses[0]) if simulate else None
    adapter = CanOpenAdapter(config.buses[0], links=line)
    hub.attach_params([d["id"] for d in drives], adapter)
    task = asyncio.create_task(adapter.run(hub), name="canopen-adapter")
    try:
        yield Rig(hub, adapter, line, task)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def online(s: DriveState) -> bool:
    return s.comm is CommState.ONLINE


async def test_run_reverse_stop_through_the_adapter() -> None:
    async with rig([drive(5), drive(6, mode="profile_velocity")]) as r:
        for d in ("d5", "d6"):
            await r.wait(d, online)
            r.hub.submit(d, Z, DriveCommand(run=True, speed_rpm=900.0))
        for d in ("d5", "d6"):
            await r.wait(d, lambda s: s.running and s.speed_rpm == 900.0)
        r.hub.submit("d5", Z, DriveCommand(direction=Direction.REVERSE, speed_rpm=600.0))
        await r.wait(
            "d5", lambda s: s.direction is Direction.REVERSE and s.speed_rpm in (600.0, -600.0)
        )
        assert r.line is not None and r.line.runner is not None
        assert r.line.runner.node(5).drive.velocity_actual == -600
        r.hub.submit("d5", Z, DriveCommand(run=False))
        await r.wait("d5", lambda s: not s.running and s.speed_rpm == 0.0)
        assert r.line is not None and r.line.runner is not None
        assert r.line.runner.node(6).drive.mode.value == 3  # the master set pv


async def test_a_fault_reaches_the_hub_with_its_emcy_code() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        assert r.line is not None and r.line.runner is not None
        r.line.runner.node(5).inject_fault(0x2310)
        state = await r.wait("d5", lambda s: s.fault_code is not None)
        assert state.fault_code == 0x2310
        assert r.line.runner.node(5).drive.state is State.FAULT


async def test_a_pulled_cable_takes_the_drive_offline_and_it_comes_back_stopped() -> None:
    async with rig([drive(5, comm_loss_option=3)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Z, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d5", lambda s: s.running and s.speed_rpm == 900.0)
        assert r.line is not None and r.line.runner is not None
        sim = r.line.runner.node(5)
        sim.silence()
        await r.wait("d5", lambda s: s.comm is CommState.OFFLINE)
        await r.line.runner.until(lambda: sim.drive.motor.speed == 0.0)  # 0x6007 = 3
        sim.silence(False)
        back = await r.wait("d5", lambda s: online(s) and not s.running, within=10.0)
        assert back.speed_rpm == 0.0
