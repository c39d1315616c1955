"""What one client may hold: ``modbus.frame_timeout`` and ``modbus.max_connections``.

Raw sockets (no pymodbus on the client side) for the misbehaving clients.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient

from gateway.config import ModbusSection, load
from gateway.errors import ConfigErrors
from gateway.modbus.limits import WarningRateLimit
from gateway.modbus.server import (
    KEEPALIVE_COUNT,
    KEEPALIVE_IDLE,
    KEEPALIVE_INTERVAL,
    PIPELINE_LIMIT,
    GatewayRequestHandler,
)
from tests.modbus.conftest import D1, D2, INPUTS, TIMEOUT, StartGateway, mbap

READ_STATUS = mbap(D1, b"\x04\x00\x00\x00\x02")
STATUS_REPLY = 9 + 2 * 2  # MBAP + function, byte count, two registers
CONNECTIONS_OPEN = 9  # gateway unit input registers (docs/modbus-map.md)
BAD_FRAMES = 22
FRAME_TIMEOUTS = 25
OVER_LIMIT = 27
SERVER_LOG = "gateway.modbus.server"

Stream = tuple[asyncio.StreamReader, asyncio.StreamWriter]


@contextlib.asynccontextmanager
async def raw(port: int) -> AsyncIterator[Stream]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def closed_by_gateway(reader: asyncio.StreamReader) -> bool:
    """Wait for the gateway to close the connection (end of stream or reset)."""
    try:
        return await asyncio.wait_for(reader.read(100), TIMEOUT) == b""
    except ConnectionResetError:
        return True


async def status_of(stream: Stream, tid: int = 1) -> bytes:
    """Read unit D1's status flags and code over a raw connection; the reply."""
    reader, writer = stream
    writer.write(mbap(D1, b"\x04\x00\x00\x00\x02", tid))
    await writer.drain()
    return await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)


async def counter(client: AsyncModbusTcpClient, address: int) -> int:
    rr = await client.read_input_registers(address, count=2, device_id=0)
    assert not rr.isError(), rr
    return int(rr.registers[0] << 16 | rr.registers[1])


def warnings(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.levelno == logging.WARNING and text in r.getMessage()
    ]


# ---------------------------------------------------------------- frame timeout


async def test_half_a_frame_is_closed_after_frame_timeout(
    start_gateway: StartGateway, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, SERVER_LOG)
    gw = await start_gateway(frame_timeout=0.2)
    plc = await gw.client()
    async with raw(gw.port) as idle, raw(gw.port) as (stalled_reader, stalled):
        assert (await status_of(idle))[7] == 4  # served, then idle: no frame begun
        stalled.write(READ_STATUS[:9])  # the header and half the PDU, then nothing
        await stalled.drain()
        closed = asyncio.ensure_future(closed_by_gateway(stalled_reader))
        served = 0
        while not served or not closed.done():  # the others are served meanwhile
            rr = await plc.read_input_registers(0, count=INPUTS, device_id=D2)
            assert not rr.isError(), rr
            served += 1
        assert await closed
        # the idle connection outlived the bound: a bound per begun frame, not an idle timeout
        assert (await status_of(idle, tid=2))[:2] == b"\x00\x02"
    assert (gw.frontend.counters.bad_frames, gw.frontend.counters.frame_timeouts) == (1, 1)
    assert await counter(plc, BAD_FRAMES) == 1
    assert await counter(plc, FRAME_TIMEOUTS) == 1
    [line] = warnings(caplog, "modbus.frame_timeout")
    assert line.startswith("Modbus client 127.0.0.1: 9 byte(s) of a frame")
    assert "(0.2 s); closing its connection" in line


async def test_half_a_header_is_closed_too(start_gateway: StartGateway) -> None:
    gw = await start_gateway(frame_timeout=0.2)
    async with raw(gw.port) as (reader, writer):
        writer.write(READ_STATUS[:3])
        await writer.drain()
        assert await closed_by_gateway(reader)
    assert gw.frontend.counters.frame_timeouts == 1


async def test_a_frame_split_across_sends_within_the_bound_is_served(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(frame_timeout=0.2)
    async with raw(gw.port) as (reader, writer):
        for cut in (3, 9):  # in the header, in the PDU
            writer.write(READ_STATUS[:cut])
            await writer.drain()
            writer.write(READ_STATUS[cut:])
            reply = await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)
            assert reply[7:9] == b"\x04\x04"
    assert gw.frontend.counters.frame_timeouts == 0
    assert gw.frontend.counters.bad_frames == 0


async def test_a_pipelined_request_split_around_a_reply_is_served(
    start_gateway: StartGateway,
) -> None:
    """The start of request 2 arrives with request 1, its rest after the reply to 1:
    the reply must not throw away the bytes of request 2 already received."""
    gw = await start_gateway()
    async with raw(gw.port) as (reader, writer):
        second = mbap(D1, b"\x04\x00\x00\x00\x02", tid=2)
        writer.write(mbap(D1, b"\x04\x00\x00\x00\x02", tid=1) + second[:9])
        await writer.drain()
        first = await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)
        assert first[:2] == b"\x00\x01"
        writer.write(second[9:])
        await writer.drain()
        reply = await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)
        assert reply[:2] == b"\x00\x02" and reply[7:9] == b"\x04\x04"
    assert gw.frontend.counters.bad_frames == 0


