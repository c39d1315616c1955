"""config/site.example.toml is a working site config: check-config says what is left to fill
in, and with its example drives uncommented and the CHANGE-ME marks filled in it loads."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gateway.cli import main
from gateway.cli.check import left_to_fill
from gateway.config import load
from gateway.model import Device

TEMPLATE = Path(__file__).resolve().parents[2] / "config" / "site.example.toml"


def filled_in(text: str) -> str:
    """The template with every example line and drive uncommented and every CHANGE-ME
    replaced."""
    out, in_drive = [], False
    for line in text.splitlines():
        if line.startswith(("# [[buses.", "# [buses.")):
            in_drive = True
        elif not line.startswith("# "):
            in_drive = False
        out.append(line[2:] if in_drive else line)
    return "\n".join(out).replace("CHANGE-ME", "A12345") + "\n"


def test_check_config_says_what_is_left_to_fill_in(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check-config", str(TEMPLATE)]) == 1
    out = capsys.readouterr().out
    assert out.startswith(f"{TEMPLATE}: valid, but not ready, 0 drive(s) on 2 bus(es)")
    assert "modbus.allow: 192.0.2.0/24 is a documentation network" in out
    assert re.search(r"line \d+: buses\.profibus\.port: replace CHANGE-ME", out)
    assert "no drive is configured" in out
    assert main(["check-config", "--errors-only", str(TEMPLATE)]) == 0  # ExecReload


def test_every_example_drive_loads(tmp_path: Path) -> None:
    site = tmp_path / "site.toml"
    site.write_text(filled_in(TEMPLATE.read_text()))
    config = load(site)
    assert {d.device for d in config.drives} == {
        Device.CFW11,
        Device.CFW700,
        Device.CFW320,
        Device.MCD600,
        Device.CFW08,
        Device.CIA402,
    }
    assert len(config.drives) == 6
    profibus = next(b for b in config.buses if b.name == "profibus")
    assert profibus.options.port.startswith("/dev/serial/by-id/")
    devicenet = next(b for b in config.buses if b.name == "devicenet")
    assert devicenet.options.channel == "can0"
    todo = left_to_fill(config, site.read_text())
    assert not any("CHANGE-ME" in item or "no drive" in item for item in todo), todo
    # what is left is this machine's: no such converter (and no can0 here)
    assert any("does not exist on this machine" in item for item in todo)


def test_the_template_does_not_claim_modbus_writes_parameters() -> None:
    text = TEMPLATE.read_text()
    assert "from Zenoh or Modbus" not in text
    assert "it reads and\n# writes no drive parameters" in text


def test_check_config_reads_the_value_not_the_comment(tmp_path: Path) -> None:
    """A value changed with CHANGE-ME left in its comment is done; a value (or an array
    line under its key) still CHANGE-ME is not, even with a # inside its string."""
    site = tmp_path / "site.toml"
    site.write_text(
        "[gateway]\n"
        'name = "line#3 CHANGE-ME"  # a # inside a string is no comment\n'
        "[modbus]\n"
        'allow = ["10.1.0.0/24"]  # CHANGE-ME: the PLC networks\n'
        "[zenoh]\n"
        "connect = [\n"
        '  "tcp/10.0.0.5:7447",  # CHANGE-ME in a comment\n'
        '  "tcp/CHANGE-ME:7447",\n'
        "]\n"
    )
    config = load(site)
    todo = left_to_fill(config, site.read_text())
    marks = [item for item in todo if "CHANGE-ME" in item]
    assert marks == [
        "line 2: gateway.name: replace CHANGE-ME",
        "line 8: zenoh.connect: replace CHANGE-ME",
    ]
    assert not any("modbus.allow" in item for item in todo)


def test_the_example_network_is_left_to_fill_in_until_replaced(tmp_path: Path) -> None:
    site = tmp_path / "site.toml"
    for allow, listed in (
        ('["192.0.2.0/24"]', True),
        ('["2001:db8::/48"]', True),
        ('["10.0.0.0/24", "192.0.2.7"]', True),
        ('["10.0.0.0/24"]', False),
    ):
        site.write_text(f"[modbus]\nallow = {allow}\n")
        todo = left_to_fill(load(site), site.read_text())
        assert any("is a documentation network" in item for item in todo) is listed, allow
