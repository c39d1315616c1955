"""Modbus TCP access: allow-list, read-only mode, and no way to a drive parameter.

What tests/modbus already shows is not repeated here (docs/operations.md lists it):
a client outside ``modbus.allow`` that sends a read is disconnected at accept
(test_connections.py), ``modbus.read_only`` refuses functions 6, 16 and 22 with
exception 1 and still serves reads (test_exceptions.py). These tests add the
attacker's side: a refused client's *writes*, the exactness of the allow-list,
function 23 under read-only, and a sweep showing that no register reaches a
drive parameter (the Modbus map has no parameter access; parameters are written
through Zenoh only, within ``writable_params``).
"""

from __future__ import annotations

import asyncio
import contextlib
import struct

import pytest

from gateway.modbus.map import DRIVE_HOLDINGS, MIRROR_OFFSET, WRITABLE_HOLDINGS
from tests.modbus.conftest import D1, TIMEOUT, StartGateway, mbap, raw_exchange

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS = 1, 2
RUN = 0x0001  # command word: bit 0 run (docs/modbus-map.md, command bits)


def write_single(address: int, value: int, tid: int = 1) -> bytes:
    return mbap(D1, struct.pack(">BHH", 6, address, value), tid)


def write_multiple(address: int, values: list[int], tid: int = 1) -> bytes:
    body = struct.pack(f">BHHB{len(values)}H", 16, address, len(values), 2 * len(values), *values)
    return mbap(D1, body, tid)


def read_write(read: tuple[int, int], write: int, values: list[int], tid: int = 1) -> bytes:
    body = struct.pack(
        f">BHHHHB{len(values)}H", 23, *read, write, len(values), 2 * len(values), *values
    )
    return mbap(D1, body, tid)


def exception(function: int, code: int, tid: int = 1) -> bytes:
    return mbap(D1, bytes([function | 0x80, code]), tid)


async def send_on_one_connection(port: int, frames: list[bytes]) -> bytes:
    """Connect and send every frame at once (no waiting for accept to decide), then
    read what comes back until the server closes the connection."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    got = b""
    try:
        writer.write(b"".join(frames))
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        while True:
            try:
                chunk = await asyncio.wait_for(reader.read(260), TIMEOUT)
            except ConnectionError:
                break
            if not chunk:
                break
            got += chunk
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()
    return got


async def test_writes_of_a_client_outside_the_allow_list_are_never_applied(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(allow=["10.0.0.0/8"])
    before = gw.hub.desired("d1")
    frames = [
        write_single(0, RUN, tid=1),
        write_multiple(0, [RUN, 900, 0x8000, 1], tid=2),
        read_write((0, 1), 0, [RUN], tid=3),
    ]
    assert await send_on_one_connection(gw.port, frames) == b""
    assert gw.hub.desired("d1") == before
    assert gw.frontend.counters.connections_refused == 1
    assert gw.frontend.counters.requests == 0
    assert gw.frontend.counters.commands_accepted == 0
    assert not gw.hub.state("d1").running


@pytest.mark.parametrize(
    ("allow", "admitted"),
    [
        (["127.0.0.1/32"], True),
        (["127.0.0.1"], True),  # a bare address is a /32
        (["127.0.0.2/32"], False),
        (["10.0.0.0/8", "192.168.0.0/16"], False),
        (["::1/128"], False),  # an IPv6 entry never admits an IPv4 peer
        (["10.0.0.0/8", "127.0.0.0/8"], True),  # any entry
    ],
    ids=["host", "bare address", "other host", "other networks", "IPv6 only", "any entry"],
)
async def test_the_allow_list_matches_the_peer_address(
    start_gateway: StartGateway, allow: list[str], admitted: bool
) -> None:
    gw = await start_gateway(allow=allow)
    read = mbap(D1, b"\x04\x00\x00\x00\x01", tid=7)
    reply = await raw_exchange(gw.port, read)
    if admitted:
        assert reply[:2] == b"\x00\x07" and reply[7] == 4, reply
    else:
        assert reply == b""
    assert gw.frontend.counters.connections_refused == (0 if admitted else 1)


async def test_read_only_refuses_function_23_and_applies_nothing(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(read_only=True)
    before = gw.hub.desired("d1")
    frames = [
        read_write((0, 3), 0, [RUN], tid=1),
        read_write((0, 3), 1, [900], tid=2),
        read_write((MIRROR_OFFSET, 1), 3, [1], tid=3),  # even the keep-alive
    ]
    for frame in frames:
        tid = int.from_bytes(frame[:2], "big")
        assert await raw_exchange(gw.port, frame) == exception(23, ILLEGAL_FUNCTION, tid)
    # an unmapped register stays an address error, read-only or not (docs/operations.md)
    assert await raw_exchange(gw.port, write_single(4, 1, tid=4)) == exception(
        6, ILLEGAL_ADDRESS, 4
    )
    assert gw.hub.desired("d1") == before
    assert gw.frontend.counters.commands_accepted == 0


def test_the_map_has_no_parameter_register() -> None:
    """The only writable holding registers are the command block (docs/modbus-map.md)."""
    assert set(WRITABLE_HOLDINGS) == {0, 1, 2, 3}
    assert [h.name for h in DRIVE_HOLDINGS] == [
        "command",
        "speed_ref_rpm",
        "speed_ref_pct",
        "keepalive",
    ]


# beyond the command block: the fake drives' parameter numbers (100, 101 and 134
# writable by Zenoh), the read-only mirror, the end of the address space
SWEEP = (4, 99, 100, 101, 120, 121, 134, 1000, 40100, 0xFFFF)


async def test_no_register_write_reaches_a_drive_parameter(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    adapter = gw.adapter("line1")
    params_before = {d: dict(p) for d, p in adapter.params.items()}
    desired_before = gw.hub.desired("d1")
    c = await gw.client()
    assert not WRITABLE_HOLDINGS & set(SWEEP)
    for address in SWEEP:
        rr = await c.write_register(address, 1234, device_id=D1)
        assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS, (address, rr)
        rr = await c.write_registers(address, [1234], device_id=D1)
        assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS, (address, rr)
    assert adapter.params == params_before
    assert gw.hub.desired("d1") == desired_before
