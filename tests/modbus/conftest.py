"""A running gateway (in-process daemon, fake drives) with the Modbus front end on loopback."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient

from gateway.config import load
from gateway.hub import Hub
from gateway.modbus.frontend import ModbusFrontEnd
from gateway.model import DriveState
from gateway.runtime.daemon import Daemon
from gateway.runtime.systemd import Notifier
from tests.support.fake_adapter import FakeAdapter
from tests.support.net import free_port
from tests.support.timing import scaled

FAKE = "fake"  # tests/support/plugins.py
TIMEOUT = scaled(20.0)
INPUTS = 21  # registers in a drive's status block
D1, D2, D4 = 1, 2, 4  # unit ids: d1 test drive, d2 MCD 600, d4 on line2 (d3 has none)


def config_text(
    port: int,
    *,
    control: str = "any",
    read_only: bool = False,
    allow: Sequence[str] = ("127.0.0.0/8",),
    command_timeout: float = 0.0,
    gateway_unit: int = 0,
    modbus_enabled: bool = False,
    frame_timeout: float | None = None,
    max_connections: int | None = None,
    idle_timeout: float | None = None,
    max_connections_per_peer: int | None = None,
) -> str:
    allow_list = ", ".join(f'"{a}"' for a in allow)
    limits = "".join(
        f"{key} = {value}\n"
        for key, value in (
            ("frame_timeout", frame_timeout),
            ("max_connections", max_connections),
            ("idle_timeout", idle_timeout),
            ("max_connections_per_peer", max_connections_per_peer),
        )
        if value is not None
    )
    return f"""
[gateway]
shutdown_timeout = 2.0
tick = 0.01
[zenoh]
enabled = false
[modbus]
enabled = {"true" if modbus_enabled else "false"}
bind = "127.0.0.1:{port}"
allow = [{allow_list}]
read_only = {"true" if read_only else "false"}
gateway_unit = {gateway_unit}
{limits}[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
modbus_unit = {D1}
ramp_time = 0.2
control = "{control}"
command_timeout = {command_timeout}
[[buses.line1.drives]]
id = "d2"
device = "MCD 600"
address = 4
modbus_unit = {D2}
ramp_time = 0.2
[[buses.line1.drives]]
id = "d3"
device = "test"
address = 5
[buses.line2]
adapter = "{FAKE}"
cycle = 0.01
[[buses.line2.drives]]
id = "d4"
device = "test"
address = 6
modbus_unit = {D4}
ramp_time = 0.2
"""


async def connect(port: int) -> AsyncModbusTcpClient:
    # reconnect_delay=0: no reconnect task may outlive a test
    client = AsyncModbusTcpClient(
        "127.0.0.1", port=port, reconnect_delay=0, retries=0, timeout=TIMEOUT
    )
    assert await client.connect()
    return client


@dataclass
class Gateway:
    daemon: Daemon
    frontend: ModbusFrontEnd
    port: int
    clients: list[AsyncModbusTcpClient] = field(default_factory=list)

    @property
    def hub(self) -> Hub:
        return self.daemon.hub

    async def client(self) -> AsyncModbusTcpClient:
        client = await connect(self.port)
        self.clients.append(client)
        return client

    def adapter(self, bus: str) -> FakeAdapter:
        return next(a for a in reversed(FakeAdapter.instances) if a.name == bus)

    async def wait_state(self, drive_id: str, pred: Callable[[DriveState], bool]) -> DriveState:
        return await asyncio.wait_for(self.hub.wait_for(drive_id, pred), TIMEOUT)

    async def inputs_until(
        self,
        client: AsyncModbusTcpClient,
        unit: int,
        pred: Callable[[list[int]], bool],
        count: int = INPUTS,
    ) -> list[int]:
        """Read the status block until ``pred`` holds, re-reading on each hub state change."""

        async def poll() -> list[int]:
            with self.hub.subscribe_states() as sub:
                while True:
                    rr = await client.read_input_registers(0, count=count, device_id=unit)
                    assert not rr.isError(), rr
                    regs = list(rr.registers)
                    if pred(regs):
                        return regs
                    await sub.get()

        return await asyncio.wait_for(poll(), TIMEOUT)


StartGateway = Callable[..., Awaitable[Gateway]]


@pytest.fixture
async def start_gateway(tmp_path: Path) -> AsyncIterator[StartGateway]:
    """``await start_gateway(**config_options)``: a daemon with its drives online and
    the Modbus front end listening; everything is stopped at the end of the test."""
    running: list[tuple[Gateway, asyncio.Task[int], asyncio.Task[None]]] = []

    async def start(**options: Any) -> Gateway:
        port = free_port()
        cfg = tmp_path / f"site{len(running)}.toml"
        cfg.write_text(config_text(port, **options))
        daemon = Daemon(load(cfg), notifier=Notifier({}))
        daemon_task = asyncio.create_task(daemon.run())
        frontend = ModbusFrontEnd(daemon.runtime)
        fe_task = asyncio.create_task(frontend.run())
        gw = Gateway(daemon, frontend, port)
        running.append((gw, daemon_task, fe_task))
        await asyncio.wait_for(frontend.ready.wait(), TIMEOUT)
        for drive_id in ("d1", "d2", "d4"):
            await gw.wait_state(drive_id, lambda s: s.online)
        return gw

    yield start
    for gw, daemon_task, fe_task in running:
        for client in gw.clients:
            client.close()
        fe_task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await fe_task
        gw.daemon.request_stop()
        assert await asyncio.wait_for(daemon_task, TIMEOUT) == 0


def mbap(unit: int, pdu: bytes, tid: int = 1) -> bytes:
    """A Modbus TCP frame (MBAP header + PDU)."""
    return (
        tid.to_bytes(2, "big")
        + b"\x00\x00"
        + (len(pdu) + 1).to_bytes(2, "big")
        + bytes([unit])
        + pdu
    )


async def raw_exchange(port: int, frame: bytes) -> bytes:
    """Send one frame on a fresh socket and return the reply (b"" if closed)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(frame)
        await writer.drain()
        return await asyncio.wait_for(reader.read(260), TIMEOUT)
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()
