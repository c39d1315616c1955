"""How the simulated line builds a device for a configured drive (sim/devices.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest

from adapters.profibus.sim.devices import SIM_DEVICES, make_device, sim_class
from adapters.profibus.sim.echo import EchoSim
from gateway.config import DriveConfig
from gateway.model import Device


@dataclass(frozen=True)
class Options:
    mode: str = "extended"
    flc_a: float | None = 52.0
    words: int = 4
    colour: str = "red"


class Plain:
    def __init__(self, mode: str = "basic", *, flc_a: int = 100, address: int = 1) -> None:
        self.mode, self.flc_a, self.address = mode, flc_a, address


class Matching:
    def __init__(self, **kw: Any) -> None:
        self.kw = kw

    @classmethod
    def matching(cls, options: Any, *, address: int = 1) -> Matching:
        return cls(options=options, address=address)


TABLE = {
    Device.TEST: "adapters.profibus.sim.echo:EchoSim",
    Device.CFW08: "tests.profibus.test_sim_devices:Plain",
    Device.CFW320: "tests.profibus.test_sim_devices:Matching",
    Device.CFW700: "tests.profibus.test_sim_devices:Nothing",
}


def drive(device: Device, options: Any = None, address: int = 9) -> DriveConfig:
    return DriveConfig(id="x", bus="pb", device=device, address=address, options=options)


def test_for_drive_wins() -> None:
    @dataclass(frozen=True)
    class EchoOptions:
        size: int = 8

    sim = make_device(Device.TEST, drive(Device.TEST, EchoOptions()), TABLE)
    assert isinstance(sim, EchoSim) and sim.size == 8


def test_matching_programs_the_device_as_the_options_say() -> None:
    sim = make_device(Device.CFW320, drive(Device.CFW320, Options()), TABLE)
    assert isinstance(sim, Matching) and sim.kw == {"options": Options(), "address": 9}


def test_constructor_keywords_shared_with_the_options() -> None:
    sim = make_device(Device.CFW08, drive(Device.CFW08, Options()), TABLE)
    assert isinstance(sim, Plain)
    assert (sim.mode, sim.flc_a, sim.address) == ("extended", 52, 9)
    assert isinstance(sim.flc_a, int)
    bare = make_device(Device.CFW08, None, TABLE)
    assert isinstance(bare, Plain) and bare.mode == "basic"


def test_missing_simulators() -> None:
    with pytest.raises(LookupError, match="no simulated CFW-11"):
        sim_class(Device.CFW11, TABLE)
    with pytest.raises(LookupError, match="has no Nothing"):
        sim_class(Device.CFW700, TABLE)


def test_every_device_of_the_adapter_has_a_simulator_entry() -> None:
    from adapters.profibus.adapter import ProfibusAdapter

    assert ProfibusAdapter.devices <= set(SIM_DEVICES)
