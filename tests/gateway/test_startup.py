"""A front end that cannot start is fatal at start-up: one line naming the cause and the
fix, exit status 2, never READY, no traceback, no bus touched (issue 18)."""

from __future__ import annotations

import errno
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.net import free_port, zenoh_endpoint
from tests.support.plugins import pythonpath

ROOT = Path(__file__).resolve().parents[2]
EXIT_STARTUP = 2  # gateway.runtime.daemon.EXIT_STARTUP
WAIT = 120  # s, a bound only: the daemon exits as soon as the bind fails


def site(tmp_path: Path, *, zenoh: str, modbus: str) -> Path:
    state_file = tmp_path / "adapter.log"
    cfg = tmp_path / "site.toml"
    cfg.write_text(
        f"{zenoh}\n{modbus}\n"
        f"[buses.line1]\nadapter = 'fake'\nstate_file = '{state_file}'\n"
        "[[buses.line1.drives]]\nid = 'd1'\ndevice = 'test'\naddress = 3\n"
    )
    return cfg


@pytest.fixture
def notify(tmp_path: Path) -> Iterator[tuple[Path, socket.socket]]:
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.setblocking(False)
    yield path, sock
    sock.close()


def received(sock: socket.socket) -> list[str]:
    lines: list[str] = []
    while True:
        try:
            lines.extend(sock.recv(4096).decode().split("\n"))
        except BlockingIOError:
            return lines


def run(cfg: Path, notify_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("WATCHDOG_")}
    env.update(NOTIFY_SOCKET=str(notify_path), PYTHONPATH=pythonpath())
    return subprocess.run(
        [sys.executable, "-m", "gateway", "run", "--config", str(cfg), *extra],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=WAIT,
        check=False,
    )


def assert_fatal(out: subprocess.CompletedProcess[str], sent: list[str], cause: str) -> str:
    assert out.returncode == EXIT_STARTUP == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert "READY=1" not in sent
    fatal = [line for line in out.stderr.splitlines() if "cannot start" in line]
    assert len(fatal) == 1, out.stderr
    assert cause in fatal[0], fatal[0]
    assert "restarting" not in out.stderr and "not serving" not in out.stderr
    problems = [ln for ln in out.stderr.splitlines() if " ERROR " in ln or " WARNING " in ln]
    assert problems == [*[ln for ln in problems if "no drives" in ln], fatal[0]], out.stderr
    assert any(line.startswith("STATUS=cannot start: ") for line in sent), sent
    return fatal[0]


def test_a_modbus_port_in_use_is_fatal_naming_the_fix(tmp_path: Path, notify) -> None:
    path, sock = notify
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cfg = site(
            tmp_path,
            zenoh="[zenoh]\nenabled = false",
            modbus=f"[modbus]\nbind = '127.0.0.1:{port}'",
        )
        out = run(cfg, path)
    line = assert_fatal(
        out, received(sock), f"modbus: cannot listen on 127.0.0.1:{port}: address already in use"
    )
    assert "another drive-gateway instance" in line and "--modbus-bind" in line
    assert not (tmp_path / "adapter.log").exists()  # no bus was touched


def test_a_zenoh_endpoint_in_use_is_fatal_naming_the_fix(tmp_path: Path, notify) -> None:
    path, sock = notify
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cfg = site(
            tmp_path,
            zenoh=f"[zenoh]\nlisten = ['tcp/127.0.0.1:{port}']",
            modbus=f"[modbus]\nbind = '127.0.0.1:{free_port()}'",
        )
        out = run(cfg, path)
    line = assert_fatal(out, received(sock), "zenoh: cannot open the session")
    assert "Address already in use" in line and "--zenoh-endpoint" in line
    assert ".rs:" not in line  # Zenoh's source locations are left out
    assert not (tmp_path / "adapter.log").exists()


def test_a_zenoh_endpoint_on_an_address_the_host_lacks_is_fatal(tmp_path: Path, notify) -> None:
    path, sock = notify
    cfg = site(
        tmp_path,
        zenoh="[zenoh]\nlisten = ['tcp/192.0.2.1:7447']",  # TEST-NET-1: never local
        modbus="[modbus]\nenabled = false",
    )
    out = run(cfg, path)
    line = assert_fatal(out, received(sock), "zenoh: cannot open the session")
    assert "this machine has no such address" in line


@pytest.mark.parametrize(
    ("endpoint", "reason"),
    [
        ("tcp/127.0.0.1:notaport", "'127.0.0.1:notaport' is not HOST:PORT"),
        ("foo/127.0.0.1:7447", "'foo' is not a Zenoh link protocol"),
    ],
)
def test_a_zenoh_endpoint_that_cannot_be_parsed_is_refused_by_check_and_run(
    tmp_path: Path, notify, endpoint: str, reason: str
) -> None:
    path, sock = notify
    cfg = site(
        tmp_path,
        zenoh=f"[zenoh]\nlisten = ['{endpoint}']",
        modbus="[modbus]\nenabled = false",
    )
    out = run(cfg, path)
    assert out.returncode == 2 and reason in out.stderr and "Traceback" not in out.stderr
    assert "READY=1" not in received(sock)
    cfg.write_text(cfg.read_text().replace(endpoint, zenoh_endpoint()))
    out = run(cfg, path, "--zenoh-endpoint", endpoint)
    assert out.returncode == 2 and reason in out.stderr and "Traceback" not in out.stderr


def test_the_bind_errors_name_their_fix() -> None:
    from gateway.modbus.server import bind_error

    denied = str(bind_error("0.0.0.0", 502, PermissionError(errno.EACCES, "Permission denied")))
    assert denied.startswith("modbus: cannot listen on 0.0.0.0:502: permission denied; ")
    assert "AmbientCapabilities=CAP_NET_BIND_SERVICE" in denied
    assert "CapabilityBoundingSet=CAP_NET_BIND_SERVICE" in denied and "--modbus-bind" in denied
    missing = str(bind_error("10.9.9.9", 1502, OSError(errno.EADDRNOTAVAIL, "x")))
    assert "this machine has no such address" in missing
    other = str(bind_error("h", 1, OSError(errno.ENETDOWN, "Network is down")))
    assert other.startswith("modbus: cannot listen on h:1: network is down; ")
