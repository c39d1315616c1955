"""End to end: quick stop on the demo's WEG line (issue 17 item 4), through Zenoh and Modbus.

The line of ``test_weg_e2e`` with the CFW700 programmed in V/f (P0202 = 0 among its
``startup_params``): the gateway reads P0202 at connect and publishes in the state that the
CFW700's quick stop is a ramp stop; a quick stop stops each drive with the run bit off, and
its release does not restart the motor. A write of P0202 through the params service is
followed at once and said in the events.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest_asyncio

from gateway.model import DriveStatus
from tests.e2e.harness import (
    PREFIX,
    QUICK_STOP,
    RUN,
    TIMEOUT,
    Gateway,
    parsed,
    running_gateway,
)
from tests.e2e.test_weg_e2e import MODELS, bus_cycles, buses, drive

CFW11, CFW700, CFW320 = MODELS


def line() -> str:
    """The demo's WEG line, the CFW700 in V/f 60 Hz, P0202 writable on every drive."""
    text = buses({"cfw700": ", P0202 = 0"})
    return text.replace("writable_params = [100, 101, 313]", "writable_params = [100, 101, 202]")


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    async with running_gateway(tmp_path, line, [m.id for m in MODELS]) as gw:
        for m in MODELS:  # connected: the start-up parameters written, P0202 read
            await gw.wait_for(m.id, lambda s: s.speed_base is not None)
        yield gw


async def test_p0202_in_the_state_and_quick_stop_by_modbus_never_restarts(gateway: Gateway) -> None:
    gw = gateway
    with gw.client.subscribe(gw.state_key(CFW700.id)) as states:
        await gw.client.settled(PREFIX)
        got = await gw.client.aone(gw.state_key(CFW700.id))
        assert parsed(got).values == {"P0202": 0, "quick_stop_as_ramp": 1}
        for model, control_type in ((CFW11, 3), (CFW320, None)):
            values = parsed(await gw.client.aone(gw.state_key(model.id))).values
            assert values.get("P0202") == control_type, model.id
        unit = CFW700.unit
        await gw.write(unit, 1, 900)  # speed_ref_rpm
        await gw.write(unit, 0, 0)
        await gw.write(unit, 0, RUN)
        await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT)
        await gw.write(unit, 0, RUN | QUICK_STOP)  # run still 1 in the client's word
        await states.auntil(lambda g: parsed(g).status is DriveStatus.READY, TIMEOUT)
        sim = drive(gw, CFW700)
        # V/f: P0684 = 0016h, a ramp stop (no bit 6, which this drive would ignore)
        assert not sim.net.run and not sim.net.quick_stop and sim.motor.speed == 0.0
        await gw.write(unit, 0, RUN)  # the quick stop released, the run bit still 1
        await bus_cycles(gw, CFW700, 40)
        assert sim.motor.speed == 0.0 and not sim.net.run
        assert not gw.daemon.hub.state(CFW700.id).running


async def test_quick_stop_by_zenoh_and_a_p0202_write(gateway: Gateway) -> None:
    gw = gateway
    events_key = f"{PREFIX}/drives/{CFW11.id}/events"
    with (
        gw.client.subscribe(gw.state_key(CFW11.id)) as states,
        gw.client.subscribe(events_key) as events,
    ):
        await gw.client.settled(PREFIX)
        await gw.command(CFW11.id, {"run": True, "speed_rpm": 900.0})
        await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT)
        await gw.command(CFW11.id, {"quick_stop": True})  # vector: OFF3 with ON = 0
        await states.auntil(lambda g: parsed(g).speed_rpm == 0.0, TIMEOUT)
        sim = drive(gw, CFW11)
        assert not sim.stw1.on and not sim.stw1.no_quick_stop
        await gw.command(CFW11.id, {"quick_stop": False})
        await bus_cycles(gw, CFW11, 40)
        assert sim.motor.speed == 0.0 and not sim.stw1.on  # released: no restart

        ok, answer = await gw.param(CFW11.id, 202, {"value": 5})  # VVW, motor stopped
        assert ok, answer
        event = await events.auntil(lambda e: e.json()["kind"] == "safety", TIMEOUT)
        assert event.json()["text"] == "quick stop falls back to ramp stop: P0202 = 5 (VVW)"
        await states.auntil(lambda g: parsed(g).values.get("quick_stop_as_ramp") == 1, TIMEOUT)
        await gw.command(CFW11.id, {"run": False})
        await gw.command(CFW11.id, {"run": True})
        await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT)
        await gw.command(CFW11.id, {"quick_stop": True})  # VVW: OFF1, bit 2 stays 1
        await states.auntil(lambda g: parsed(g).speed_rpm == 0.0, TIMEOUT)
        assert not sim.stw1.on and sim.stw1.no_quick_stop