async def test_a_flood_is_framed_a_bounded_batch_at_a_time(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Thousands of requests in one read are not all decoded in one callback (that held
    the event loop, and the fieldbus cycles, for tens of milliseconds): at most
    PIPELINE_LIMIT per callback, the rest when the queue has drained; all answered in order."""
    gw = await start_gateway()
    framed_per_call: list[int] = []
    original = GatewayRequestHandler.data_received

    def counting(self: GatewayRequestHandler, data: bytes) -> None:
        before = gw.frontend.counters.requests
        original(self, data)
        framed_per_call.append(gw.frontend.counters.requests - before)

    monkeypatch.setattr(GatewayRequestHandler, "data_received", counting)
    flood = 20 * PIPELINE_LIMIT
    async with raw(gw.port) as (reader, writer):
        writer.write(b"".join(mbap(D1, b"\x04\x00\x00\x00\x02", tid=t) for t in range(flood)))
        await writer.drain()
        tids = []
        for _ in range(flood):
            reply = await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)
            tids.append(int.from_bytes(reply[:2], "big"))
    assert tids == list(range(flood))
    assert sum(framed_per_call) == flood
    assert 0 < max(framed_per_call) <= PIPELINE_LIMIT


# ---------------------------------------------------------------- max connections


async def test_a_connection_beyond_max_connections_is_closed_at_accept(
    start_gateway: StartGateway, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, SERVER_LOG)
    gw = await start_gateway(max_connections=2)
    plc = await gw.client()
    async with raw(gw.port) as second:
        assert (await status_of(second))[7] == 4
        for _ in range(2):  # a third, twice
            async with raw(gw.port) as (reader, writer):
                writer.write(READ_STATUS)
                assert await closed_by_gateway(reader)
        # the two admitted ones keep working
        assert (await status_of(second, tid=2))[:2] == b"\x00\x02"
        rr = await plc.read_input_registers(CONNECTIONS_OPEN, count=1, device_id=0)
        assert rr.registers == [2]
        assert await counter(plc, OVER_LIMIT) == 2
    # the second one is gone: once the gateway has seen it, a new one is admitted

    async def until_one_open() -> None:
        while True:
            rr = await plc.read_input_registers(CONNECTIONS_OPEN, count=1, device_id=0)
            if rr.registers == [1]:
                return

    await asyncio.wait_for(until_one_open(), TIMEOUT)
    async with raw(gw.port) as third:
        assert (await status_of(third, tid=3))[:2] == b"\x00\x03"
    counters = gw.frontend.counters
    assert (counters.connections_over_limit, counters.connections_refused) == (2, 0)
    assert counters.connections_accepted == 3
    assert warnings(caplog, "refused Modbus client") == [
        "refused Modbus client 127.0.0.1: modbus.max_connections (2) connections are open"
    ]  # the second refusal, within the minute, at DEBUG only


async def test_the_default_admits_64_connections(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    streams = [await asyncio.open_connection("127.0.0.1", gw.port) for _ in range(64)]
    try:
        replies = await asyncio.gather(*(status_of(s, tid=i) for i, s in enumerate(streams)))
        assert all(r[7] == 4 for r in replies)
    finally:
        for _, writer in streams:
            writer.close()
        for _, writer in streams:
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()
    assert gw.frontend.counters.connections_over_limit == 0
    assert ModbusSection().max_connections >= 64


async def test_connections_have_tcp_keepalive(start_gateway: StartGateway) -> None:
    """A client gone without a FIN (power cut) must not hold its place for ever."""
    gw = await start_gateway()
    async with raw(gw.port) as stream:
        assert (await status_of(stream))[7] == 4
        server = gw.frontend._server
        assert server is not None
        [handler] = server.active_connections.values()
        sock = handler.transport.get_extra_info("socket")
        assert sock.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE) != 0
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPIDLE) == KEEPALIVE_IDLE
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPINTVL) == KEEPALIVE_INTERVAL
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPCNT) == KEEPALIVE_COUNT


def test_over_limit_warnings_are_rate_limited() -> None:
    limit = WarningRateLimit(60.0)
    assert limit.admit(1000.0) == 0  # the first one is a warning
    assert limit.admit(1000.5) is None
    assert limit.admit(1059.9) is None
    assert limit.admit(1060.0) == 2  # a warning again, saying two were held back
    assert limit.admit(1200.0) == 0


# ---------------------------------------------------------------- config


def load_modbus(tmp_path: Path, body: str) -> ModbusSection:
    path = tmp_path / "site.toml"
    path.write_text(f"[modbus]\n{body}\n")
    return load(path).modbus


def test_defaults_and_values(tmp_path: Path) -> None:
    d = load_modbus(tmp_path, "")
    assert (d.frame_timeout, d.max_connections) == (5.0, 100)
    s = load_modbus(tmp_path, "frame_timeout = 0.25\nmax_connections = 1000")
    assert (s.frame_timeout, s.max_connections) == (0.25, 1000)
    assert load_modbus(tmp_path, "frame_timeout = 2\nmax_connections = 1").frame_timeout == 2.0


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("frame_timeout = 0", "modbus.frame_timeout: must be above 0, not 0"),
        ("frame_timeout = -1.5", "modbus.frame_timeout: must be above 0, not -1.5"),
        ("frame_timeout = 'soon'", "modbus.frame_timeout: must be a number, not a string"),
        ("frame_timeout = 3601", "modbus.frame_timeout: 3601 is above the maximum 3600.0"),
        ("frame_timeout = nan", "modbus.frame_timeout: must be a finite number"),
        ("max_connections = 0", "modbus.max_connections: 0 is below the minimum 1"),
        ("max_connections = 1001", "modbus.max_connections: 1001 is above the maximum 1000"),
        ("max_connections = 2.5", "modbus.max_connections: must be an integer, not a number"),
        ("max_connections = '10'", "modbus.max_connections: must be an integer, not a string"),
    ],
)
def test_bad_values_give_their_exact_message(tmp_path: Path, body: str, message: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        load_modbus(tmp_path, body)
    assert [str(e) for e in err.value.errors] == [f"{tmp_path / 'site.toml'}: {message}"]
