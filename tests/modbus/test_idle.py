"""Issue 18: connections that never send a byte cannot lock a polling PLC out.

``modbus.idle_timeout`` closes a connection with no complete request for that long,
and at ``modbus.max_connections`` the connection idle longest makes room for a new
client. Raw sockets for the idle ones, a real pymodbus client for the PLC.
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

import pytest

from gateway.config import load
from gateway.modbus import limits
from gateway.modbus.limits import EVICT_MIN_IDLE, ConnectionLimits
from tests.modbus.conftest import TIMEOUT, StartGateway, connect
from tests.modbus.test_limits import closed_by_gateway, raw, status_of


async def test_an_idle_connection_is_closed_after_idle_timeout(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(idle_timeout=0.3)
    async with raw(gw.port) as (reader, _writer):
        assert await closed_by_gateway(reader)
    assert gw.frontend.counters.idle_closed == 1


async def test_a_polling_client_stays_past_idle_timeout(start_gateway: StartGateway) -> None:
    gw = await start_gateway(idle_timeout=0.3)
    async with raw(gw.port) as stream:
        loop = asyncio.get_running_loop()
        end = loop.time() + 1.2  # four idle timeouts, a request every 0.1 s
        tid = 1
        while loop.time() < end:
            assert (await status_of(stream, tid))[:2] == tid.to_bytes(2, "big")
            tid += 1
            await asyncio.sleep(0.1)
    assert gw.frontend.counters.idle_closed == 0


async def test_idle_connections_at_the_limit_make_room_for_a_plc(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """100 connections of 100 that never send a byte (idle_timeout off): a PLC
    connecting afterwards gets in, the idlest making room."""
    monkeypatch.setattr(limits, "EVICT_MIN_IDLE", 0.3)
    gw = await start_gateway(max_connections=100, idle_timeout=0)
    async with contextlib.AsyncExitStack() as stack:
        idle = [await stack.enter_async_context(raw(gw.port)) for _ in range(100)]
        await asyncio.sleep(0.4)  # they are idle now for longer than evict_after
        plc = await connect(gw.port)
        try:
            rr = await plc.read_input_registers(0, count=2, device_id=1)
            assert not rr.isError(), rr
        finally:
            plc.close()
        assert gw.frontend.counters.idle_evicted >= 1
        assert gw.frontend.counters.connections_over_limit == 0
        del idle


def test_evict_after_is_the_shorter_of_the_idle_timeout_and_the_floor() -> None:
    assert ConnectionLimits(5.0, 10, idle_timeout=0.5).evict_after == 0.5
    assert ConnectionLimits(5.0, 10, idle_timeout=600.0).evict_after == EVICT_MIN_IDLE
    assert ConnectionLimits(5.0, 10, idle_timeout=0.0).evict_after == EVICT_MIN_IDLE


def test_idle_timeout_is_read_from_the_config(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[modbus]\nidle_timeout = 0\n")
    assert load(path).modbus.idle_timeout == 0.0
    path.write_text("[modbus]\n")
    assert load(path).modbus.idle_timeout == 60.0
    assert TIMEOUT > 0
