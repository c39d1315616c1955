"""How the simulated line builds a device for a configured drive (sim/devices.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest

from adapters.mcd600.options import Mcd600Options
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.sim.devices import KINDS, SIM_DEVICES, make_device, sim_class
from adapters.profibus.sim.echo import EchoSim
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim
from gateway.config import DriveConfig
from gateway.loader import NotLoadable
from gateway.model import Device


class Recording:
    """A simulator class: its one factory is ``for_drive``."""

    def __init__(self, drive: DriveConfig | None) -> None:
        self.drive = drive

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> Any:
        return cls(drive)


TABLE = {
    Device.TEST: "adapters.profibus.sim.echo:EchoSim",
    Device.CFW08: "tests.profibus.test_sim_devices:Recording",
    Device.CFW700: "tests.profibus.test_sim_devices:Nothing",
}


def drive(device: Device, options: Any = None, address: int = 9) -> DriveConfig:
    return DriveConfig(id="x", bus="pb", device=device, address=address, options=options)


def test_for_drive_builds_the_device_of_a_drive() -> None:
    @dataclass(frozen=True)
    class EchoOptions:
        size: int = 8

    sim = make_device(Device.TEST, drive(Device.TEST, EchoOptions()), TABLE)
    assert isinstance(sim, EchoSim) and sim.size == 8


def test_the_factory_gets_the_drive_or_none() -> None:
    configured = drive(Device.CFW08)
    sim = make_device(Device.CFW08, configured, TABLE)
    assert isinstance(sim, Recording) and sim.drive is configured
    bare = make_device(Device.CFW08, None, TABLE)
    assert isinstance(bare, Recording) and bare.drive is None


def test_a_weg_drive_is_programmed_as_its_options_say() -> None:
    options = WegOptions(words=4)
    sim = make_device(Device.CFW320, drive(Device.CFW320, options, address=9))
    assert isinstance(sim, Cfw320Sim)
    assert sim.values == Cfw320Sim.matching(options, address=9).values
    plain = make_device(Device.CFW11, drive(Device.CFW11, None, address=9))
    assert isinstance(plain, Cfw11Sim)
    assert plain.values == Cfw11Sim(address=9).values
    assert make_device(Device.CFW11).values == Cfw11Sim().values  # type: ignore[attr-defined]


def test_an_mcd600_is_built_from_its_options() -> None:
    sim = make_device(Device.MCD600, drive(Device.MCD600, Mcd600Options(flc_a=52.0)))
    assert isinstance(sim, Mcd600Sim)
    assert isinstance(make_device(Device.MCD600), Mcd600Sim)


def test_missing_simulators() -> None:
    with pytest.raises(LookupError, match="no simulated CFW-11"):
        sim_class(Device.CFW11, TABLE)
    with pytest.raises(NotLoadable, match="has no Nothing"):
        sim_class(Device.CFW700, TABLE)


def test_every_device_of_the_adapter_has_a_simulator_entry() -> None:
    from adapters.profibus.adapter import ProfibusAdapter

    assert ProfibusAdapter.devices <= set(SIM_DEVICES)


def test_the_command_line_names_come_from_the_registry() -> None:
    assert list(KINDS) == ["cfw11", "cfw700", "cfw320", "mcd600", "echo"]
