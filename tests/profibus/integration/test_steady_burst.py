"""Steady exchanges in bursts (docs/decisions/0101): with the slaves answering apart from
the line's loop (here a thread and loop of their own, as a device or the plant bench's
process does), the line takes the steady replies back to back without its loop turning;
a command relayed from the hub ends a burst and goes out with the slave's next exchanges;
a line simulated on the line's own loop never bursts (its slaves could not answer).

Two CFW700 on a pty, the adapter on a :class:`LineThread` as the daemon runs it.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import AsyncIterator, Iterator
from functools import partial
from typing import Any

import pytest

from adapters.link.timer import loop_ready
from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.link import profibus_port
from adapters.profibus.sim.devices import SIM_DEVICES
from adapters.profibus.sim.simulated import SimulatedLine
from gateway.config import BusConfig, parse
from gateway.hub import Hub
from gateway.model import Device, DriveCommand, Source
from gateway.runtime.daemon import build_hub
from gateway.runtime.linethread import LineThread
from tests.profibus.integration.test_steady_lane_line import DRIVES, _run_commanded
from tests.support import simulated
from tests.support.heard import Heard
from tests.support.timing import scaled

LIMIT = 30.0  # s, times the machine's time scale: a bound, never a wait
REMOTE = "tests.profibus.integration.test_steady_lane_line:RemoteCfw700"


def _bus(**options: Any) -> tuple[BusConfig, Hub]:
    table = {
        "adapter": "profibus",
        "simulate": True,
        "latency": 0.02,
        "cycle_time": 0.0,  # flat out: the line waits for replies most of the time
        "drives": DRIVES,
        **options,
    }
    config = parse({"buses": {"profibus": table}}, "steady-burst.toml")
    return config.buses[0], build_hub(config)


@contextlib.contextmanager
def slaves_apart(bus: BusConfig) -> Iterator[tuple[str, SimulatedLine]]:
    """The bus's simulated slaves on a pty, served by a thread and loop of their own."""
    sim = SimulatedLine(bus, {**SIM_DEVICES, Device.CFW700: REMOTE})
    loop = asyncio.new_event_loop()
    ready = threading.Event()
    stop = asyncio.Event()
    holder: dict[str, Any] = {}

    async def serve() -> None:
        holder["path"] = sim.start()
        ready.set()
        try:
            await stop.wait()
        finally:
            sim.close()

    thread = threading.Thread(target=lambda: loop.run_until_complete(serve()), daemon=True)
    thread.start()
    try:
        assert ready.wait(scaled(10.0))
        yield str(holder["path"]), sim
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(scaled(10.0))
        loop.close()


@contextlib.asynccontextmanager
async def line_apart(
    **options: Any,
) -> AsyncIterator[tuple[Hub, ProfibusAdapter, SimulatedLine, LineThread]]:
    bus, hub = _bus(**options)
    with slaves_apart(bus) as (path, sim):
        adapter = ProfibusAdapter(bus, links=profibus_port(path, bus.options.baudrate))
        line = LineThread(adapter, hub)
        task = asyncio.create_task(line.run())
        try:
            yield hub, adapter, sim, line
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


async def _exchanges(sim: SimulatedLine, address: int, count: int) -> None:
    assert sim.line is not None
    counters = sim.line[address].counters
    first = counters.exchanges
    with Heard(counters) as heard:
        await heard.until(lambda: counters.exchanges >= first + count)


def _commanded_as(device: Any, running: bool) -> bool:
    return bool(_run_commanded(device)) == running


async def commands_go_out_at_once(hub: Hub, sim: SimulatedLine) -> None:
    """A run and a stop relayed from the hub's loop are on the wire within drive a's
    (slave 3's) next few exchanges."""
    assert sim.line is not None
    slave = sim.line[3]
    device = slave.device
    for command, running in ((DriveCommand(run=True, speed_rpm=600.0), True),
                             (DriveCommand(run=False), False)):  # fmt: skip
        before = slave.counters.exchanges
        hub.submit("a", Source.ZENOH, command)
        with Heard(slave.counters) as heard:
            await heard.until(partial(_commanded_as, device, running))
        assert slave.counters.exchanges - before <= 3


async def test_steady_replies_are_taken_in_bursts_and_a_command_ends_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("DRIVE_GATEWAY_RING", "off")  # the bursts alone (rings: test_steady_ring)
    async with line_apart() as (hub, adapter, sim, line), asyncio.timeout(scaled(LIMIT)):
        for drive in ("a", "b"):
            await hub.wait_for(drive, lambda s: s.online)
        await _exchanges(sim, 3, 200)
        driver = adapter._driver
        assert driver is not None
        assert driver.burst_taken > 0  # replies taken back to back, without the loop
        await commands_go_out_at_once(hub, sim)
        # a callback put in the line's loop from another thread (as the hub's relay of a
        # command is) while the line bursts ends the burst; the reply read meanwhile is
        # handed to the loop after it, and the line goes on
        await _exchanges(sim, 3, 50)
        for _ in range(200):
            if driver.bursts_yielded:
                break
            await line.call(lambda: None)
        assert driver.bursts_yielded > 0
        await _exchanges(sim, 3, 50)


async def test_a_line_simulated_on_its_own_loop_never_bursts() -> None:
    bus, hub = _bus()
    adapter = ProfibusAdapter(bus, links=SimulatedLine(bus))
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    try:
        async with asyncio.timeout(scaled(LIMIT)):
            for drive in ("a", "b"):
                await hub.wait_for(drive, lambda s: s.online)
            driver = adapter._driver
            assert driver is not None
            taken = driver.lane_taken
            sim_line = simulated.sim_line(adapter)
            assert sim_line is not None
            with Heard(sim_line[3].counters, sim_line[4].counters) as heard:
                await heard.until(lambda: driver.lane_taken >= taken + 100)
            assert driver.burst_taken == 0
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def test_the_loops_ready_queue_is_seen() -> None:
    """What a burst looks at to give the loop back: asyncio's queue of due callbacks
    (private to asyncio: this fails if a Python version moves it)."""
    loop = asyncio.new_event_loop()
    try:
        ready = loop_ready(loop)
        assert not ready
        loop.call_soon(lambda: None)
        assert ready
        loop.run_until_complete(asyncio.sleep(0))
        assert not ready
    finally:
        loop.close()
