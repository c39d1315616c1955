from __future__ import annotations

from pathlib import Path

import pytest

from gateway.cli import main
from gateway.config import DEFAULT_CONFIG, load
from gateway.errors import ConfigErrors
from gateway.model import ControlMode, Device, StopAction

FAKE = "fake"  # tests/support/plugins.py

GOOD = f"""
[gateway]
name = "t"
[zenoh]
prefix = "test/gw"
listen = ["tcp/127.0.0.1:17447"]
[modbus]
bind = "127.0.0.1:15020"
allow = ["127.0.0.1/32", "10.0.0.0/8"]
[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
modbus_unit = 1
control = "modbus"
command_timeout = 2.5
on_command_timeout = "coast"
writable_params = [100, 101]
ramp_time = 1.0
[[buses.line1.drives]]
id = "d2"
device = "MCD 600"
address = 4
modbus_unit = 2
"""


def write(tmp_path: Path, text: str, name: str = "site.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_demo_config_is_valid() -> None:
    config = load(DEFAULT_CONFIG)
    assert config.zenoh.prefix == "demo"
    assert config.zenoh.multicast_scouting is False
    assert all(ep.startswith("tcp/127.0.0.1:") for ep in config.zenoh.listen)
    assert (config.modbus.host, config.modbus.port) == ("127.0.0.1", 1502)


def test_good_config(tmp_path: Path) -> None:
    config = load(write(tmp_path, GOOD))
    d1, d2 = config.drives
    assert (d1.id, d1.device, d1.address, d1.modbus_unit) == ("d1", Device.TEST, 3, 1)
    assert d1.control is ControlMode.MODBUS
    assert d1.command_timeout == 2.5 and d1.on_command_timeout is StopAction.COAST
    assert d1.writable_params == frozenset({100, 101})
    assert d1.options.ramp_time == 1.0
    assert d2.command_timeout is None and d2.on_shutdown is StopAction.RAMP_STOP
    assert config.buses[0].options.cycle == 0.01


def test_overrides(tmp_path: Path) -> None:
    config = load(write(tmp_path, GOOD)).with_overrides("tcp/127.0.0.1:9999", "127.0.0.1:5555")
    assert config.zenoh.listen == ("tcp/127.0.0.1:9999",)
    assert (config.modbus.host, config.modbus.port) == ("127.0.0.1", 5555)


BROKEN = [
    ("[gateway]\nnmae = 'x'\n", "site.toml: gateway.nmae: unknown key (did you mean 'name'?)"),
    ("[gateway\n", "site.toml: not valid TOML: Expected ']' at the end of a table declaration (at line 1, column 9)"),
    ("[gateway]\nshutdown_timeout = 'soon'\n", "site.toml: gateway.shutdown_timeout: must be a number, not a string"),
    ("[gateway]\nlog_level = 'LOUD'\n", "site.toml: gateway.log_level: 'LOUD' is not one of 'DEBUG', 'INFO', 'WARNING', 'ERROR'"),
    ("[zenoh]\nlisten = ['127.0.0.1:7447']\n", "site.toml: zenoh.listen[0]: '127.0.0.1:7447' is not a Zenoh endpoint (like tcp/127.0.0.1:7447)"),
    ("[zenoh]\nprefix = 'a/*'\n", "site.toml: zenoh.prefix: 'a/*' is not a valid Zenoh key prefix"),
    ("[zenoh]\nconfig_file = 'nope.json5'\n", "site.toml: zenoh.config_file: 'nope.json5' does not exist"),
    ("[modbus]\nbind = 'localhost'\n", "site.toml: modbus.bind: 'localhost' is not HOST:PORT"),
    ("[modbus]\nallow = ['10.0.0.300/8']\n", "site.toml: modbus.allow[0]: '10.0.0.300/8' is not an address or CIDR network"),
    ("[buses.l]\nadapter = 'canbus'\n", "site.toml: buses.l.adapter: unknown adapter 'canbus' (known: canopen, devicenet, echo-profibus, fake, held, profibus)"),
    ("[buses.l]\ncycle = 1\n", "site.toml: buses.l.adapter: is required"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'CFW-11'\naddress = 1\n",
     "site.toml: buses.l.drives[a].device: 'CFW-11' is not one of 'MCD 600', 'test'"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 126\n",
     "site.toml: buses.l.drives[a].address: 126 is above the maximum 125"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a b'\ndevice = 'test'\naddress = 1\n",
     "site.toml: buses.l.drives[0].id: 'a b' must be letters, digits, '-' or '_' (it is a key)"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\ncontrol = 'plc'\n",
     "site.toml: buses.l.drives[a].control: 'plc' is not one of 'any', 'zenoh', 'modbus', 'web', 'opcua'"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\non_command_timeout = 'brake'\n",
     "site.toml: buses.l.drives[a].on_command_timeout: 'brake' is not one of 'ramp_stop', 'coast', 'hold'"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\nwritable_params = [100, 'P1x1']\n",
     "site.toml: buses.l.drives[a].writable_params[1]: 'P1x1' is not a parameter: 100, P0100, 0x6083 or 0x2000:1"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\nmodbus_unit = 0\n",
     "site.toml: buses.l.drives[a].modbus_unit: 0 is below the minimum 1"),
    (f"[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\nramp = 2\n",
     "site.toml: buses.l.drives[a].ramp: unknown key (did you mean 'ramp_time'?)"),
    ("[extra]\nx = 1\n", "site.toml: extra: unknown key"),
    ("buses = 3\n", "site.toml: buses: must be a table, not an integer"),
    (f"[buses.l]\nadapter = '{FAKE}'\ncylce = 1\n", "site.toml: buses.l.cylce: unknown key (did you mean 'cycle'?)"),
    (f"[buses.l]\nadapter = '{FAKE}'\ndrives = {{ id = 'a' }}\n",
     "site.toml: buses.l.drives: must be an array of tables ([[buses.l.drives]])"),
    (f"[modbus]\ngateway_unit = 5\n[buses.l]\nadapter = '{FAKE}'\n[[buses.l.drives]]\nid = 'a'\ndevice = 'test'\naddress = 1\nmodbus_unit = 5\n",
     "site.toml: modbus.gateway_unit: 5 is also the modbus_unit of drive 'a'"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "message"), BROKEN)
def test_broken_config_gives_its_exact_message(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, text))
    messages = [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors]
    assert messages == [message]


