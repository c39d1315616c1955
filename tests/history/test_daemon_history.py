"""The history in the daemon (in-process, a fake bus, no front end): a corrupt file moved
aside is told in every drive's events; the recorder samples the drives and records their
events, and the last ones are written at shutdown."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from gateway.adapter import EventKind
from gateway.config import load
from gateway.history.store import HistoryStore
from gateway.runtime.daemon import Daemon
from gateway.runtime.systemd import Notifier
from tests.gateway.test_daemon import config_text
from tests.reliability.demo import until
from tests.support.timing import scaled

TIMEOUT = scaled(30.0)


def history_section(path: Path) -> str:
    return f'\n[history]\nenabled = true\npath = "{path}"\nperiod = 0.05\nbatch_interval = 0.05\n'


async def test_a_corrupt_file_is_moved_aside_and_said_in_every_drives_events(
    tmp_path: Path,
) -> None:
    path = tmp_path / "history.sqlite"
    path.write_bytes(b"\x00garbage, no SQLite header\x00" * 200)
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(tmp_path / "log", start_running=False) + history_section(path))
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    store = HistoryStore(path)
    with daemon.hub.subscribe_events() as events:
        task = asyncio.create_task(daemon.run())
        try:
            async with asyncio.timeout(TIMEOUT):
                while True:
                    ev = await events.get()
                    if ev.kind is EventKind.CONFIG and "history database" in ev.text:
                        break
                await daemon.hub.wait_for("d1", lambda s: s.online)
                await until(lambda: bool(store.readings("d1", 0, time.time() + 60)))
        finally:
            daemon.request_stop()
            assert await asyncio.wait_for(task, TIMEOUT) == 0
    assert ev.drive_id == "d1"
    assert "moved aside to history.sqlite.corrupt-" in ev.text
    moved = Path(ev.data["moved_to"])
    assert moved.read_bytes().startswith(b"\x00garbage")  # noqa: ASYNC240
    texts = [e.text for e in store.events("d1", 0, time.time() + 60)]
    assert any("moved aside" in t for t in texts)
    assert any("gateway shutting down" in t for t in texts)  # written at shutdown
