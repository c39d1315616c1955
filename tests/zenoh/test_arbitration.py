"""Arbitration across the two front ends: a real Zenoh session and a real Modbus TCP
client command the same drive of one gateway, under each ``control`` setting."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from pymodbus.client import AsyncModbusTcpClient

from gateway.config import load
from gateway.runtime.daemon import Daemon
from gateway.runtime.systemd import Notifier
from tests.support.net import free_port, zenoh_endpoint
from tests.zenoh.client import Client

FAKE = "fake"  # tests/support/plugins.py
PREFIX = "arb"
UNIT = 1
DEVICE_FAILURE = 4
SOURCE_CODES = {"none": 0, "zenoh": 1, "modbus": 2, "gateway": 3}
COMMAND = f"{PREFIX}/drives/d1/command"
STATE = f"{PREFIX}/drives/d1/state"


def config_text(control: str) -> str:
    return f"""
[gateway]
shutdown_timeout = 2.0
tick = 0.01
[zenoh]
prefix = "{PREFIX}"
heartbeat = 0.2
[modbus]
allow = ["127.0.0.0/8"]
[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
modbus_unit = {UNIT}
ramp_time = 0.1
control = "{control}"
"""


@dataclass
class Both:
    daemon: Daemon
    zenoh: Client
    modbus: AsyncModbusTcpClient

    async def command(self, body: dict[str, Any]) -> dict[str, Any]:
        reply = await self.zenoh.aone(COMMAND, body)
        assert reply.ok, reply
        result: dict[str, Any] = reply.json()
        return result

    async def word(self, value: int) -> int | None:
        """Write the command word; the exception code, or None when accepted."""
        rr = await self.modbus.write_register(0, value, device_id=UNIT)
        return rr.exception_code if rr.isError() else None

    async def registers(self, pred: Callable[[list[int]], bool]) -> list[int]:
        """The drive's status block once ``pred`` holds (re-read on every hub change)."""
        hub = self.daemon.hub

        async def poll() -> list[int]:
            with hub.subscribe_states() as sub:
                while True:
                    rr = await self.modbus.read_input_registers(0, count=16, device_id=UNIT)
                    assert not rr.isError(), rr
                    if pred(list(rr.registers)):
                        return list(rr.registers)
                    await sub.get()

        return await asyncio.wait_for(poll(), 10)


@pytest_asyncio.fixture
async def start(tmp_path: Path) -> AsyncIterator[Callable[[str], Any]]:
    running: list[tuple[Daemon, asyncio.Task[int], Client, AsyncModbusTcpClient]] = []

    async def start(control: str) -> Both:
        cfg = tmp_path / f"{control}.toml"
        cfg.write_text(config_text(control))
        endpoint = zenoh_endpoint()
        config = load(cfg).with_overrides(endpoint, f"127.0.0.1:{free_port()}")
        daemon = Daemon(config, notifier=Notifier({}))
        task = asyncio.create_task(daemon.run())
        await asyncio.wait_for(daemon.ready.wait(), 30)
        zenoh_client = Client(endpoint, asyncio.get_running_loop())
        modbus = AsyncModbusTcpClient(
            config.modbus.host, port=config.modbus.port, reconnect_delay=0, retries=0, timeout=5
        )
        running.append((daemon, task, zenoh_client, modbus))
        assert await modbus.connect()
        await asyncio.wait_for(daemon.hub.wait_for("d1", lambda s: s.online), 10)
        await zenoh_client.settled(PREFIX)
        return Both(daemon, zenoh_client, modbus)

    yield start
    for daemon, task, zenoh_client, modbus in running:
        modbus.close()
        zenoh_client.close()
        daemon.request_stop()
        with contextlib.suppress(Exception):
            assert await asyncio.wait_for(task, 30) == 0


async def test_control_any_last_writer_wins_and_the_state_says_who(start: Any) -> None:
    gw: Both = await start("any")
    hub = gw.daemon.hub
    with gw.zenoh.subscribe(STATE) as states:
        assert await gw.command({"run": True, "speed_rpm": 600}) == {"accepted": True}
        await states.auntil(lambda s: s.json()["control_source"] == "zenoh" and s.json()["running"])
        # Modbus writes a new run edge: it takes control, and it is running on its word
        assert await gw.word(0x0000) is None
        assert await gw.word(0x0001) is None
        regs = await gw.registers(lambda r: r[14] == SOURCE_CODES["modbus"] and r[0] & 0b100 != 0)
        assert regs[15] == 0  # control mode "any"
        await states.auntil(lambda s: s.json()["control_source"] == "modbus")
        # Zenoh writes again: control passes back, and run needs a new run command (rule 1)
        assert await gw.command({"speed_rpm": 300}) == {"accepted": True}
        assert not hub.desired("d1").run
        await states.auntil(
            lambda s: s.json()["control_source"] == "zenoh" and not s.json()["running"]
        )
        await gw.registers(lambda r: r[14] == SOURCE_CODES["zenoh"])
        # the PLC rewrites its unchanged word: no edge, no takeover, no restart
        assert await gw.word(0x0001) is None
        assert hub.desired("d1").source.value == "zenoh" and not hub.desired("d1").run


async def test_control_zenoh_refuses_modbus_commands(start: Any) -> None:
    gw: Both = await start("zenoh")
    assert await gw.word(0x0000) is None  # a stop is never refused (issue 32)
    assert gw.daemon.hub.desired("d1").source.value == "none"  # and takes no control
    assert await gw.word(0x0001) == DEVICE_FAILURE
    assert not gw.daemon.hub.desired("d1").run
    assert await gw.command({"run": True, "speed_rpm": 600}) == {"accepted": True}
    regs = await gw.registers(lambda r: r[14] == SOURCE_CODES["zenoh"] and r[0] & 0b100 != 0)
    assert regs[15] == 1  # control mode "zenoh"
    # a Modbus stop is applied (a stop is never refused, issue 32); control stays with Zenoh
    assert await gw.word(0x0000) is None
    assert not gw.daemon.hub.desired("d1").run
    assert gw.daemon.hub.desired("d1").source.value == "zenoh"


async def test_control_modbus_refuses_zenoh_commands(start: Any) -> None:
    gw: Both = await start("modbus")
    refused = await gw.command({"run": True})
    assert refused == {"accepted": False, "error": "drive d1 takes commands from modbus only"}
    assert not gw.daemon.hub.desired("d1").run
    assert await gw.word(0x0000) is None
    assert not (await gw.modbus.write_register(1, 600, device_id=UNIT)).isError()
    assert await gw.word(0x0001) is None
    regs = await gw.registers(lambda r: r[14] == SOURCE_CODES["modbus"] and r[0] & 0b100 != 0)
    assert regs[15] == 2  # control mode "modbus"
    with gw.zenoh.subscribe(f"{PREFIX}/drives/d1/events") as events:
        await gw.zenoh.settled(PREFIX)
        gw.zenoh.put(COMMAND, {"run": True})  # a put is refused the same way, as an event
        event = await events.auntil(lambda e: e.json()["kind"] == "command_refused")
        assert "takes commands from modbus only" in event.json()["text"]
        assert gw.daemon.hub.desired("d1").run
        gw.zenoh.put(COMMAND, {"run": False})  # a stop is never refused (issue 32)
        await events.auntil(lambda e: e.json()["kind"] == "command")
    assert not gw.daemon.hub.desired("d1").run
    assert gw.daemon.hub.desired("d1").source.value == "modbus"


@pytest.mark.parametrize("control", ["any", "zenoh", "modbus"])
async def test_the_keepalive_register_never_takes_control(start: Any, control: str) -> None:
    gw: Both = await start(control)
    rr = await gw.modbus.write_register(3, 1, device_id=UNIT)
    assert not rr.isError()
    assert gw.daemon.hub.desired("d1").source.value == "none"
