"""The demo gateway in the bench's own process, and what the loads benchmark reads of it.

:class:`Demo` copies config/demo.toml (and the EDS files beside it) into a temporary
directory, turns on commands from the web page (with the digest of a random token, which
nobody is told), moves the Zenoh endpoint, the Modbus server and the web page to free
loopback ports, and runs the real :class:`~gateway.runtime.daemon.Daemon` on the calling
asyncio loop: the python-can ``virtual`` channels of the DeviceNet and CANopen lines
reach only within one process, and the benchmark's CAN floods must reach them.

Each line's figures are read from its diagnostics: on the line's own loop when the daemon
runs it on a thread of its own (``call`` of the line, the reading time taken there), else
from the adapter itself. :class:`EventWatch` counts the hub's events; :func:`rss_mb` and
:class:`LogCapture` give the process's memory and what the gateway logs.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import math
import secrets
import shutil
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final

from tests.support.net import free_port

ROOT: Final = Path(__file__).resolve().parents[2]
DEMO: Final = ROOT / "config" / "demo.toml"
COUNTER_KEYS: Final = ("cycles", "poll_cycles", "syncs_tx")
"""A line's cycle counter, the first key its diagnostics have: the Profibus master's
cycles, the DeviceNet scanner's poll cycles, the CANopen master's SYNCs sent."""
DROP_KEYS: Final = ("restarts", "offline_count", "lost")
"""A drive's own count of its drops, the first key its entry has: a Profibus slave that
left data exchange, a DeviceNet node gone offline, a CANopen node whose heartbeat was lost."""
CALL_BOUND: Final = 2.0  # s a reading on a line's own loop may take before the snapshot serves
ONLINE_BOUND: Final = 90.0  # s for every drive of the demo to come online
STOP_BOUND: Final = 30.0  # s for the daemon to stop
EVENT_PERIOD: Final = 0.25  # s between two drains of the hub's events


@dataclass(frozen=True)
class Reading:
    """One line's counters at one time (``time.monotonic``)."""

    at: float
    cycles: int | None
    drops: int
    fresh: bool  # read on the line now (else its last snapshot)


def with_web_commands(text: str, digest: str) -> str:
    """The config text with ``commands = true`` and ``token_sha256`` in its ``[web]`` table
    (a table added if it has none)."""
    out: list[str] = []
    in_web = found = False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("["):
            in_web = stripped == "[web]"
            found = found or in_web
            out.append(line)
            if in_web:
                out += ["commands = true", f'token_sha256 = "{digest}"']
            continue
        key = stripped.split("=", 1)[0].strip()
        if in_web and key in ("commands", "token_sha256"):
            continue
        out.append(line)
    if not found:
        out += ["[web]", 'bind = "127.0.0.1:8080"', "commands = true", f'token_sha256 = "{digest}"']
    return "\n".join(out) + "\n"


def demo_copy(tmp: Path, digest: str) -> Path:
    """config/demo.toml with web commands on, and its EDS files, copied into ``tmp``."""
    eds = DEMO.parent / "eds"
    if eds.is_dir():
        shutil.copytree(eds, tmp / "eds")
    path = tmp / "demo.toml"
    path.write_text(with_web_commands(DEMO.read_text(), digest))
    return path


def _first_int(mapping: Any, keys: tuple[str, ...]) -> int | None:
    if not isinstance(mapping, dict):
        return None
    for key in keys:
        value = mapping.get(key)
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    return None


def counters(diag: dict[str, Any]) -> tuple[int | None, int]:
    """(the line's cycle counter or None, the sum of its drives' drop counts)."""
    drives = diag.get("drives", {})
    drops = 0
    if isinstance(drives, dict):
        drops = sum(_first_int(d, DROP_KEYS) or 0 for d in drives.values())
    return _first_int(diag, COUNTER_KEYS), drops


