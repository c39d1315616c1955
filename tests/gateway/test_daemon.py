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
from gateway.model import CommState
from gateway.runtime.daemon import Backoff, Daemon
from gateway.runtime.systemd import Notifier
from tests.support.net import free_port, zenoh_endpoint
from tests.support.plugins import pythonpath

ROOT = Path(__file__).resolve().parents[2]
FAKE = "fake"  # tests/support/plugins.py


def config_text(
    state_file: Path,
    crash_after: int = 0,
    start_running: bool = True,
    stuck: bool = False,
    shutdown_timeout: float = 5.0,
) -> str:
    return f"""
[gateway]
shutdown_timeout = {shutdown_timeout}
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
stuck = {"true" if stuck else "false"}
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


def start_daemon(cfg: Path, notify: Path, **env_extra: str) -> subprocess.Popen[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("WATCHDOG_")}
    env.update(NOTIFY_SOCKET=str(notify), PYTHONPATH=pythonpath(), **env_extra)
    return subprocess.Popen(
        [sys.executable, "-m", "gateway", "run", "--config", str(cfg)],
        env=env,
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_daemon_ready_then_signal_applies_on_shutdown(
    tmp_path: Path, notify_socket, sig: signal.Signals
) -> None:
    """SIGTERM (systemd) and SIGINT (Ctrl-C on `make run`) shut down the same way."""
    path, sock = notify_socket
    state_file = tmp_path / "adapter.log"
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(state_file))
    proc = start_daemon(cfg, path)
    try:
        ready = recv_until(sock, "READY=1")
        assert any(line.startswith("STATUS=1 drive(s)") for line in ready)
        proc.send_signal(sig)
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


def test_shutdown_is_bounded_when_a_drive_does_not_stop(tmp_path: Path, notify_socket) -> None:
    """A drive deaf to the stop: the daemon waits shutdown_timeout, leaves the bus, exits 0."""
    path, sock = notify_socket
    state_file = tmp_path / "adapter.log"
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(state_file, stuck=True, shutdown_timeout=0.5))
    proc = start_daemon(cfg, path)
    try:
        recv_until(sock, "READY=1")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "gateway shutting down: ramp_stop applied" in err
    assert "shutdown bound 0.5 s reached; still running: ['d1']" in err
    assert "still turning" in err and "the drive's own reaction to a lost master" in err
    assert "all drives stopped" not in err
    assert state_file.read_text().splitlines() == ["started", "left the bus"]


def test_watchdog_keepalives_follow_watchdog_usec(tmp_path: Path, notify_socket) -> None:
    """WATCHDOG=1 is sent (at half of WATCHDOG_USEC) from start-up until STOPPING=1."""
    path, sock = notify_socket
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(tmp_path / "log", start_running=False))
    proc = start_daemon(cfg, path, WATCHDOG_USEC="200000")  # a keep-alive every 0.1 s
    try:
        got = recv_until(sock, "READY=1")
        while got.count("WATCHDOG=1") < 3:
            got.extend(recv_until(sock, "WATCHDOG=1"))
        proc.send_signal(signal.SIGTERM)
        recv_until(sock, "STOPPING=1")
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err


def test_backoff_doubles_to_the_longest_and_resets_after_a_good_run() -> None:
    backoff = Backoff(first=0.5, longest=30.0)
    pauses = [backoff.after_crash(ran_for=0.1) for _ in range(9)]
    assert pauses == [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0, 30.0]
    assert backoff.after_crash(ran_for=31.0) == 0.5  # it ran well for a while: start over
    assert backoff.after_crash(ran_for=0.1) == 1.0


async def test_a_crash_is_logged_with_its_traceback_and_restarted_after_the_backoff(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    pauses: list[float] = []

    class Recorded(Backoff):
        def after_crash(self, ran_for: float) -> float:
            pauses.append(super().after_crash(ran_for))
            return 0.0  # the test does not wait for the real pauses

    monkeypatch.setattr("gateway.runtime.daemon.Backoff", Recorded)
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(tmp_path / "log", crash_after=2, start_running=False))
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    with daemon.hub.subscribe_states() as sub:
        while daemon.runtime.restarts.get("bus line1", 0) < 3:
            await asyncio.wait_for(sub.get(), 10)
    daemon.request_stop()
    assert await asyncio.wait_for(task, 10) == 0
    assert pauses[:3] == [0.5, 1.0, 2.0]
    crashes = [r for r in caplog.records if "bus line1 crashed; restarting in" in r.getMessage()]
    assert crashes and crashes[0].exc_info is not None
    assert "fake adapter crash (test)" in caplog.text


async def test_ready_waits_for_the_front_ends_to_serve(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """READY means serving: the Modbus and Zenoh front ends listen when it is sent; with
    no drives configured the gateway still starts, serves and says so."""
    cfg = tmp_path / "site.toml"
    cfg.write_text("[zenoh]\nprefix = 't'\n[modbus]\nallow = ['127.0.0.1/32']\n")
    config = load(cfg).with_overrides(zenoh_endpoint(), f"127.0.0.1:{free_port()}")
    sent: list[str] = []

    class Recording(Notifier):
        def notify(self, *lines: str) -> bool:
            sent.extend(lines)
            return True

    daemon = Daemon(config, notifier=Recording({}))
    task = asyncio.create_task(daemon.run())
    try:
        await asyncio.wait_for(daemon.ready.wait(), 30)
        assert sent[:2] == ["READY=1", "STATUS=0 drive(s) on 0 bus(es)"]
        for name in ("zenoh", "modbus"):
            assert daemon.front_ends[name].ready.is_set(), name  # type: ignore[attr-defined]
        # serving: the gateway unit answers at once
        reader, writer = await asyncio.open_connection(config.modbus.host, config.modbus.port)
        writer.write(bytes.fromhex("0001 0000 0006 00 04 0005 0001"))
        reply = await asyncio.wait_for(reader.readexactly(11), 10)
        writer.close()
        await writer.wait_closed()
        assert reply == bytes.fromhex("0001 0000 0005 00 04 02 0000")  # 0 drives configured
    finally:
        daemon.request_stop()
        assert await asyncio.wait_for(task, 30) == 0
    assert "no drives are configured" in caplog.text


async def test_a_front_end_that_cannot_bind_stops_the_start_without_ready(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Used to report READY after READY_BOUND and retry the bind for ever (issue 18)."""
    monkeypatch.setattr("gateway.runtime.daemon.READY_BOUND", 0.5)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cfg = tmp_path / "site.toml"
        cfg.write_text(f"[zenoh]\nenabled = false\n[modbus]\nbind = '127.0.0.1:{port}'\n")
        sent: list[str] = []

        class Recording(Notifier):
            def notify(self, *lines: str) -> bool:
                sent.extend(lines)
                return True

        daemon = Daemon(load(cfg), notifier=Recording({}))
        assert await asyncio.wait_for(daemon.run(), 30) == 2
    assert "READY=1" not in sent and not daemon.ready.is_set()
    assert sent[0].startswith(f"STATUS=cannot start: modbus: cannot listen on 127.0.0.1:{port}")
    assert daemon.runtime.restarts.get("modbus front end", 0) == 0
