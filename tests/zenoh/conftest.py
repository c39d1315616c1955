"""The gateway under test: in a subprocess (``python -m gateway run``) or in-process."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.net import free_port, zenoh_endpoint
from tests.support.plugins import pythonpath
from tests.zenoh.client import Client

ROOT = Path(__file__).resolve().parents[2]
FAKE = "fake"  # tests/support/plugins.py
PREFIX = "demo"
HEARTBEAT = 0.2
READY_LINE = " running: "  # the daemon's READY line: front ends serve, buses started


def gateway_config(heartbeat: float = HEARTBEAT, connect: str | None = None) -> str:
    """Three fake drives: d1 and d2 turn (test device), soft is an MCD 600 soft starter."""
    endpoints = f'["{connect}"]' if connect else "[]"
    return f"""
[gateway]
shutdown_timeout = 2.0
[zenoh]
prefix = "{PREFIX}"
heartbeat = {heartbeat}
connect = {endpoints}
multicast_scouting = false
[modbus]
enabled = false
[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
ramp_time = 0.2
writable_params = [100, 101]
[[buses.line1.drives]]
id = "d2"
device = "test"
address = 4
writable_params = [100, 101]
[[buses.line1.drives]]
id = "soft"
device = "MCD 600"
address = 5
"""


class GatewayProcess:
    """``python -m gateway run`` in a subprocess; its stderr is read by a thread."""

    def __init__(self, config: Path, endpoint: str) -> None:
        self.endpoint = endpoint
        env = {**os.environ, "PYTHONPATH": pythonpath()}
        env.pop("NOTIFY_SOCKET", None)
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "gateway",
                "run",
                "--config",
                str(config),
                "--zenoh-endpoint",
                endpoint,
                "--modbus-bind",
                f"127.0.0.1:{free_port()}",
            ],
            cwd=ROOT,
            env=env,
            stdin=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.log: list[str] = []
        self._reader = threading.Thread(target=self._read, name="gateway-stderr", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.log.append(line)
            self.lines.put(line)
        self.lines.put("")  # end of output

    def wait_for_line(self, text: str, timeout: float = 20.0) -> str:
        while True:
            line = self.lines.get(timeout=timeout)
            if not line:
                raise AssertionError(f"gateway exited before {text!r}:\n{''.join(self.log)}")
            if text in line:
                return line

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        self._reader.join(5)
        return code

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()
        self._reader.join(5)


def start_gateway(tmp: Path, heartbeat: float = HEARTBEAT) -> GatewayProcess:
    cfg = tmp / "gateway.toml"
    cfg.write_text(gateway_config(heartbeat))
    gw = GatewayProcess(cfg, zenoh_endpoint())
    try:
        gw.wait_for_line(READY_LINE)
    except BaseException:
        gw.kill()
        raise
    return gw


@pytest.fixture(scope="module")
def gateway(tmp_path_factory: pytest.TempPathFactory) -> Iterator[GatewayProcess]:
    """One gateway process shared by a module's tests (each test uses its own drives)."""
    gw = start_gateway(tmp_path_factory.mktemp("gw"))
    yield gw
    code = gw.stop()
    assert code == 0, "".join(gw.log)


@pytest.fixture(scope="module")
def client(gateway: GatewayProcess) -> Iterator[Client]:
    """A client session connected to the shared gateway, once its token is seen."""
    c = Client(gateway.endpoint)
    try:
        with c.liveliness(f"{PREFIX}/gateway") as live:
            live.until(lambda s: s.put, timeout=10)
        yield c
    finally:
        c.close()
