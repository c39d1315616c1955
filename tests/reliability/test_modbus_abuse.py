"""Modbus TCP clients misbehaving, through the daemon with the demo's drives simulated:
malformed frames, half frames, a flood of requests, 64 connections at once. Each is
answered or dropped; none stops the gateway, stalls another client or moves a drive.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator
from pathlib import Path

from pymodbus.client import AsyncModbusTcpClient

from tests.e2e.harness import PREFIX, RUN, TIMEOUT, Gateway
from tests.reliability.demo import UNITS, Events, at_speed, demo_gateway

STATUS_BLOCK = 21  # input registers 0-20 of a drive unit (docs/modbus-map.md)
BAD_FRAMES = 22  # gateway unit input registers 22-23: frames with a bad MBAP header
CONNECTIONS_OPEN = 9


def mbap(
    unit: int, pdu: bytes, tid: int = 1, protocol: int = 0, length: int | None = None
) -> bytes:
    size = len(pdu) + 1 if length is None else length
    return struct.pack(">HHHB", tid, protocol, size, unit) + pdu


def read_status(unit: int, tid: int = 1) -> bytes:
    return mbap(unit, struct.pack(">BHH", 4, 0, STATUS_BLOCK), tid)


@contextlib.asynccontextmanager
async def raw(gw: Gateway) -> AsyncIterator[tuple[asyncio.StreamReader, asyncio.StreamWriter]]:
    reader, writer = await asyncio.open_connection("127.0.0.1", gw.daemon.config.modbus.port)
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def exchange(gw: Gateway, frame: bytes) -> bytes:
    """One frame on a fresh connection; the reply, or b"" when the gateway closed it."""
    async with raw(gw) as (reader, writer):
        writer.write(frame)
        await writer.drain()
        try:
            return await asyncio.wait_for(reader.read(260), TIMEOUT)
        except ConnectionResetError:
            return b""


async def gateway_inputs(gw: Gateway, address: int, count: int) -> list[int]:
    rr = await gw.modbus.read_input_registers(address, count=count, device_id=0)
    assert not rr.isError(), rr
    return list(rr.registers)


def exception_of(reply: bytes) -> tuple[int, int]:
    """(function code, exception code) of an exception reply."""
    return reply[7], reply[8]


async def test_malformed_and_half_frames(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        unit = UNITS["cfw700"]
        # a PLC runs the CFW700 (its first word never starts a drive: 0, then run)
        await gw.write(unit, 1, 900)
        await gw.write(unit, 0, 0)
        await gw.write(unit, 0, RUN)
        await gw.wait_for("cfw700", at_speed(900.0))
        desired = {d: hub.desired(d) for d in UNITS}

        # a bad MBAP header closes that connection, and is counted
        closed = [
            mbap(unit, b"\x04\x00\x00\x00\x01", protocol=0x1234),
            mbap(unit, b"\x04\x00\x00\x00\x01", length=0),
            mbap(unit, b"\x04\x00\x00\x00\x01", length=300),
        ]
        for frame in closed:
            assert await exchange(gw, frame) == b"", frame.hex()
        # a well-framed but wrong request gets its exception reply
        answered = {
            mbap(unit, b"\x2b\x0e\x01\x00"): (0xAB, 0x01),  # identification: not served
            mbap(99, b"\x04\x00\x00\x00\x01"): (0x84, 0x0B),  # no such unit
            mbap(unit, b"\x04\x00"): (0x84, 0x03),  # a PDU that does not decode
            mbap(unit, b"\x04\x00\x00\x00\x00"): (0x84, 0x03),  # zero registers
            mbap(unit, b"\x06\x00\x00\xff\xff"): (0x86, 0x03),  # reserved command bits
            mbap(unit, b"\x06\x00\x01\x4e\x20"): (0x86, 0x03),  # 20000 rpm: refused, no clamp
            mbap(unit, b"\x06\x00\x32\x00\x01"): (0x86, 0x02),  # not a writable register
        }
        for frame, expected in answered.items():
            assert exception_of(await exchange(gw, frame)) == expected, frame.hex()
        # half a header, half a frame: closed by the client, or held open forever
        for chunk in (b"\x00\x02\x00", read_status(unit)[:9]):
            async with raw(gw) as (_, writer):
                writer.write(chunk)
                await writer.drain()
        async with raw(gw) as (_, stalled):
            stalled.write(read_status(unit)[:10])
            await stalled.drain()
            # a request split in single bytes is served, next to the stalled one
            async with raw(gw) as (reader, writer):
                for byte in read_status(unit, tid=7):
                    writer.write(bytes([byte]))
                    await writer.drain()
                reply = await asyncio.wait_for(reader.readexactly(9 + 2 * STATUS_BLOCK), TIMEOUT)
            assert reply[:2] == b"\x00\x07" and reply[7:9] == bytes([4, 2 * STATUS_BLOCK])
            # the PLC's connection and Zenoh were never disturbed
            regs = await gw.inputs(unit)
            assert regs[2] == 900
            health = (await gw.client.aone(f"{PREFIX}/gateway/health")).json()
            assert health["online"] == len(UNITS)
        counters = await gateway_inputs(gw, BAD_FRAMES, 2)
        assert counters[0] << 16 | counters[1] == len(closed)
        assert {d: hub.desired(d) for d in UNITS} == desired  # nothing was obeyed
        assert at_speed(900.0)(hub.state("cfw700"))


async def test_a_flood_of_requests_does_not_starve_the_others(tmp_path: Path) -> None:
    flood = 2000
    async with demo_gateway(tmp_path) as gw:
        unit = UNITS["cfw08"]

        async def flooder() -> list[int]:
            """Every request written at once, without waiting: the replies, in order."""
            async with raw(gw) as (reader, writer):
                writer.write(b"".join(read_status(unit, tid) for tid in range(1, flood + 1)))
                await writer.drain()
                tids = []
                for _ in range(flood):
                    reply = await asyncio.wait_for(
                        reader.readexactly(9 + 2 * STATUS_BLOCK), 4 * TIMEOUT
                    )
                    tids.append(int.from_bytes(reply[:2], "big"))
                return tids

        events = Events(gw)
        floods = [asyncio.create_task(flooder()) for _ in range(3)]
        try:
            # meanwhile a PLC runs the CFW-08 and SCADA the CFW-11
            await gw.write(unit, 1, 600)
            await gw.write(unit, 0, 0)
            await gw.write(unit, 0, RUN)
            await gw.command("cfw11", {"run": True, "speed_rpm": 900})
            await gw.wait_for("cfw08", at_speed(600.0))
            await gw.wait_for("cfw11", at_speed(900.0))
            assert (await gw.inputs(unit))[2] == 600
            for tids in await asyncio.wait_for(asyncio.gather(*floods), 8 * TIMEOUT):
                assert tids == list(range(1, flood + 1))  # every one answered, in order
        finally:
            events.close()
            for task in floods:
                task.cancel()
            await asyncio.gather(*floods, return_exceptions=True)
        # the buses never waited for the flood: the CFW-08 (offline after 4 x EPR = 0.2 s
        # without a poll) stayed online all along
        assert not [t for t in events.texts("cfw08") if "offline" in t]
        requests = await gateway_inputs(gw, 14, 2)
        assert requests[0] << 16 | requests[1] >= 3 * flood


async def test_64_connections_at_once(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        port = gw.daemon.config.modbus.port
        clients = [
            AsyncModbusTcpClient(
                "127.0.0.1", port=port, reconnect_delay=0, retries=0, timeout=TIMEOUT
            )
            for _ in range(64)
        ]
        try:
            assert all(await asyncio.gather(*(c.connect() for c in clients)))
            assert (await gateway_inputs(gw, CONNECTIONS_OPEN, 1))[0] == 64 + 1  # and the PLC

            async def poll(client: AsyncModbusTcpClient) -> list[list[int]]:
                out = []
                for unit in UNITS.values():
                    rr = await client.read_input_registers(0, count=STATUS_BLOCK, device_id=unit)
                    assert not rr.isError(), rr
                    out.append(list(rr.registers))
                return out

            results = await asyncio.gather(*(poll(c) for c in clients))
            assert all(len(r) == len(UNITS) for r in results)
            # while they poll, one of them is still a working PLC
            unit = UNITS["cfw320"]
            await clients[0].write_register(1, 900, device_id=unit)
            await clients[0].write_register(0, 0, device_id=unit)
            await clients[0].write_register(0, RUN, device_id=unit)
            await gw.wait_for("cfw320", at_speed(900.0))
        finally:
            for c in clients:
                c.close()

        async def open_now() -> int:
            return (await gateway_inputs(gw, CONNECTIONS_OPEN, 1))[0]

        async with asyncio.timeout(TIMEOUT):
            while await open_now() != 1:  # noqa: ASYNC110 - a counter has no event
                await asyncio.sleep(0.05)
        assert at_speed(900.0)(gw.daemon.hub.state("cfw320"))
