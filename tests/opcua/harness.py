"""The daemon in-process with an OPC UA server on a free loopback port, test drives on the
fake adapter (tests/support/fake_adapter.py) and a history store of made-up rows: what the
OPC UA end-to-end tests (asyncua's client here, node-opcua's in its own process) share."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway.config import load
from gateway.model import DriveState
from gateway.runtime.daemon import READY_BOUND, Daemon
from gateway.runtime.systemd import Notifier
from tests.support.net import free_port
from tests.support.timing import scaled

TIMEOUT = scaled(30.0)
DRIVES = ("m1", "m2", "soft")
HISTORY_START = 1_700_000_000.0
HISTORY_ROWS = 50
HISTORY_EVENTS = 30


@dataclass(frozen=True)
class Row:
    t: float
    values: Mapping[str, float | None]


@dataclass(frozen=True)
class StoredEvent:
    t: float
    drive_id: str
    kind: str
    text: str


@dataclass
class FakeHistory:
    """A history store of made-up rows: speed_rpm = 10 * i at HISTORY_START + i."""

    calls: list[tuple[str, float, float, float | None]] = field(default_factory=list)
    counters: None = None  # no writer here (a store's counters in /metrics)
    event_calls: list[tuple[str | None, float, float, int | None, bool]] = field(
        default_factory=list
    )

    def readings(
        self, drive_id: str, start: float, end: float, step: float | None = None
    ) -> list[Row]:
        self.calls.append((drive_id, start, end, step))
        rows = [
            Row(HISTORY_START + i, {"speed_rpm": 10.0 * i, "current_a": None})
            for i in range(HISTORY_ROWS)
        ]
        return [r for r in rows if start <= r.t <= end]

    def events(
        self,
        drive_id: str | None,
        start: float,
        end: float,
        limit: int | None = None,
        newest: bool = False,
    ) -> list[StoredEvent]:
        """m1: a fault at HISTORY_START + 10 * i, commands between; m2: 5 commands."""
        self.event_calls.append((drive_id, start, end, limit, newest))
        made = [
            StoredEvent(HISTORY_START + i, "m1", "fault" if i % 10 == 0 else "command", f"m1 {i}")
            for i in range(HISTORY_EVENTS)
        ] + [StoredEvent(HISTORY_START + i + 0.5, "m2", "command", f"m2 {i}") for i in range(5)]
        found = sorted(
            (e for e in made if start <= e.t < end and drive_id in (None, e.drive_id)),
            key=lambda e: e.t,
            reverse=newest,
        )
        return found if limit is None else found[: limit + 1]


def config_text(
    port: int,
    *,
    command_timeout: float = 0.0,
    security: str = '["none"]',
    extra: str = "",
    extra_root: str = "",
) -> str:
    timeout = f"command_timeout = {command_timeout}\n" if command_timeout else ""
    return f"""{extra_root}
[gateway]
shutdown_timeout = 3.0
tick = 0.01
[zenoh]
enabled = false
[modbus]
enabled = false
[opcua]
bind = "127.0.0.1:{port}"
security = {security}
publish_interval = 0.05
{extra}
[buses.line1]
adapter = "fake"
cycle = 0.02

[[buses.line1.drives]]
id = "m1"
device = "test"
address = 1
ramp_time = 0.2
{timeout}
[[buses.line1.drives]]
id = "m2"
device = "test"
address = 2
control = "modbus"

[[buses.line1.drives]]
id = "soft"
device = "MCD 600"
address = 3
"""


@dataclass
class Gateway:
    daemon: Daemon
    endpoint: str
    history: FakeHistory

    async def wait_for(self, drive: str, predicate: object) -> DriveState:
        return await asyncio.wait_for(
            self.daemon.hub.wait_for(drive, predicate),  # type: ignore[arg-type]
            TIMEOUT,
        )

    def adapter(self) -> object:
        return self.daemon.runtime.adapters["line1"].adapter


@contextlib.asynccontextmanager
async def running_gateway(
    tmp_path: Path, fake_history: bool = True, **kwargs: Any
) -> AsyncIterator[Gateway]:
    """``fake_history``: the made-up rows of :class:`FakeHistory` (False: the daemon's own
    store, as its config has it)."""
    port = free_port()
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(config_text(port, **kwargs))
    config = load(cfg)
    daemon = Daemon(config, notifier=Notifier({}))
    history = FakeHistory()
    if fake_history:
        daemon.runtime.history = history  # type: ignore[assignment]  # a fake of the store
    task = asyncio.create_task(daemon.run())
    try:
        await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
        for drive in DRIVES:
            await asyncio.wait_for(daemon.hub.wait_for(drive, lambda s: s.online), TIMEOUT)
        yield Gateway(daemon, config.opcua.endpoint, history)
    finally:
        daemon.request_stop()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, 15)
        # asyncua fills its standard address space in the loop's default executor: its idle
        # worker thread is ended here, as asyncio.run ends it when the daemon exits
        await asyncio.get_running_loop().shutdown_default_executor()
