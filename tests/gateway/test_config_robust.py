"""A bad configuration is refused with every reason at once, never with a traceback
(issue 18, "Configuration and start-up")."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.cli import main
from gateway.config import load
from gateway.errors import ConfigErrors
from tests.support.plugins import pythonpath

ROOT = Path(__file__).resolve().parents[2]
MAX_DEPTH = 64  # gateway.json5check.MAX_DEPTH


def messages(tmp_path: Path, text: str) -> list[str]:
    path = tmp_path / "site.toml"
    path.write_text(text)
    with pytest.raises(ConfigErrors) as err:
        load(path)
    return [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors]


# ------------------------------------------------------------- every error at once


def test_a_bus_level_error_does_not_hide_the_drives_errors(tmp_path: Path) -> None:
    text = (
        "[buses.line1]\nadapter = 'fake'\ncycle = 'fast'\ncrash_afterr = 1\n"
        "[[buses.line1.drives]]\nid = 'cfw11'\ndevice = 'test'\naddress = 3\n"
        "[[buses.line1.drives]]\nid = 'cfw700'\ndevice = 'test'\naddress = 3\n"
        "[[buses.line1.drives]]\nid = 'ssw'\ndevice = 'test'\naddress = 200\nramp_tme = 1\n"
    )
    assert sorted(messages(tmp_path, text)) == sorted(
        [
            "site.toml: buses.line1.cycle: must be a number, not a string",
            "site.toml: buses.line1.drives[ssw].address: 200 is above the maximum 125",
            "site.toml: buses.line1.crash_afterr: unknown key (did you mean 'crash_after'?)",
            "site.toml: buses.line1.drives: address 3 is used by cfw11 and cfw700",
        ]
    )


def test_every_bad_key_of_a_drive_and_of_the_sections_is_reported(tmp_path: Path) -> None:
    text = (
        "[gatway]\n[gateway]\ntick = 9\nlog_level = 'LOUD'\n"
        "[zenoh]\nprefix = 'a/*'\nlisten = ['nowhere']\n"
        "[modbus]\nbind = 'localhost'\nallow = ['300.1.1.1']\n"
        "[buses.l]\nadapter = 'fake'\n"
        "[[buses.l.drives]]\nid = 'd1'\ndevice = 'test'\naddress = 1\n"
        "control = 'plc'\nmodbus_unit = 0\nadress = 2\n"
    )
    assert sorted(messages(tmp_path, text)) == sorted(
        [
            "site.toml: gatway: unknown key (did you mean 'gateway'?)",
            "site.toml: gateway.tick: 9 is above the maximum 1.0",
            "site.toml: gateway.log_level: 'LOUD' is not one of 'DEBUG', 'INFO', 'WARNING', 'ERROR'",
            "site.toml: zenoh.prefix: 'a/*' is not a valid Zenoh key prefix",
            "site.toml: zenoh.listen[0]: 'nowhere' is not a Zenoh endpoint (like tcp/127.0.0.1:7447)",
            "site.toml: modbus.bind: 'localhost' is not HOST:PORT",
            "site.toml: modbus.allow[0]: '300.1.1.1' is not an address or CIDR network",
            "site.toml: buses.l.drives[d1].control: 'plc' is not one of 'any', 'zenoh', 'modbus', 'web', 'opcua'",
            "site.toml: buses.l.drives[d1].modbus_unit: 0 is below the minimum 1",
            "site.toml: buses.l.drives[d1].adress: unknown key (did you mean 'address'?)",
        ]
    )


def test_duplicates_name_every_party(tmp_path: Path) -> None:
    drive = (
        "[[buses.{bus}.drives]]\nid = '{id}'\ndevice = 'test'\naddress = {a}\nmodbus_unit = {u}\n"
    )
    text = (
        "[buses.l]\nadapter = 'fake'\n"
        + drive.format(bus="l", id="cfw11", a=3, u=5)
        + drive.format(bus="l", id="cfw700", a=3, u=5)
        + drive.format(bus="l", id="cfw320", a=3, u=6)
        + "[buses.m]\nadapter = 'fake'\n"
        + drive.format(bus="m", id="cfw11", a=4, u=7)
    )
    assert sorted(messages(tmp_path, text)) == sorted(
        [
            "site.toml: buses.l.drives: address 3 is used by cfw11, cfw700 and cfw320",
            "site.toml: buses: drive id 'cfw11' is used by buses.l address 3 and buses.m address 4",
            "site.toml: buses: modbus_unit 5 is used by cfw11 and cfw700",
        ]
    )


def test_port_digits_that_are_not_ascii_are_an_error_not_a_crash(tmp_path: Path) -> None:
    assert messages(tmp_path, "[modbus]\nbind = '127.0.0.1:\u00b2'\n") == [
        "site.toml: modbus.bind: '127.0.0.1:\u00b2' is not HOST:PORT"
    ]


# ------------------------------------------------------------- bounded input


def test_deeply_nested_toml_is_refused(tmp_path: Path) -> None:
    arrays = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    assert messages(tmp_path, arrays) == ["site.toml: not valid TOML: nested too deep"]
    tables = "x = " + "{a = " * 40 + "1" + "}" * 40 + "\n"
    assert messages(tmp_path, tables) == ["site.toml: tables and arrays nest deeper than 32 levels"]
    dotted = "[" + ".".join(["a"] * 100) + "]\n"
    assert messages(tmp_path, dotted) == ["site.toml: tables and arrays nest deeper than 32 levels"]


def test_the_config_file_itself_must_be_a_bounded_regular_file(tmp_path: Path) -> None:
    for path, reason in [
        ("/dev/zero", "is a character device, not a regular file (a config file)"),
        (str(tmp_path), "is a directory, not a regular file (a config file)"),
    ]:
        with pytest.raises(ConfigErrors) as err:
            load(path)
        assert [e.reason for e in err.value.errors] == [reason]
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * (1 << 20) + "\n")
    with pytest.raises(ConfigErrors, match="may have at most 1048576"):
        load(big)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"[gateway]\nname = '\xff'\n")
    with pytest.raises(ConfigErrors, match="is not UTF-8 text"):
        load(binary)


def zenoh_file_errors(tmp_path: Path, config_file: str) -> list[str]:
    return messages(tmp_path, f"[zenoh]\nconfig_file = {config_file!r}\n")


def test_zenoh_config_file_gives_the_real_reason(tmp_path: Path) -> None:
    (tmp_path / "dir.json5").mkdir()
    (tmp_path / "big.json5").write_text("{a: '" + "x" * (1 << 20) + "'}")
    (tmp_path / "nested.json5").write_text("{a: " + "[" * 50_000 + "]" * 50_000 + "}")
    (tmp_path / "bad.json5").write_text('{\n  mode: "peer",\n  listen: {endpoints: ["tcp/x"]\n}\n')
    (tmp_path / "list.json5").write_text("[1, 2]")
    (tmp_path / "z.yaml").write_text("{mode: peer}")
    key = "site.toml: zenoh.config_file: "
    cases = {
        "/dev/zero": "'/dev/zero' is a character device, not a regular file (a Zenoh config file)",
        "dir.json5": "'dir.json5' is a directory, not a regular file (a Zenoh config file)",
        "absent.json5": "'absent.json5' does not exist",
        "big.json5": "'big.json5' is 1048583 bytes; a Zenoh config file may have at most 1048576",
        "nested.json5": f"'nested.json5' is not a Zenoh JSON5 config: nested deeper than "
        f"{MAX_DEPTH} levels (line 1, column {MAX_DEPTH + 4})",
        "bad.json5": "'bad.json5' is not a Zenoh JSON5 config: expected ',' or '}', "
        "found the end of the file (line 5, column 1)",
        "list.json5": "'list.json5' is not a Zenoh JSON5 config: expected '{', found '[' "
        "(line 1, column 1)",
        "z.yaml": "'z.yaml' is YAML; the gateway takes a Zenoh config in JSON5",
    }
    for name, reason in cases.items():
        assert zenoh_file_errors(tmp_path, name) == [key + reason], name


def test_a_good_zenoh_config_file_is_read_once_and_kept(tmp_path: Path) -> None:
    text = "// site\n{ mode: 'peer', listen: { endpoints: ['tcp/127.0.0.1:7447'], }, }\n"
    (tmp_path / "z.json5").write_text(text)
    cfg = tmp_path / "site.toml"
    cfg.write_text("[zenoh]\nconfig_file = 'z.json5'\n")
    config = load(cfg)
    assert config.zenoh.config_file == tmp_path / "z.json5"
    assert config.zenoh.config_text == text


# ------------------------------------------------------------- the commands


def run_gateway(tmp_path: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": pythonpath()}
    env.pop("NOTIFY_SOCKET", None)
    return subprocess.run(
        [sys.executable, "-m", "gateway", *argv],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_check_config_and_run_refuse_a_zenoh_file_zenoh_would_crash_on(tmp_path: Path) -> None:
    """Used to pass check-config, then run died of SIGSEGV in Zenoh's parser (exit 139)."""
    (tmp_path / "z.json5").write_text("{a: " + "[" * 50_000 + "]" * 50_000 + "}")
    cfg = tmp_path / "site.toml"
    cfg.write_text(
        "[zenoh]\nconfig_file = 'z.json5'\n[modbus]\nenabled = false\n"
        "[buses.l]\nadapter = 'fake'\n[[buses.l.drives]]\nid = 'd1'\ndevice = 'test'\naddress = 1\n"
    )
    for argv in (["check-config", str(cfg)], ["run", "--config", str(cfg)]):
        out = run_gateway(tmp_path, *argv)
        assert out.returncode == 2, (argv, out.returncode, out.stderr)
        assert f"nested deeper than {MAX_DEPTH} levels" in out.stderr
        assert "Traceback" not in out.stderr