def drives_toml(*drives: str) -> str:
    body = "".join(f"[[buses.l.drives]]\n{d}\n" for d in drives)
    return f"[buses.l]\nadapter = '{FAKE}'\n{body}"


@pytest.mark.parametrize(
    ("drives", "message"),
    [
        (
            ("id='a'\ndevice='test'\naddress=1", "id='a'\ndevice='test'\naddress=2"),
            "site.toml: buses: drive id 'a' is used by buses.l address 1 and buses.l address 2",
        ),
        (
            ("id='a'\ndevice='test'\naddress=1", "id='b'\ndevice='test'\naddress=1"),
            "site.toml: buses.l.drives: address 1 is used by a and b",
        ),
        (
            (
                "id='a'\ndevice='test'\naddress=1\nmodbus_unit=7",
                "id='b'\ndevice='test'\naddress=2\nmodbus_unit=7",
            ),
            "site.toml: buses: modbus_unit 7 is used by a and b",
        ),
    ],
)
def test_duplicates_are_errors(tmp_path: Path, drives: tuple[str, ...], message: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, drives_toml(*drives)))
    assert [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors] == [message]


def test_all_errors_are_reported_at_once(tmp_path: Path) -> None:
    text = "[gateway]\ntick = 9\n[modbus]\nread_only = 'yes'\n[extra]\n"
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, text))
    assert len(err.value.errors) == 3


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigErrors, match="file not found"):
        load(tmp_path / "absent.toml")


def test_check_config_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check-config", str(write(tmp_path, GOOD))]) == 0
    out = capsys.readouterr().out
    assert "2 drive(s) on 1 bus(es)" in out and "d1" in out and "MCD 600" in out
    assert main(["check-config", str(write(tmp_path, "[gateway]\nx=1\n", "bad.toml"))]) == 2
    assert "gateway.x: unknown key" in capsys.readouterr().err


def test_site_template_is_valid() -> None:
    config = load(DEFAULT_CONFIG.parent / "site.example.toml")
    assert (config.modbus.host, config.modbus.port) == ("0.0.0.0", 502)
    assert config.zenoh.multicast_scouting is False
