"""The daemon in-process with simulated devices, driven through a real Zenoh session and
a real Modbus TCP client (the harness every end-to-end test shares).

The test's Zenoh client listens and the daemon connects to it as it starts, so no retry
wait slows the start; the daemon's own endpoint is a free loopback port.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from pymodbus.client import AsyncModbusTcpClient

from adapters.profibus.sim.slave import SlaveCounters
from gateway.config import load
from gateway.model import DriveState
from gateway.runtime.daemon import READY_BOUND, Daemon
from gateway.runtime.linethread import LineThread
from gateway.runtime.systemd import Notifier
from tests.support.heard import Heard
from tests.support.net import free_port, zenoh_endpoint
from tests.support.timing import scaled
from tests.zenoh.client import Client

T = TypeVar("T")

PREFIX = "e2e"
TIMEOUT = scaled(30.0)  # a bound on waits for events: tests/support/timing.py
RUN, REVERSE, RESET, QUICK_STOP, COAST_STOP = 0x01, 0x02, 0x04, 0x08, 0x10  # docs/modbus-map.md


def header(
    modbus_port: int, client_endpoint: str, tick: float = 0.01, shutdown_timeout: float = 3.0
) -> str:
    """The [gateway], [zenoh] and [modbus] tables of an end-to-end config."""
    return f"""
[gateway]
shutdown_timeout = {shutdown_timeout}
tick = {tick}
[zenoh]
prefix = "{PREFIX}"
heartbeat = 0.2
connect = ["{client_endpoint}"]
multicast_scouting = false
[modbus]
bind = "127.0.0.1:{modbus_port}"
allow = ["127.0.0.0/8"]
"""


# The simulated Profibus line of the end-to-end suites: 1.5 Mbit/s on a pty, timings short
# enough for seconds-long tests, the live list off.
_SIM_PROFIBUS = """adapter = "profibus"
simulate = true
baudrate = 1500000
watchdog = 0.5
latency = 0.02
cycle_time = 0.002
absent_retry = 0.1
fault_retry = 0.2
"""


def simulated_profibus(bus: str, **extra: float) -> str:
    """The ``[buses.<bus>]`` table of a simulated Profibus line (``extra``: more keys)."""
    more = "".join(f"{key} = {value}\n" for key, value in extra.items())
    return f"\n[buses.{bus}]\n{_SIM_PROFIBUS}{more}live_list_period = 0.0\n"


async def exchanges(counters: SlaveCounters, n: int) -> None:
    """Until a simulated slave has exchanged ``n`` more telegrams with the master."""
    target = counters.exchanges + n
    with Heard(counters) as heard:
        async with asyncio.timeout(TIMEOUT):
            await heard.until(lambda: counters.exchanges >= target)


def parsed(sample: Any) -> DriveState:
    return DriveState.from_json(sample.json())


@dataclass
class Gateway:
    daemon: Daemon
    client: Client
    modbus: AsyncModbusTcpClient

    def line(self, bus: str) -> LineThread:
        """The bus's line as the daemon runs it (its figures, ``call`` onto its loop)."""
        return self.daemon.runtime.adapters[bus]

    def adapter(self, bus: str) -> Any:
        """The bus's adapter (it runs on its line's own loop: read it, poke it through
        ``line(bus).call``)."""
        return self.line(bus).adapter

    async def on_line(self, bus: str, fn: Callable[[], T]) -> T:
        """``fn()`` run on the bus's line (its own thread and loop), its result: how a test
        changes a simulated device or the adapter without racing the line."""
        return await self.line(bus).call(fn)

    async def diagnostics(self, bus: str) -> dict[str, Any]:
        """The bus adapter's figures as they are now, made on its line (the line's own
        ``diagnostics()`` is a snapshot up to 0.25 s old)."""
        adapter = self.adapter(bus)
        figures: dict[str, Any] = await self.on_line(bus, adapter.diagnostics)
        return figures

    def state_key(self, drive: str) -> str:
        return f"{PREFIX}/drives/{drive}/state"

    async def command(self, drive: str, payload: dict[str, Any]) -> None:
        """A command query that the gateway must accept."""
        reply = await self.client.aone(f"{PREFIX}/drives/{drive}/command", payload)
        assert reply.json() == {"accepted": True}, reply.json()

    async def refused(self, drive: str, payload: dict[str, Any]) -> str:
        """A command query that the gateway must refuse: its reason."""
        reply = await self.client.aone(f"{PREFIX}/drives/{drive}/command", payload)
        answer = reply.json()
        assert answer["accepted"] is False, answer
        reason: str = answer["error"]
        return reason

    async def param(self, drive: str, number: int, payload: Any = None) -> Any:
        """A params query: (ok, the JSON reply)."""
        reply = await self.client.aone(f"{PREFIX}/drives/{drive}/params/{number}", payload)
        return reply.ok, reply.json()

    async def inputs(self, unit: int, count: int = 21) -> list[int]:
        rr = await self.modbus.read_input_registers(0, count=count, device_id=unit)
        assert not rr.isError(), rr
        return list(rr.registers)

    async def write(self, unit: int, address: int, value: int) -> None:
        rr = await self.modbus.write_register(address, value, device_id=unit)
        assert not rr.isError(), rr

    async def wait_for(
        self, drive: str, predicate: Callable[[DriveState], bool], within: float = TIMEOUT
    ) -> DriveState:
        """The hub's state of ``drive`` once ``predicate`` holds."""
        return await asyncio.wait_for(self.daemon.hub.wait_for(drive, predicate), within)


async def for_each(
    items: Iterable[T], name: Callable[[T], str], check: Callable[[T], Awaitable[None]]
) -> None:
    """``check`` every item at once (several drives of one gateway); a failure names its
    item (the first failure is raised, the others are cancelled)."""

    async def one(item: T) -> None:
        try:
            await check(item)
        except Exception as exc:
            raise AssertionError(f"{name(item)}: {type(exc).__name__}: {exc}") from exc

    async with asyncio.TaskGroup() as group:
        for item in items:
            group.create_task(one(item))


@contextlib.asynccontextmanager
async def running_gateway(
    tmp_path: Path,
    buses: Callable[[], str],
    drives: list[str],
    tick: float = 0.01,
    shutdown_timeout: float = 3.0,
) -> AsyncIterator[Gateway]:
    """Start the daemon on ``header + buses()``; yield once every drive in ``drives`` is online."""
    cfg = tmp_path / "gateway.toml"
    modbus_port = free_port()
    client_endpoint = zenoh_endpoint()
    client = Client(client_endpoint, asyncio.get_running_loop(), listen=True)
    cfg.write_text(header(modbus_port, client_endpoint, tick, shutdown_timeout) + buses())
    config = load(cfg).with_overrides(zenoh_endpoint=zenoh_endpoint())
    daemon = Daemon(config, notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    modbus = AsyncModbusTcpClient(
        "127.0.0.1", port=modbus_port, reconnect_delay=0, retries=0, timeout=TIMEOUT
    )
    try:
        with client.liveliness(f"{PREFIX}/gateway") as live:
            await live.auntil(lambda g: g.put, TIMEOUT)
        # READY: every front end serves (or the daemon gave up waiting and says which not)
        await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
        assert await modbus.connect(), "the Modbus front end does not accept a connection"
        for drive in drives:
            await asyncio.wait_for(daemon.hub.wait_for(drive, lambda s: s.online), TIMEOUT)
        yield Gateway(daemon, client, modbus)
    finally:
        modbus.close()
        daemon.request_stop()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, shutdown_timeout + 10)
        client.close()
