from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.systemd import Notifier

ROOT = Path(__file__).resolve().parents[2]
UNIT = ROOT / "config" / "drive-gateway.service"


@pytest.fixture
def fake_systemd(tmp_path: Path):
    path = tmp_path / "notify"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(5)
    yield str(path), sock
    sock.close()


def test_messages_reach_the_socket(fake_systemd) -> None:
    path, sock = fake_systemd
    n = Notifier({"NOTIFY_SOCKET": path})
    assert n.ready("3 drives")
    assert sock.recv(100) == b"READY=1\nSTATUS=3 drives"
    n.status("degraded")
    assert sock.recv(100) == b"STATUS=degraded"
    n.watchdog()
    assert sock.recv(100) == b"WATCHDOG=1"
    n.stopping()
    assert sock.recv(100) == b"STOPPING=1"
    n.close()


def test_abstract_socket_address() -> None:
    assert Notifier({"NOTIFY_SOCKET": "@sd/notify"}).address == "\0sd/notify"


def test_nothing_happens_without_notify_socket() -> None:
    n = Notifier({})
    assert not n.enabled
    assert n.ready() is False and n.watchdog() is False


@pytest.mark.parametrize(
    ("env", "interval"),
    [
        ({"WATCHDOG_USEC": "10000000"}, 5.0),
        ({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": str(os.getpid())}, 5.0),
        ({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "1"}, None),
        ({"WATCHDOG_USEC": "0"}, None),
        ({}, None),
    ],
)
def test_watchdog_interval_is_half_of_watchdog_usec(
    env: dict[str, str], interval: float | None
) -> None:
    assert Notifier(env).watchdog_interval == interval


def test_unit_file_has_the_required_settings() -> None:
    text = UNIT.read_text()
    settings = {
        line.split("=", 1)[0]: line.split("=", 1)[1]
        for line in text.splitlines()
        if "=" in line and not line.startswith("#")
    }
    assert settings["Type"] == "notify"
    assert settings["Restart"] == "on-failure"
    assert int(settings["WatchdogSec"]) > 0
    assert settings["NoNewPrivileges"] == "yes"
    assert settings["ProtectSystem"] == "strict"
    assert settings["PrivateTmp"] == "yes"
    assert settings["SupplementaryGroups"] == "dialout"
    assert settings["CapabilityBoundingSet"] == ""  # CAP_NET_BIND_SERVICE only for port 502
    assert "#AmbientCapabilities=CAP_NET_BIND_SERVICE" in text


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_unit_file_verifies(tmp_path: Path) -> None:
    exe = Path(sys.executable).parent / "drive-gateway"
    unit = tmp_path / "drive-gateway.service"
    unit.write_text(
        UNIT.read_text().replace("/opt/drive-gateway/.venv/bin/drive-gateway", str(exe))
    )
    proc = subprocess.run(
        ["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, check=False
    )
    problems = [
        line for line in (proc.stdout + proc.stderr).splitlines() if "drive-gateway.service" in line
    ]
    assert problems == [], problems
