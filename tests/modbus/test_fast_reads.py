"""Status-block reads take a short path past pymodbus: the same bytes, the same order."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from gateway.modbus.frontend import DriveUnit
from gateway.modbus.server import GatewayRequestHandler
from tests.modbus.conftest import D1, D2, INPUTS, TIMEOUT, StartGateway, mbap


def read(fc: int, address: int, count: int) -> bytes:
    return bytes([fc]) + address.to_bytes(2, "big") + count.to_bytes(2, "big")


# (unit, PDU): reads the short path answers, and reads beside them it must leave to pymodbus
REQUESTS = [
    (D1, read(4, 0, INPUTS)),
    (D1, read(4, 5, 3)),
    (D1, read(4, 20, 1)),
    (D1, read(4, 0, INPUTS + 1)),  # past the block: exception 2 from pymodbus
    (D1, read(4, INPUTS, 1)),
    (D1, read(4, 0, 0)),  # quantity 0: exception 3
    (D1, read(4, 0, 126)),
    (D2, read(3, 100, INPUTS)),  # the holding mirror
    (D2, read(3, 110, 5)),
    (D2, read(3, 99, 3)),  # across the mirror's start
    (D1, read(3, 0, 2)),  # the command holdings: pymodbus's path
    (D1, bytes([6]) + (0).to_bytes(2, "big") + (0).to_bytes(2, "big")),  # a write between reads
    (D1, read(4, 0, INPUTS)),
    (0, read(4, 0, 4)),  # the gateway unit
    (99, read(4, 0, 4)),  # no such unit: 0x0B
    (D1, read(1, 0, 1)),  # coils: exception 2
]


async def exchange(port: int, frames: bytes, count: int) -> list[bytes]:
    """Send ``frames`` in one write; the ``count`` replies, each framed by its MBAP length."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(frames)
        await writer.drain()
        replies = []
        for _ in range(count):
            header = await asyncio.wait_for(reader.readexactly(7), TIMEOUT)
            body = await asyncio.wait_for(
                reader.readexactly(int.from_bytes(header[4:6], "big") - 1), TIMEOUT
            )
            replies.append(header + body)
        return replies
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def test_short_path_replies_are_pymodbus_replies(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    gw = await start_gateway()
    # fixed registers, so that both runs read the same values (the gateway unit's counters
    # change with every request: it is compared without them)
    monkeypatch.setattr(DriveUnit, "update", lambda self, state: None)
    for n, unit in enumerate(gw.frontend.drives.values()):
        unit.inputs = [(1000 * (n + 1) + i) & 0xFFFF for i in range(INPUTS)]
    frames = b"".join(mbap(unit, pdu, tid=i + 1) for i, (unit, pdu) in enumerate(REQUESTS))
    served = gw.frontend.counters.requests
    fast = await exchange(gw.port, frames, len(REQUESTS))
    assert gw.frontend.counters.requests - served == len(REQUESTS)
    monkeypatch.setattr(GatewayRequestHandler, "_fast_read", lambda self, data, at: 0)
    slow = await exchange(gw.port, frames, len(REQUESTS))
    gateway_unit = next(i for i, (unit, _) in enumerate(REQUESTS) if unit == 0)
    for i, (a, b) in enumerate(zip(fast, slow, strict=True)):
        if i == gateway_unit:
            assert a[:9] == b[:9]  # header, function, byte count
        else:
            assert a == b, REQUESTS[i]
    assert [int.from_bytes(r[:2], "big") for r in fast] == list(range(1, len(REQUESTS) + 1))
    assert fast[0][9:] == b"".join(v.to_bytes(2, "big") for v in range(1000, 1000 + INPUTS))


async def test_a_flood_of_status_reads_is_served_in_bounded_batches(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Short-path reads are answered a bounded batch per callback too, in order, each
    batch in one write."""
    gw = await start_gateway()
    writes: list[int] = []
    original = GatewayRequestHandler._flush_out

    def counting(self: GatewayRequestHandler) -> None:
        if self._out:
            writes.append(len(self._out))
        original(self)

    monkeypatch.setattr(GatewayRequestHandler, "_flush_out", counting)
    flood = 1000
    frames = b"".join(mbap(D1, read(4, 0, INPUTS), tid=t) for t in range(flood))
    replies = await exchange(gw.port, frames, flood)
    assert [int.from_bytes(r[:2], "big") for r in replies] == list(range(flood))
    reply_size = 9 + 2 * INPUTS
    assert sum(writes) == flood * reply_size
    assert max(writes) <= 64 * reply_size  # PIPELINE_LIMIT replies at most per write
    assert len(writes) < flood // 4  # batched, not one write per reply


async def test_a_new_encoding_is_read_at_once(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Replies are kept while a unit's registers stay the same list; a new state's
    encoding (a new list) is what the next read returns."""
    gw = await start_gateway()
    monkeypatch.setattr(DriveUnit, "update", lambda self, state: None)
    unit = gw.frontend.drives["d1"]
    frame = mbap(D1, read(4, 0, INPUTS))
    for base in (100, 200, 200, 300):
        if unit.inputs[0] != base:
            unit.inputs = [base + i for i in range(INPUTS)]
        (reply,) = await exchange(gw.port, frame, 1)
        assert reply[9:] == b"".join(v.to_bytes(2, "big") for v in range(base, base + INPUTS))
