"""Config keys of a Profibus bus and its drives: defaults and the exact error messages."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.link import Rs485
from adapters.profibus.options import BusOptions, DriveOptions
from gateway.cli import main
from gateway.config import load_adapter, parse
from gateway.errors import ConfigErrors
from gateway.model import Device
from tests.profibus.support import ADAPTER

FILE = "config/site.toml"


def bus(adapter: str = "profibus", drives: list[dict[str, Any]] | None = None, **keys: Any):
    table: dict[str, Any] = {"adapter": adapter, **keys}
    if drives is not None:
        table["drives"] = drives
    return parse({"buses": {"profibus1": table}}, FILE)


def errors(**keys: Any) -> list[str]:
    with pytest.raises(ConfigErrors) as exc:
        bus(**keys)
    return [str(e) for e in exc.value.errors]


def test_the_registry_names_this_adapter() -> None:
    assert load_adapter("profibus") is ProfibusAdapter
    assert ProfibusAdapter.devices == {Device.CFW11, Device.CFW700, Device.CFW320, Device.MCD600}
    assert ProfibusAdapter.address_range == (0, 126)  # each profile narrows it (issue 20)


def test_defaults() -> None:
    options = bus(port="/dev/ttyUSB0").buses[0].options
    assert options == BusOptions(port="/dev/ttyUSB0")
    params = options.bus_params()
    assert (params.tsl, params.min_tsdr, params.max_tsdr) == (200, 11, 100)  # 500k (1.1)
    assert options.watchdog == 0.5 and options.retries == 1


def test_bus_parameters_follow_the_baud_rate() -> None:
    options = bus(port="/dev/ttyS1", baudrate=187500).buses[0].options
    assert (options.tsl, options.max_tsdr) == (100, 60)  # 1.1: <= 187.5 kbit/s
    options = bus(port="/dev/ttyS1", baudrate=1500000, tsl=400).buses[0].options
    assert (options.tsl, options.max_tsdr) == (400, 150)


def test_a_baud_rate_outside_the_standard_list() -> None:
    assert errors(port="/dev/ttyUSB0", baudrate=250000) == [
        "config/site.toml: buses.profibus1.baudrate: 250000 is not a Profibus DP baud rate "
        "(9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000)"
    ]


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"tsl": 50}, "buses.profibus1.tsl: 50 is outside max_tsdr + 15 (115)..16383"),
        ({"tsl": 20000}, "buses.profibus1.tsl: 20000 is above the maximum 16383"),
        ({"min_tsdr": 5}, "buses.profibus1.min_tsdr: 5 is outside 11..max_tsdr - 1 (99)"),
        ({"max_tsdr": 300}, "buses.profibus1.tsl: 200 is outside max_tsdr + 15 (315)..16383"),
        ({"retries": 0}, "buses.profibus1.retries: 0 is below the minimum 1"),
        ({"retries": 16}, "buses.profibus1.retries: 16 is above the maximum 15"),
        ({"master_address": 126}, "buses.profibus1.master_address: 126 is above the maximum 125"),
        (
            {"watchdog": 0.005},
            "buses.profibus1.watchdog: 0.005 is below the minimum 0.01 (0 turns it off)",
        ),
        ({"watchdog": 700}, "buses.profibus1.watchdog: 700 is above the maximum 650.25"),
        ({"acyclic_timeout": 0}, "buses.profibus1.acyclic_timeout: 0 is below the minimum 0.01"),
        ({"simulate": "yes"}, "buses.profibus1.simulate: must be true or false, not a string"),
        ({"colour": "red"}, "buses.profibus1.colour: unknown key"),
    ],
)
def test_bus_errors(keys: dict[str, Any], message: str) -> None:
    assert errors(**{"port": "/dev/ttyUSB0", **keys}) == [f"{FILE}: {message}"]


def test_rs485_direction_control() -> None:
    assert bus(port="/dev/ttyS1").buses[0].options.rs485 is Rs485.AUTO
    for mode in Rs485:
        assert bus(port="/dev/ttyS1", rs485=mode.value).buses[0].options.rs485 is mode
    assert errors(port="/dev/ttyS1", rs485="rts") == [
        f"{FILE}: buses.profibus1.rs485: 'rts' is not one of 'auto', 'on', 'off'"
    ]


def test_port_rules() -> None:
    assert errors() == [f"{FILE}: buses.profibus1.port: is required"]
    assert errors(port="COM3") == [
        f"{FILE}: buses.profibus1.port: 'COM3' is not a device path (/dev/ttyUSB0) or a "
        "pyserial URL (rfc2217://host:port, socket://host:port)"
    ]
    assert errors(port="http://x") == [
        f"{FILE}: buses.profibus1.port: 'http://x': unknown pyserial URL scheme "
        "(known: rfc2217, socket, loop, spy, alt, hwgrep)"
    ]
    assert errors(port="/dev/ttyUSB0", simulate=True) == [
        f"{FILE}: buses.profibus1.port: not used with simulate = true (the gateway makes a pty)"
    ]
    for port in ("/dev/ttyUSB0", "/dev/ttyS0", "rfc2217://10.0.0.9:4001", "socket://gw:4001"):
        assert bus(port=port).buses[0].options.port == port
    assert bus(simulate=True).buses[0].options.port is None


def test_no_drive_at_the_masters_address() -> None:
    drives = [{"id": "a", "device": "test", "address": 2}]
    assert errors(adapter=ADAPTER, simulate=True, drives=drives) == [
        f"{FILE}: buses.profibus1.drives[0].address: 2 is the master's own address (master_address)"
    ]


def test_drive_options_are_the_profiles_plus_a_watchdog() -> None:
    drives = [
        {"id": "a", "device": "test", "address": 5, "size": 8, "watchdog": 0.2},
        {"id": "b", "device": "test", "address": 6},
    ]
    cfg = bus(adapter=ADAPTER, simulate=True, drives=drives)
    a, b = cfg.buses[0].drives
    assert isinstance(a.options, DriveOptions)
    assert a.options.watchdog == 0.2 and a.options.profile.size == 8
    assert b.options.watchdog is None


def test_drive_errors_name_the_drive_key() -> None:
    drives = [
        {"id": "a", "device": "test", "address": 126},
        {"id": "b", "device": "CFW-08", "address": 7},
        {"id": "c", "device": "test", "address": 8, "size": 99},
        {"id": "d", "device": "test", "address": 9, "speed": 1},
    ]
    got = errors(adapter=ADAPTER, simulate=True, drives=drives)
    assert got[0] == (
        f"{FILE}: buses.profibus1.drives[a].address: 126 is outside the test range "
        "0-125 (DP station addresses, fact sheet 1.2); use 0-125"
    )
    assert got[1].startswith(f"{FILE}: buses.profibus1.drives[b].device: 'CFW-08' is not one of")
    assert got[2] == f"{FILE}: buses.profibus1.drives[c].size: 99 is above the maximum 32"
    assert got[3] == f"{FILE}: buses.profibus1.drives[d].speed: unknown key"


@pytest.mark.parametrize(
    ("device", "good", "bad", "source"),
    [
        ("CFW-11", (1, 125), (0, 126), "CFW-11 manual 2.3.2 and P0918 (section 3): 1 a 125"),
        ("CFW700", (1, 125), (0, 126), "CFW700 manual P0918 (section 4): 1 to 126"),
        ("CFW320", (1, 125), (0, 126), "CFW320 manual 3.2 and P750 (section 4.2): 1 to 126"),
        ("MCD 600", (1, 125), (0, 126), "MCD 600 PROFIBUS manual 7.2"),
    ],
)
def test_each_device_takes_the_addresses_its_manual_gives(
    device: str, good: tuple[int, ...], bad: tuple[int, ...], source: str
) -> None:
    """Issue 20: CFW-11 P0918 1-125, CFW700 P0918 1-126, CFW320 P750 1-126, MCD 600 1-125;
    126 (the Set_Slave_Add default address) never reaches data exchange (1.2: <= 125)."""
    for address in good:
        bus(
            adapter="profibus",
            simulate=True,
            drives=[{"id": "m", "device": device, "address": address}],
        )
    for address in bad:
        drives = [{"id": "pump-3", "device": device, "address": address}]
        [got] = errors(adapter="profibus", simulate=True, drives=drives)
        assert got.startswith(f"{FILE}: buses.profibus1.drives[pump-3].address: {address} is "), got
        assert source in got and got.endswith("; use 1-125"), got
    [over] = errors(
        adapter="profibus", simulate=True, drives=[{"id": "x", "device": device, "address": 126}]
    )
    if device in ("CFW700", "CFW320"):
        assert f"126 is in the {device} range 1-126 but 126 is the Set_Slave_Add default" in over


def test_duplicate_addresses_are_the_cores_error() -> None:
    drives = [
        {"id": "a", "device": "test", "address": 5},
        {"id": "b", "device": "test", "address": 5},
    ]
    assert errors(adapter=ADAPTER, simulate=True, drives=drives) == [
        f"{FILE}: buses.profibus1.drives: address 5 is used by a and b"
    ]


def test_check_config_names_the_drive_and_the_manuals_range(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    site = tmp_path / "site.toml"
    site.write_text(
        '[buses.pb]\nadapter = "profibus"\nsimulate = true\n'
        '[[buses.pb.drives]]\nid = "conveyor"\ndevice = "CFW-11"\naddress = 126\n'
    )
    assert main(["check-config", str(site)]) == 2
    err = capsys.readouterr().err
    assert "drives[conveyor].address: 126 is outside the CFW-11 range 1-125" in err
    assert "P0918" in err
