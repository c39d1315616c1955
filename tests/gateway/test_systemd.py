from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.runtime.systemd import Notifier

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
    # ExecReload= does what SIGHUP does (check the file, reload nothing), then sends it
    reloads = [
        line.split("=", 1)[1] for line in text.splitlines() if line.startswith("ExecReload=")
    ]
    assert reloads == [
        "/opt/drive-gateway/venv/bin/drive-gateway check-config --errors-only /etc/drive-gateway/site.toml",
        "/bin/kill -HUP $MAINPID",
    ]


def test_the_site_template_and_the_unit_agree_on_the_modbus_port() -> None:
    """Binding a port below 1024 needs CAP_NET_BIND_SERVICE, and only that capability."""
    import tomllib

    site = tomllib.loads((UNIT.parent / "site.example.toml").read_text())
    port = int(site["modbus"]["bind"].rsplit(":", 1)[1])
    settings = dict(unit_lines())
    wanted = "CAP_NET_BIND_SERVICE" if port < 1024 else ""
    assert settings["CapabilityBoundingSet"] == wanted, port
    assert settings["AmbientCapabilities"] == wanted, port


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_unit_file_verifies(tmp_path: Path) -> None:
    exe = Path(sys.executable).parent / "drive-gateway"
    unit = tmp_path / "drive-gateway.service"
    unit.write_text(UNIT.read_text().replace("/opt/drive-gateway/venv/bin/drive-gateway", str(exe)))
    proc = subprocess.run(
        ["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, check=False
    )
    problems = [
        line for line in (proc.stdout + proc.stderr).splitlines() if "drive-gateway.service" in line
    ]
    assert problems == [], problems


def unit_lines() -> list[tuple[str, str]]:
    """Every setting of the unit file, in order (a key may repeat)."""
    out = []
    for line in UNIT.read_text().splitlines():
        if "=" in line and not line.startswith("#"):
            name, value = line.split("=", 1)
            out.append((name, value))
    return out


def test_unit_sandbox_keeps_what_the_product_needs() -> None:
    lines = unit_lines()
    settings = dict(lines)
    families = set(settings["RestrictAddressFamilies"].split())
    # journal and notify socket, Zenoh and Modbus, SocketCAN and its interface lookup
    assert families == {"AF_UNIX", "AF_INET", "AF_INET6", "AF_CAN", "AF_NETLINK"}
    assert settings["DevicePolicy"] == "closed"
    devices = {value for name, value in lines if name == "DeviceAllow"}
    assert {"char-ttyS rw", "char-ttyUSB rw", "char-ttyACM rw"} <= devices
    assert all(d.startswith("char-tty") for d in devices)  # serial ports only
    assert "PrivateDevices" not in settings  # it would hide /dev/ttyS* and /dev/ttyUSB*
    assert "PrivateNetwork" not in settings and "IPAddressDeny" not in settings
    assert "PrivateUsers" not in settings  # it would void CAP_NET_BIND_SERVICE for port 502
    assert settings["NotifyAccess"] == "main"
    for name, value in {
        "ProtectSystem": "strict",
        "PrivateMounts": "yes",
        "RemoveIPC": "yes",
        "ProtectProc": "invisible",
        "ProcSubset": "pid",
        "MemoryDenyWriteExecute": "yes",
        "RestrictNamespaces": "yes",
        "SystemCallArchitectures": "native",
        "ReadOnlyPaths": "/etc/drive-gateway",
    }.items():
        assert settings[name] == value, name


def _offline_security(unit: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["systemd-analyze", "security", "--offline=yes", "--no-pager", str(unit)],
        capture_output=True,
        text=True,
        check=False,
    )


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_unit_exposure_stays_low(tmp_path: Path) -> None:
    """The score recorded in docs/operations.md ("Security"); systemd >= 250 (--offline).
    2.1: the 1.7 of the sandbox, CAP_NET_BIND_SERVICE for Modbus on port 502 (issue 24) and
    the steady rings' real-time priority (decision 0104)."""
    exe = Path(sys.executable).parent / "drive-gateway"
    unit = tmp_path / "drive-gateway.service"
    unit.write_text(UNIT.read_text().replace("/opt/drive-gateway/venv/bin/drive-gateway", str(exe)))
    proc = _offline_security(unit)
    if "--offline" in proc.stderr and proc.returncode != 0:
        pytest.skip(f"systemd-analyze has no --offline: {proc.stderr.strip()}")
    found = re.search(r"Overall exposure level for drive-gateway\.service: ([0-9.]+)", proc.stdout)
    assert found, proc.stdout + proc.stderr
    assert float(found.group(1)) <= 2.1, proc.stdout


def test_the_unit_lets_the_site_templates_ring_priority_through() -> None:
    """ring_priority (decision 0104): the template's priority within LimitRTPRIO, realtime
    not restricted, sched_setscheduler allowed again after @resources is taken away."""
    lines = unit_lines()
    settings = dict(lines)
    template = (UNIT.parent / "site.example.toml").read_text()
    found = re.search(r"^ring_priority = (\d+)", template, flags=re.M)
    assert found is not None
    assert 0 < int(found.group(1)) <= int(settings["LimitRTPRIO"])
    assert settings.get("RestrictRealtime", "no") == "no"
    filters = [value for name, value in lines if name == "SystemCallFilter"]
    removed = next(i for i, f in enumerate(filters) if "~" in f and "@resources" in f)
    assert any("sched_setscheduler" in f.split() for f in filters[removed + 1 :])
