"""Simulators are chosen by the composition root: the daemon gives an adapter a simulated
line for ``simulate = true``, and nothing else ever simulates (adapters/link/__init__.py)."""

from __future__ import annotations

import asyncio
import uuid
from typing import Any

import pytest

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.link import CanOpenBus
from adapters.canopen.sim.simulated import SimulatedBus as CanOpenSimulatedBus
from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.link import DeviceNetBus
from adapters.devicenet.sim.simulated import SimulatedBus
from adapters.link.serial import SerialPort
from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.sim.simulated import SimulatedLine
from gateway.config import BusConfig, Config, parse
from gateway.errors import ConfigError
from gateway.runtime.daemon import SIMULATORS, Daemon, build_hub, simulated_line


def profibus(**bus: Any) -> Config:
    table = {"adapter": "profibus", **bus}
    table["drives"] = [{"id": "cfw11", "device": "CFW-11", "address": 3}]
    return parse({"buses": {"pb": table}}, "line.toml")


def devicenet(**bus: Any) -> Config:
    channel = f"t-{uuid.uuid4().hex[:8]}"
    table: dict[str, Any] = {"adapter": "devicenet", "interface": "virtual", "channel": channel}
    drive = {"id": "cfw08", "device": "CFW-08", "address": 2, "max_rpm": 1800.0}
    table.update(bus, drives=[drive])
    return parse({"buses": {"dn": table}}, "line.toml")


def canopen(**bus: Any) -> Config:
    channel = f"t-{uuid.uuid4().hex[:8]}"
    table: dict[str, Any] = {"adapter": "canopen", "interface": "virtual", "channel": channel}
    drive = {"id": "co1", "device": "CiA 402", "address": 5, "eds": "eds/cia402-drive.eds"}
    table.update(bus, drives=[drive])
    return parse({"buses": {"co": table}}, "line.toml")


@pytest.mark.parametrize("cls", [ProfibusAdapter, DeviceNetAdapter, CanOpenAdapter])
def test_a_missing_options_table_is_a_config_error_naming_the_bus(cls: Any) -> None:
    """It used to mean ``simulate = true`` on Profibus: a line silently simulated."""
    with pytest.raises(ConfigError, match=r"buses\.line7: the bus has no options table"):
        cls(BusConfig(name="line7", adapter="x"))


def test_the_config_says_which_buses_are_simulated() -> None:
    assert profibus(simulate=True).buses[0].simulate
    assert not profibus(port="/dev/ttyUSB0").buses[0].simulate
    assert devicenet(simulate=True).buses[0].simulate
    assert not devicenet().buses[0].simulate
    assert canopen(simulate=True).buses[0].simulate
    assert not canopen().buses[0].simulate


def test_the_daemon_gives_a_simulated_line_only_where_the_config_says_so() -> None:
    cases: list[tuple[Config, type]] = [
        (profibus(simulate=True), SimulatedLine),
        (profibus(port="/dev/ttyUSB0"), SerialPort),
        (devicenet(simulate=True), SimulatedBus),
        (devicenet(), DeviceNetBus),
        (canopen(simulate=True), CanOpenSimulatedBus),
        (canopen(), CanOpenBus),
    ]
    for config, links in cases:
        adapter: Any = Daemon(config)._make_line(config.buses[0]).adapter
        assert isinstance(adapter.links, links)
    assert set(SIMULATORS) == {"profibus", "devicenet", "canopen"}


def test_a_bus_whose_adapter_has_no_simulator_cannot_be_simulated() -> None:
    bus = BusConfig(name="x", adapter="fake", simulate=True)
    with pytest.raises(ConfigError, match=r"buses\.x\.simulate: adapter 'fake' has no simulator"):
        simulated_line(bus)


@pytest.mark.parametrize(
    "config", [profibus(simulate=True), devicenet(simulate=True), canopen(simulate=True)]
)
async def test_an_adapter_given_no_simulated_line_does_not_run(config: Config) -> None:
    """Built to be looked at (its setup, its node configs) it may be; run, it refuses."""
    bus = config.buses[0]
    classes: dict[str, Any] = {
        "profibus": ProfibusAdapter,
        "devicenet": DeviceNetAdapter,
        "canopen": CanOpenAdapter,
    }
    adapter: Any = classes[bus.adapter](bus)
    assert adapter.links is None
    with pytest.raises(ConfigError, match=rf"buses\.{bus.name}\.simulate: simulate = true, but"):
        await asyncio.wait_for(adapter.run(build_hub(config)), 5.0)
