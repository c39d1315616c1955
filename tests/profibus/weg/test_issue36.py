"""Issue 36, the WEG audit rows fixed in the profiles: the second ramp (P0684 bit 5, rows
C11-10, C7-10, C3-09) as a drive option, and the CFW320's warning that P308, P310, P311
and P312 must keep their factory settings (2.4, row C3-36) checked at connect."""

from __future__ import annotations

from typing import Any

import pytest

from adapters.profibus.contract import DiagKind
from adapters.profibus.weg.cfw11 import Cfw11Profile
from adapters.profibus.weg.cfw320 import Cfw320Profile
from adapters.profibus.weg.cfw700 import Cfw700Profile
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from gateway.config import parse as config_parse
from gateway.errors import ConfigError, ConfigErrors
from gateway.model import Device, DriveStatus
from gateway.schema import Table
from tests.profibus.weg.helpers import Loop, drive

SECOND_RAMP = {102: 5, 103: 5}  # 0.5 s to P0134 = 1800 rpm (first ramp: 2.0 s)


def parse(cls: type[WegProfile], **data: Any) -> WegOptions:
    table = Table(data, "site.toml", "buses.pb.drives[0]")
    options = cls.parse_options(table, drive(cls.device))
    assert table.unread() == []
    return options


# ----------------------------------------------------------------- the second ramp


@pytest.mark.parametrize("cls", [Cfw11Profile, Cfw700Profile, Cfw320Profile])
def test_second_ramp_is_a_drive_option(cls: type[WegProfile]) -> None:
    assert parse(cls).second_ramp is False
    assert parse(cls, second_ramp=True).second_ramp is True


def test_the_profidrive_profile_has_no_second_ramp_bit() -> None:
    with pytest.raises(ConfigError, match="STW1 has no such bit"):
        parse(Cfw11Profile, data_profile="profidrive", second_ramp=True)


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
async def test_bit_5_sends_the_drive_to_its_second_ramp(device: Device) -> None:
    ramps: dict[bool, float] = {}
    for second in (False, True):
        loop = Loop(device, WegOptions(second_ramp=second), params=SECOND_RAMP)
        await loop.connect()
        loop.step()
        assert bool(loop.last_out[1] & 0x20) is second  # P0684 bit 5 (low byte)
        loop.command(run=True, speed_rpm=900.0)
        start = loop.now
        loop.until(lambda s: s["at_reference"], 5.0)
        ramps[second] = loop.now - start
        assert loop.state["status"] is DriveStatus.RUNNING
        loop.command(run=False)
        loop.until(lambda s: s["status"] is DriveStatus.READY, 5.0)
        assert not loop.last_out[1] & 0x01  # stopped: bit 5 never starts anything
    # 900 rpm on a 2.0 s ramp to 1800 rpm: about 1 s; on the 0.5 s ramp: about 0.25 s
    assert ramps[True] < ramps[False] / 2


async def test_bit_5_alone_never_moves_the_motor() -> None:
    loop = Loop(Device.CFW700, WegOptions(second_ramp=True), params=SECOND_RAMP)
    await loop.connect()
    loop.step(40)
    assert loop.sim.motor.speed == 0.0
    assert loop.state["running"] is False


# ----------------------------------------------------------------- CFW320 P308, P310-P312


async def test_the_cfw320_factory_settings_are_read_at_connect() -> None:
    loop = Loop(Device.CFW320)
    changes = await loop.connect()
    assert changes["values"] == {"P308": 1, "P310": 0, "P311": 0, "P312": 0}
    assert [e for e in loop.events.got if e[1] == "config"] == []
    assert loop.step()["values"]["P308"] == 1  # kept beside the status bits


async def test_a_changed_setting_is_a_config_event_each_connect() -> None:
    loop = Loop(Device.CFW320, params={308: 7, 312: 2})
    await loop.connect()
    configs = [e for e in loop.events.got if e[1] == "config"]
    assert configs == [
        (
            "P308 = 7 (factory setting 1), P312 = 2 (factory setting 0): the CFW320 manual "
            "requires P308, P310, P311, P312 at their factory settings for the Profibus DP "
            "module to work",
            DiagKind.CONFIG,
            {"P308": 7, "P310": 0, "P311": 0, "P312": 2},
        )
    ]
    await loop.connect()
    assert len([e for e in loop.events.got if e[1] == "config"]) == 2


async def test_a_drive_s_own_factory_values_are_taken() -> None:
    options = parse(Cfw320Profile, factory_settings={"P308": 7, "312": 2})
    assert options.factory_settings == ((308, 7), (312, 2))
    loop = Loop(Device.CFW320, options, params={308: 7, 312: 2})
    await loop.connect()
    assert [e for e in loop.events.got if e[1] == "config"] == []


@pytest.mark.parametrize(
    ("cls", "data", "message"),
    [
        (Cfw320Profile, {"P313": 1}, "P313: not a parameter the CFW320 manual says"),
        (
            Cfw11Profile,
            {"P0308": 1},
            r"the CFW-11 manual says must keep its factory setting \(none\)",
        ),
        (Cfw320Profile, {"P308": 1, "308": 1}, "names a parameter twice"),
    ],
)
def test_factory_settings_errors(cls: type[WegProfile], data: dict[str, int], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse(cls, factory_settings=data)


async def test_the_other_models_have_none_to_read() -> None:
    loop = Loop(Device.CFW11)
    changes = await loop.connect()
    assert not {"P308", "P0308"} & set(changes.get("values", {}))


# ----------------------------------------------------------------- Clear and the other drives


def bus(*devices: str, clear: bool) -> dict[str, Any]:
    drives = [
        {"id": f"d{i}", "device": device, "address": 3 + i} for i, device in enumerate(devices)
    ]
    table = {"adapter": "profibus", "simulate": True, "clear_on_lost_control": clear}
    return {"buses": {"pb": {**table, "drives": drives}}}


@pytest.mark.parametrize("device", ["CFW-11", "CFW700", "CFW320"])
def test_clear_on_lost_control_is_refused_on_a_line_with_a_weg_drive(device: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        config_parse(bus("MCD 600", device, clear=True), "site.toml")
    [error] = err.value.errors
    assert error.key == "buses.pb.clear_on_lost_control"
    assert error.reason.startswith(f"drive d1 ({device}): in Clear a WEG drive takes no outputs")
    assert error.reason.endswith(
        "the command watchdog already stops the drive whose client is lost"
    )


def test_clear_on_lost_control_stays_for_lines_whose_drives_take_clear_as_a_stop() -> None:
    config = config_parse(bus("MCD 600", "MCD 600", clear=True), "site.toml")
    assert config.buses[0].options.clear_on_lost_control is True
    assert config_parse(bus("CFW-11", clear=False), "site.toml").buses[0].drives