def test_check_config_reports_a_traceback_free_error_for_deep_toml(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "deep.toml"
    cfg.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert main(["check-config", str(cfg)]) == 2
    assert "nested too deep" in capsys.readouterr().err


@pytest.mark.parametrize("adapter", [":x", ".x:y", "os:getcwd", "json:loads", "os", ""])
def test_check_config_refuses_any_adapter_not_registered(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], adapter: str
) -> None:
    """Used to print a traceback (exit 1) or import the module named."""
    cfg = tmp_path / "site.toml"
    cfg.write_text(f"[buses.l]\nadapter = {adapter!r}\n")
    assert main(["check-config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {cfg}: buses.l.adapter: ") and "Traceback" not in err
    assert "is not an adapter name" in err or "unknown adapter" in err


def test_the_cli_tools_check_their_zenoh_config_file_too(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``watch``/``cmd``/``param``/``health --zenoh-config`` gave Zenoh the file as it was."""
    deep = tmp_path / "client.json5"
    deep.write_text("{a: " + "[" * 50_000 + "]" * 50_000 + "}")
    with pytest.raises(SystemExit) as exit_:
        main(["health", "--zenoh-config", str(deep)])
    assert exit_.value.code == 2
    assert f"nested deeper than {MAX_DEPTH} levels" in capsys.readouterr().err
