"""The daemon and a line another master holds (LineHeld): refused at start with one line
and exit status 75; met again after a restart, logged in one line and retried."""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import ClassVar

import pytest

from gateway.adapter import HubPort
from gateway.config import load
from gateway.errors import LineHeld
from gateway.model import CommState
from gateway.runtime.daemon import EXIT_LINE_HELD, Daemon
from gateway.runtime.systemd import Notifier
from tests.support.fake_adapter import FakeAdapter

HELD = "serial port /dev/ttyTEST is held by pid 1 (init): another master is on this line"


class HeldAdapter(FakeAdapter):
    """The fake adapter, whose runs raise ``plan``'s errors in turn, then run."""

    plan: ClassVar[list[Exception]] = []

    async def run(self, hub: HubPort) -> None:
        if HeldAdapter.plan:
            raise HeldAdapter.plan.pop(0)
        await super().run(hub)


CONFIG = """
[zenoh]
enabled = false
[modbus]
enabled = false
[buses.line1]
adapter = "held"  # tests/support/site: an entry point
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
"""


def errors(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.levelno >= logging.ERROR]


async def test_a_line_held_at_start_stops_the_daemon_with_75(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(HeldAdapter, "plan", [LineHeld(HELD)])
    cfg = tmp_path / "site.toml"
    cfg.write_text(CONFIG)
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    assert await asyncio.wait_for(daemon.run(), 30) == EXIT_LINE_HELD
    (record,) = errors(caplog)
    assert record.exc_info is None  # one line, no traceback
    assert (
        record.getMessage() == f"bus line1: {HELD}; drive-gateway does not start (exit status 75)"
    )
    assert not daemon.ready.is_set() and not daemon.runtime.restarts


async def test_a_line_held_after_a_restart_is_retried(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(HeldAdapter, "plan", [RuntimeError("crash (test)"), LineHeld(HELD)])
    cfg = tmp_path / "site.toml"
    cfg.write_text(CONFIG)
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    try:
        await asyncio.wait_for(daemon.hub.wait_for("d1", lambda s: s.comm is CommState.ONLINE), 30)
    finally:
        daemon.request_stop()
        status = await asyncio.wait_for(task, 30)
    assert status == 0 and daemon.runtime.restarts == {"bus line1": 2}
    crashed, held = errors(caplog)
    assert crashed.exc_info is not None  # a crash keeps its traceback
    assert held.exc_info is None and held.getMessage().startswith(f"bus line1: {HELD}; retrying in")
