"""The steady exchange on a simulated line (docs/decisions/0096): the adapter, its WEG
profile and the hub are called for a reply only when it says something new, and a command
goes out with the slave's next Data_Exchange all the same.

Two CFW700 (manufacturer profile) on a pty, the adapter on the test's loop with the hub.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.master import InputsReceived
from adapters.profibus.master.station import INPUTS_REFRESH
from adapters.profibus.sim.devices import SIM_DEVICES
from adapters.profibus.sim.simulated import SimulatedLine
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.drive import Cfw700Sim, WegSim
from gateway.config import DriveConfig, parse
from gateway.hub import Hub
from gateway.model import Device, DriveCommand, Source
from gateway.runtime.daemon import build_hub
from tests.support import simulated
from tests.support.heard import Heard
from tests.support.timing import scaled

LIMIT = 20.0  # s, times the machine's time scale: a bound, never a wait
DRIVES: list[dict[str, Any]] = [
    {"id": "a", "address": 3, "device": "CFW700"},
    {"id": "b", "address": 4, "device": "CFW700"},
]


class RemoteCfw700(Cfw700Sim):
    """A CFW700 taking its run, stop and speed from the network."""

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> WegSim:
        sim = super().for_drive(drive)
        sim.values.update(sp.NETWORK_SOURCES)
        return sim


@contextlib.asynccontextmanager
async def line() -> AsyncIterator[tuple[Hub, ProfibusAdapter]]:
    table = {"adapter": "profibus", "simulate": True, "latency": 0.02, "drives": DRIVES}
    config = parse({"buses": {"profibus": table}}, "steady-lane.toml")
    hub = build_hub(config)
    here = f"{__name__}:RemoteCfw700"
    links = SimulatedLine(config.buses[0], {**SIM_DEVICES, Device.CFW700: here})
    adapter = ProfibusAdapter(config.buses[0], links=links)
    task = asyncio.create_task(adapter.run(hub))
    try:
        yield hub, adapter
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def _counting(adapter: ProfibusAdapter) -> list[int]:
    """Counts the InputsReceived the engine hands the adapter, by slave address."""
    handled: list[int] = []
    original = adapter._on_action

    def on_action(action: Any) -> None:
        if isinstance(action, InputsReceived):
            handled.append(action.address)
        original(action)

    adapter._on_action = on_action  # type: ignore[method-assign]
    driver = adapter._driver
    assert driver is not None
    driver.on_action = on_action
    return handled


def _run_commanded(device: WegSim) -> bool:
    commands = device.commands
    return commands.run_command(commands.remote())


async def test_a_steady_line_hands_the_adapter_only_what_changed() -> None:
    async with line() as (hub, adapter), asyncio.timeout(scaled(LIMIT)):
        for drive in ("a", "b"):
            await hub.wait_for(drive, lambda s: s.online)
        sim_line = simulated.sim_line(adapter)
        assert sim_line is not None
        handled = _counting(adapter)
        driver = adapter._driver
        assert driver is not None
        taken = driver.lane_taken
        slave = sim_line[3]
        first = slave.counters.exchanges
        with Heard(slave.counters) as heard:
            while slave.counters.exchanges < first + 400:
                await heard.next()
        exchanges = slave.counters.exchanges - first
        # at rest the telegrams repeat: the adapter sees slave 3's replies only every
        # INPUTS_REFRESH s (and its own changes), the lane takes the rest
        assert handled.count(3) < exchanges / 4, (handled.count(3), exchanges)
        assert driver.lane_taken - taken > exchanges / 2


async def test_a_command_on_a_steady_line_goes_out_with_the_next_exchange() -> None:
    async with line() as (hub, adapter), asyncio.timeout(scaled(LIMIT)):
        await hub.wait_for("a", lambda s: s.online)
        sim_line = simulated.sim_line(adapter)
        assert sim_line is not None
        slave = sim_line[3]
        device = slave.device
        assert isinstance(device, WegSim)
        with Heard(slave.counters) as heard:  # quiet: well past a refresh of its inputs
            start = asyncio.get_running_loop().time()
            while asyncio.get_running_loop().time() < start + 3 * INPUTS_REFRESH:
                await heard.next()
        assert adapter.master._slave(3).quiet
        before = slave.counters.exchanges
        hub.submit("a", Source.ZENOH, DriveCommand(run=True, speed_rpm=600.0))
        with Heard(slave.counters) as heard:
            while not _run_commanded(device):
                await heard.next()
        # the run went out within the next few exchanges, not at the next refresh
        assert slave.counters.exchanges - before <= 3
        before = slave.counters.exchanges
        hub.submit("a", Source.ZENOH, DriveCommand(run=False))
        with Heard(slave.counters) as heard:
            while _run_commanded(device):
                await heard.next()
        assert slave.counters.exchanges - before <= 3
