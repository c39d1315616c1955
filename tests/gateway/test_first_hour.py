"""What a new user reads first says what the gateway is: CANopen in the package's
description and the command line's, and the CANopen texts as CANopen users read them
(codes in hex, ``speed_base`` with its value)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from gateway.cli.parser import build_parser
from gateway.devices import Device, code_text

ROOT = Path(__file__).resolve().parents[2]


def test_canopen_is_in_every_description() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "CANopen" in project["description"]
    assert "CANopen" in (ROOT / "README.md").read_text().split("\n\n")[1]
    assert "CANopen" in (build_parser().description or "")
    assert "CANopen" in (ROOT / "config" / "drive-gateway.service").read_text()


@pytest.mark.parametrize(
    ("device", "code", "text"),
    [
        (Device.CIA402, 0x8130, "0x8130"),
        ("CiA 402", 0x2310, "0x2310"),
        (Device.CIA402, 0x10, "0x0010"),
        (Device.CFW11, 21, "21"),
        ("MCD 600", 26, "26"),
        ("no such model", 33072, "33072"),
        (None, 7, "7"),
    ],
)
def test_codes_as_the_devices_documents_write_them(
    device: Device | str | None, code: int, text: str
) -> None:
    assert code_text(device, code) == text


def test_the_canopen_speed_base_says_its_value() -> None:
    from adapters.canopen.drive import speed_base
    from adapters.canopen.options import Mode

    assert speed_base(Mode.VELOCITY, 1800.0, 1.0) == "100 % = max_rpm 1800 rpm; 0x6042 in rpm"
    assert speed_base(Mode.PROFILE_VELOCITY, 1500.0, 10.0) == (
        "100 % = max_rpm 1500 rpm; 0x60FF = rpm x 10"
    )


def test_the_watch_table_and_cmd_show_a_canopen_code_in_hex() -> None:
    from gateway.cli.tools import state_line, why_not

    state = {
        "id": "co",
        "device": "CiA 402",
        "comm": "online",
        "status": "faulted",
        "running": False,
        "fault_code": 0x8130,
        "fault_text": "heartbeat or life guard error",
    }
    assert "fault 0x8130 heartbeat or life guard error" in state_line(state)
    assert "(0x8130 heartbeat" in why_not(state, "run", 1.0)
