"""Quick stop on a simulated Profibus line (issue 17 item 4): adapter, master, pty, simulators.

A CFW700 programmed in V/f (P0202 = 0, written as a start-up parameter like the demo's
command sources) and one in sensorless vector: the gateway reads P0202 at connect, says in
the events and the state that the V/f drive's quick stop is a ramp stop, and the drive
stops on a quick stop and stays stopped when the quick stop is released.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

import pytest

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.weg.sim.drive import WegSim
from gateway.adapter import EventKind
from gateway.config import parse
from gateway.hub import Hub
from gateway.model import CommState, DriveCommand, DriveState, Source
from gateway.runtime.daemon import build_hub
from tests.support import simulated
from tests.support.heard import Heard

NETWORK = {"P0220": 10, "P0222": 11, "P0226": 9, "P0227": 4, "P0228": 5, "P0105": 5}
RAMPS = {"P0100": 10, "P0101": 10, "P0313": 1}  # 1.0 s from 0 to P0134 = 1800 rpm
LIMIT = 20.0  # s: a bound on a busy machine, never a wait


def drive(drive_id: str, address: int, control_type: int) -> dict[str, Any]:
    startup = {**NETWORK, **RAMPS, "P0202": control_type}
    return {"id": drive_id, "device": "CFW700", "address": address, "startup_params": startup}


@contextlib.asynccontextmanager
async def line() -> AsyncIterator[tuple[Hub, ProfibusAdapter]]:
    drives = [drive("vf", 4, 0), drive("vector", 5, 3)]
    table = {"adapter": "profibus", "simulate": True, "latency": 0.02, "drives": drives}
    config = parse({"buses": {"profibus": table}}, "quick-stop-line.toml")
    hub = build_hub(config)
    adapter = simulated.profibus(ProfibusAdapter, config.buses[0])
    hub.attach_params([d["id"] for d in drives], adapter)
    task = asyncio.create_task(adapter.run(hub))
    try:
        yield hub, adapter
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def until(hub: Hub, drive_id: str, pred: Any) -> DriveState:
    async with asyncio.timeout(LIMIT):
        state: DriveState = await hub.wait_for(drive_id, pred)
        return state


def sim(adapter: ProfibusAdapter, address: int) -> WegSim:
    line = simulated.sim_line(adapter)
    assert line is not None
    device = line[address].device
    assert isinstance(device, WegSim)
    return device


def configured(state: DriveState) -> bool:
    return state.comm is CommState.ONLINE and "quick_stop_as_ramp" in state.values


async def test_p0202_read_at_connect_said_in_events_and_state() -> None:
    async with line() as (hub, _adapter):
        with hub.subscribe_events() as events:
            vf = await until(hub, "vf", configured)
            vector = await until(hub, "vector", configured)
            safety = [e for e in events.drain() if e.kind is EventKind.SAFETY]
    assert vf.values["quick_stop_as_ramp"] == 1 and vf.values["P0202"] == 0
    assert vector.values["quick_stop_as_ramp"] == 0 and vector.values["P0202"] == 3
    assert [(e.drive_id, e.text) for e in safety] == [
        ("vf", "quick stop falls back to ramp stop: P0202 = 0 (V/f 60 Hz)")
    ]


@pytest.mark.parametrize(("drive_id", "address"), [("vf", 4), ("vector", 5)])
async def test_quick_stop_stops_and_its_release_does_not_restart(
    drive_id: str, address: int
) -> None:
    async with line() as (hub, adapter):
        await until(hub, drive_id, lambda s: s.online and s.speed_base is not None)
        hub.submit(drive_id, Source.ZENOH, DriveCommand(run=True, speed_rpm=900.0))
        await until(hub, drive_id, lambda s: s.at_reference)
        hub.submit(drive_id, Source.ZENOH, DriveCommand(quick_stop=True))
        await until(hub, drive_id, lambda s: not s.running)
        drive_sim = sim(adapter, address)
        assert drive_sim.net.run is False  # P0684 bit 0 = 0 with the quick stop
        assert drive_sim.net.quick_stop is (drive_id == "vector")  # V/f: no bit 6 sent
        assert drive_sim.motor.speed == 0.0
        # released: whatever the hub's desired run still says, the motor stays stopped
        sims = simulated.sim_line(adapter)
        assert sims is not None
        slave = sims[address]
        hub.submit(drive_id, Source.ZENOH, DriveCommand(quick_stop=False))
        after = slave.counters.exchanges + 20  # twenty data exchanges after the release
        with Heard(slave.counters) as heard:
            async with asyncio.timeout(LIMIT):
                while slave.counters.exchanges < after:  # watched after every telegram
                    assert drive_sim.motor.speed == 0.0 and not drive_sim.net.run
                    await heard.next()
        assert not hub.state(drive_id).running
