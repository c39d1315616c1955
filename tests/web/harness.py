"""What the web tests share: the demo daemon in-process with its web front end on a free
loopback port, a small runtime of test drives (no bus) for the security and escaping
tests, and an HTTP client.

The demo daemon is the one `make run` starts (config/demo.toml) with its ports moved to
free ones: the test's Zenoh client listens and the daemon connects to it, as in
tests/e2e/harness.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import aiohttp

from gateway.access.users import User
from gateway.config import DEFAULT_CONFIG, Config, load
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState, DriveStatus
from gateway.runtime.daemon import READY_BOUND, Daemon, Runtime
from gateway.runtime.linethread import LineThread
from gateway.runtime.systemd import Notifier
from gateway.web.frontend import WebFrontEnd
from gateway.webconfig import WebSection
from tests.support.net import free_port, zenoh_endpoint
from tests.support.timing import scaled
from tests.zenoh.client import Client

T = TypeVar("T")

TIMEOUT = scaled(30.0)
PREFIX = "demo"
DEMO_DRIVES = ("cfw11", "cfw700", "cfw320", "mcd600", "cfw08", "cia402a", "cia402b")
TOKEN = "correct horse battery staple"
TOKEN_SHA256 = hashlib.sha256(TOKEN.encode()).hexdigest()
ROOT = Path(__file__).resolve().parents[2]
ARTEFACTS = ROOT / "artefacts" / "web"
"""Screenshots of the page (git-ignored)."""


def web_section(**changes: Any) -> WebSection:
    return replace(WebSection(enabled=True, host="127.0.0.1", port=0), **changes)


@dataclass
class Demo:
    daemon: Daemon
    client: Client
    http: aiohttp.ClientSession

    @property
    def web(self) -> WebFrontEnd:
        front_end = self.daemon.front_ends["web"]
        assert isinstance(front_end, WebFrontEnd)
        return front_end

    @property
    def url(self) -> str:
        return self.web.url

    async def command(self, drive: str, payload: dict[str, Any]) -> None:
        """A Zenoh command query the gateway must accept."""
        reply = await self.client.aone(f"{PREFIX}/drives/{drive}/command", payload)
        assert reply.json() == {"accepted": True}, reply.json()

    async def wait_for(self, drive: str, predicate: Any) -> DriveState:
        return await asyncio.wait_for(self.daemon.hub.wait_for(drive, predicate), TIMEOUT)

    def line(self, bus: str) -> LineThread:
        """The bus's line as the daemon runs it (its figures, ``call`` onto its loop)."""
        return self.daemon.runtime.adapters[bus]

    def adapter(self, bus: str) -> Any:
        """The bus's adapter (it runs on its line's own loop: read it, poke it through
        :meth:`on_line`)."""
        return self.line(bus).adapter

    async def on_line(self, bus: str, fn: Callable[[], T]) -> T:
        """``fn()`` run on the bus's line (its own thread and loop), its result: how a test
        changes a simulated device without racing the line."""
        return await self.line(bus).call(fn)


def demo_config(client_endpoint: str, web: WebSection | None = None) -> Config:
    config = load(DEFAULT_CONFIG).with_overrides(
        zenoh_endpoint=zenoh_endpoint(), modbus_bind=f"127.0.0.1:{free_port()}"
    )
    return replace(
        config,
        zenoh=replace(config.zenoh, connect=(client_endpoint,)),
        web=web or replace(config.web, host="127.0.0.1", port=0),
        # the demo's history is the user's file: the web tests keep none (tests/history)
        history=replace(config.history, enabled=False),
        opcua=replace(config.opcua, enabled=False),  # tests/opcua has its own daemon tests
    )


@contextlib.asynccontextmanager
async def demo_daemon(web: WebSection | None = None) -> AsyncIterator[Demo]:
    """The demo daemon, its web front end serving; yields once every drive is online."""
    client_endpoint = zenoh_endpoint()
    client = Client(client_endpoint, asyncio.get_running_loop(), listen=True)
    daemon = Daemon(demo_config(client_endpoint, web), notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    http = aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=TIMEOUT))
    try:
        await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
        for drive in DEMO_DRIVES:
            await asyncio.wait_for(daemon.hub.wait_for(drive, lambda s: s.online), TIMEOUT)
        yield Demo(daemon, client, http)
    finally:
        await http.close()
        daemon.request_stop()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, 15)
        client.close()


@dataclass
class Small:
    """A runtime of test drives, online, with no bus: the web front end alone."""

    runtime: Runtime
    web: WebFrontEnd
    http: aiohttp.ClientSession

    @property
    def hub(self) -> Hub:
        return self.runtime.hub

    @property
    def url(self) -> str:
        return self.web.url


@contextlib.asynccontextmanager
async def small_gateway(
    web: WebSection,
    drives: tuple[str, ...] = ("d1", "d2"),
    users: tuple[User, ...] = (),
    **state: Any,
) -> AsyncIterator[Small]:
    hub = Hub()
    for i, drive in enumerate(drives):
        hub.add_drive(DriveState(id=drive, device=Device.TEST, bus="line", address=i + 1))
        hub.update(drive, comm=CommState.ONLINE, status=DriveStatus.READY, **state)
    runtime = Runtime(config=Config(file="test.toml", web=web, users=users), hub=hub)
    front_end = WebFrontEnd(runtime)
    runtime.front_ends["web"] = front_end
    task = asyncio.create_task(front_end.run())
    http = aiohttp.ClientSession(
        timeout=aiohttp.ClientTimeout(total=TIMEOUT),
        cookie_jar=aiohttp.CookieJar(unsafe=True),  # cookies of an address (127.0.0.1)
        connector=aiohttp.TCPConnector(ssl=False),  # a test's self-signed certificate
    )
    try:
        ready = asyncio.create_task(front_end.ready.wait())
        done, _ = await asyncio.wait({ready, task}, timeout=TIMEOUT, return_when="FIRST_COMPLETED")
        if task in done:
            ready.cancel()
            task.result()
        assert ready in done, "the web front end does not serve"
        yield Small(runtime, front_end, http)
    finally:
        await http.close()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
