"""The simulated line behind an adapter, as the composition root gives it (simulate = true):
a test builds an adapter with it, and reaches the simulated devices through it."""

from __future__ import annotations

from typing import TypeVar

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.sim.runner import SimRunner as CanOpenRunner
from adapters.canopen.sim.simulated import SimulatedBus as CanOpenSimulatedBus
from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.sim.runner import SimRunner
from adapters.devicenet.sim.simulated import SimulatedBus
from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.simulated import SimulatedLine
from gateway.config import BusConfig

P = TypeVar("P", bound=ProfibusAdapter)


def profibus(cls: type[P], bus: BusConfig) -> P:
    """A Profibus adapter on a simulated line when ``bus`` says ``simulate = true``."""
    return cls(bus, links=SimulatedLine(bus)) if bus.simulate else cls(bus)


def devicenet(bus: BusConfig) -> DeviceNetAdapter:
    """A DeviceNet adapter on a simulated line when ``bus`` says ``simulate = true``."""
    return DeviceNetAdapter(bus, links=SimulatedBus(bus)) if bus.simulate else DeviceNetAdapter(bus)


def sim_line(adapter: object) -> SimLine | None:
    """The simulated slaves of a Profibus adapter (None until its line started)."""
    assert isinstance(adapter, ProfibusAdapter)
    links = adapter.links
    assert isinstance(links, SimulatedLine), "not a simulated line"
    return links.line


def sim_runner(adapter: object) -> SimRunner | None:
    """The simulated nodes of a DeviceNet adapter (None until its line started)."""
    assert isinstance(adapter, DeviceNetAdapter)
    links = adapter.links
    assert isinstance(links, SimulatedBus), "not a simulated line"
    return links.runner


def canopen_runner(adapter: object) -> CanOpenRunner | None:
    """The simulated CiA 402 nodes of a CANopen adapter (None until its line started)."""
    assert isinstance(adapter, CanOpenAdapter)
    links = adapter.links
    assert isinstance(links, CanOpenSimulatedBus), "not a simulated line"
    return links.runner