class Demo:
    """The demo gateway, in this process, on the running loop (see the module docstring)."""

    def __init__(self, tmp: Path) -> None:
        from gateway.config import load

        self.web, self.modbus, self.zenoh = free_port(), free_port(), free_port()
        self.path = demo_copy(tmp, hashlib.sha256(secrets.token_bytes(32)).hexdigest())
        config = load(self.path).with_overrides(
            zenoh_endpoint=f"tcp/127.0.0.1:{self.zenoh}",
            modbus_bind=f"127.0.0.1:{self.modbus}",
            web_bind=f"127.0.0.1:{self.web}",
        )
        # the loads are the web's, Modbus', Zenoh's and the buses'; the OPC UA server has
        # its own benchmark (bench/bench_opcua.py) and would hold the demo's fixed port
        self.config = replace(config, opcua=replace(config.opcua, enabled=False))
        self.daemon: Any = None
        self._task: asyncio.Task[int] | None = None

    @property
    def buses(self) -> list[str]:
        return [bus.name for bus in self.config.buses]

    def bus(self, adapter: str) -> Any:
        """The first bus of this adapter kind, or None."""
        return next((b for b in self.config.buses if b.adapter == adapter), None)

    async def start(self) -> None:
        """Run the daemon; return once every drive is online (an error after ONLINE_BOUND)."""
        from gateway.runtime.daemon import Daemon
        from gateway.runtime.systemd import Notifier

        self.daemon = Daemon(self.config, notifier=Notifier({}))
        self._task = asyncio.create_task(self.daemon.run(), name="bench-loads-daemon")
        deadline = time.monotonic() + ONLINE_BOUND
        while not self.all_online():
            if self._task.done():
                raise RuntimeError(f"the daemon ended at start: {self._task.result()}")
            if time.monotonic() > deadline:
                late = [s.id for s in self.daemon.hub.states() if not s.online]
                raise RuntimeError(f"not online within {ONLINE_BOUND:g} s: {late}")
            await asyncio.sleep(0.2)

    def all_online(self) -> bool:
        return all(s.online for s in self.daemon.hub.states())

    async def stop(self) -> None:
        """Stop the daemon (its own shutdown), bounded by STOP_BOUND."""
        task = self._task
        if self.daemon is None or task is None:
            return
        self.daemon.request_stop()
        with contextlib.suppress(Exception, asyncio.CancelledError):
            await asyncio.wait_for(task, STOP_BOUND)

    async def reading(self, bus: str) -> Reading:
        """The bus's counters now (see the module docstring)."""
        line = self.daemon.runtime.adapters.get(bus)
        if line is None:
            return Reading(time.monotonic(), None, 0, False)
        call = getattr(line, "call", None)
        adapter = getattr(line, "adapter", None)
        if callable(call) and adapter is not None:

            def now() -> tuple[float, dict[str, Any]]:
                return time.monotonic(), adapter.diagnostics()

            try:
                at, diag = await asyncio.wait_for(call(now), CALL_BOUND)
                return Reading(at, *counters(diag), True)
            except Exception:  # its loop busy or gone: its last snapshot
                pass
        diag = line.diagnostics()
        return Reading(time.monotonic(), *counters(diag), not callable(call))

    async def readings(self) -> dict[str, Reading]:
        return {bus: await self.reading(bus) for bus in self.buses}


def rate(before: Reading, after: Reading) -> float:
    """Cycles per second between two readings (NaN without a counter, or after a restart)."""
    if before.cycles is None or after.cycles is None or after.cycles < before.cycles:
        return math.nan
    return (after.cycles - before.cycles) / max(after.at - before.at, 1e-9)


class EventWatch:
    """Every hub event from now on, counted by kind; each drive that left online, kept."""

    def __init__(self, hub: Any) -> None:
        self._sub = hub.subscribe_events()
        self.kinds: Counter[str] = Counter()
        self.left_online: list[str] = []
        self._task = asyncio.create_task(self._drain_loop(), name="bench-loads-events")

    async def _drain_loop(self) -> None:
        while True:
            self.drain()
            await asyncio.sleep(EVENT_PERIOD)

    def drain(self) -> None:
        for event in self._sub.drain():
            kind = getattr(event.kind, "value", str(event.kind))
            self.kinds[kind] += 1
            if kind == "comm" and "online ->" in event.text:
                self.left_online.append(event.drive_id)

    def mark(self) -> tuple[Counter[str], int]:
        self.drain()
        return Counter(self.kinds), len(self.left_online)

    def since(self, mark: tuple[Counter[str], int]) -> tuple[dict[str, int], list[str]]:
        """(events by kind, the drives that left online) since ``mark``."""
        self.drain()
        kinds = self.kinds - mark[0]
        return dict(kinds), self.left_online[mark[1] :]

    async def close(self) -> None:
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        self._sub.close()


def rss_mb() -> float:
    """This process's resident memory (VmRSS), MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


class LogCapture:
    """The gateway's log (this process's root logger) into a file, at the config's level,
    as ``drive-gateway run`` writes it to its journal; its size read per load."""

    def __init__(self, path: Path, level: str) -> None:
        self.path = path
        self.level = getattr(logging, level, logging.INFO)

    @contextlib.contextmanager
    def installed(self) -> Iterator[LogCapture]:
        root = logging.getLogger()
        handler = logging.FileHandler(self.path)
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        kept = root.level, list(root.handlers)
        for old in kept[1]:
            root.removeHandler(old)
        root.addHandler(handler)
        root.setLevel(self.level)
        try:
            yield self
        finally:
            root.removeHandler(handler)
            handler.close()
            root.setLevel(kept[0])
            for old in kept[1]:
                root.addHandler(old)

    def size(self) -> int:
        try:
            return self.path.stat().st_size
        except OSError:
            return 0
