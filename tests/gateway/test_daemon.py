"""The daemon: in a subprocess with a fake NOTIFY_SOCKET, and in-process for supervision."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.config import load
from gateway.daemon import Daemon
from gateway.model import CommState
from gateway.systemd import Notifier

ROOT = Path(__file__).resolve().parents[2]
FAKE = "tests.support.fake_adapter:FakeAdapter"


def config_text(state_file: Path, crash_after: int = 0, start_running: bool = True) -> str:
    return f"""
[gateway]
shutdown_timeout = 5.0
[zenoh]
enabled = false
[modbus]
enabled = false
[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
crash_after = {crash_after}
state_file = "{state_file}"
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
ramp_time = 0.3
start_running = {"true" if start_running else "false"}
"""


def recv_until(sock: socket.socket, wanted: str) -> list[str]:
    got: list[str] = []
    while True:
        msg = sock.recv(4096).decode()
        got.extend(msg.split("\n"))
        if wanted in got:
            return got


@pytest.fixture
def notify_socket(tmp_path: Path):
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(30)
    yield path, sock
    sock.close()


def test_daemon_ready_then_sigterm_applies_on_shutdown(tmp_path: Path, notify_socket) -> None:
    path, sock = notify_socket
    state_file = tmp_path / "adapter.log"
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(state_file))
    env = {**os.environ, "NOTIFY_SOCKET": str(path), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway", "run", "--config", str(cfg)],
        env=env,
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        ready = recv_until(sock, "READY=1")
        assert any(line.startswith("STATUS=1 drive(s)") for line in ready)
        proc.send_signal(signal.SIGTERM)
        assert "STOPPING=1" in recv_until(sock, "STOPPING=1")
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "gateway shutting down: ramp_stop applied" in err
    assert "all drives stopped" in err
    lines = state_file.read_text().splitlines()
    # the drive was stopped by on_shutdown before the adapter left the bus
    assert lines == ["started", "d1 stopped", "left the bus"]


def test_bad_config_exits_2_naming_the_key(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[modbus]\nbind = 'nowhere'\n")
    proc = subprocess.run(
        [sys.executable, "-m", "gateway", "run", "--config", str(cfg)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert proc.returncode == 2
    assert f"{cfg}: modbus.bind: 'nowhere' is not HOST:PORT" in proc.stderr


async def test_crashed_adapter_is_restarted_and_its_drives_go_offline(tmp_path: Path) -> None:
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(tmp_path / "log", crash_after=5, start_running=False))
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    comm: list[CommState] = []
    task = asyncio.create_task(daemon.run())
    with daemon.hub.subscribe_states() as sub:
        while daemon.runtime.restarts.get("bus line1", 0) < 2 or comm[-1:] != [CommState.ONLINE]:
            state = await asyncio.wait_for(sub.get(), 10)
            if not comm or comm[-1] is not state.comm:
                comm.append(state.comm)
    daemon.request_stop()
    assert await asyncio.wait_for(task, 10) == 0
    assert comm.count(CommState.OFFLINE) >= 2  # offline while the adapter was down
    assert comm[-1] is CommState.ONLINE  # and back after each restart
