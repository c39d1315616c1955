"""Admission at accept: ``modbus.max_connections_per_peer``, the allow-list on the bare
socket, and accepts that fail for lack of file descriptors.

Every peer is on loopback: 127.0.0.1 and, as a second client address, 127.0.0.2 (the
whole of 127.0.0.0/8 reaches the loopback interface on Linux).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import resource
import socket
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from gateway.config import ModbusSection, load
from gateway.errors import ConfigErrors
from gateway.modbus import limits
from gateway.modbus.limits import Admission, ConnectionLimits, PeerCounts, admission
from gateway.modbus.server import GatewayRequestHandler, GatewayServer
from tests.modbus.conftest import TIMEOUT, StartGateway, mbap
from tests.modbus.test_limits import (
    OVER_LIMIT,
    READ_STATUS,
    SERVER_LOG,
    STATUS_REPLY,
    Stream,
    closed_by_gateway,
    counter,
    status_of,
    warnings,
)

OVER_PEER_LIMIT = 29  # gateway unit input registers (docs/modbus-map.md)
ACCEPT_FAILURES = 31
SECOND_PEER = "127.0.0.2"


@contextlib.asynccontextmanager
async def raw_from(port: int, source: str = "127.0.0.1") -> AsyncIterator[Stream]:
    """A raw connection to the gateway from the client address ``source``."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def refused_at_accept(port: int, source: str = "127.0.0.1") -> bool:
    """Open a connection, send a request, and whether the gateway closed it unanswered."""
    async with raw_from(port, source) as (reader, writer):
        writer.write(READ_STATUS)
        return await closed_by_gateway(reader)


# ---------------------------------------------------------------- the rule


def test_the_per_peer_limit_comes_before_the_total() -> None:
    both = ConnectionLimits(5.0, max_connections=4, max_per_peer=2)
    assert admission(both, open_total=3, open_of_peer=1) is Admission.ADMIT
    assert admission(both, open_total=3, open_of_peer=2) is Admission.PEER_FULL
    assert admission(both, open_total=4, open_of_peer=2) is Admission.PEER_FULL
    assert admission(both, open_total=4, open_of_peer=0) is Admission.FULL
    no_per_peer = ConnectionLimits(5.0, max_connections=4)
    assert admission(no_per_peer, open_total=3, open_of_peer=3) is Admission.ADMIT


def test_peer_counts_forget_an_address_with_nothing_open() -> None:
    peers = PeerCounts()
    peers.add("10.0.0.1")
    peers.add("10.0.0.1")
    peers.add("10.0.0.2")
    assert (peers.of("10.0.0.1"), peers.of("10.0.0.2"), len(peers)) == (2, 1, 2)
    peers.remove("10.0.0.2")
    peers.remove("10.0.0.1")
    assert (peers.of("10.0.0.1"), peers.of("10.0.0.2"), len(peers)) == (1, 0, 1)


# ---------------------------------------------------------------- per peer


async def test_one_address_over_its_limit_is_refused_while_another_is_served(
    start_gateway: StartGateway, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, SERVER_LOG)
    gw = await start_gateway(max_connections_per_peer=2)
    async with raw_from(gw.port) as first, raw_from(gw.port) as second:
        assert (await status_of(first))[7] == 4
        assert (await status_of(second))[7] == 4
        for _ in range(2):  # a third from the same address, twice
            assert await refused_at_accept(gw.port)
        # the other address is admitted, up to its own limit
        async with raw_from(gw.port, SECOND_PEER) as other:
            assert (await status_of(other))[7] == 4
            # the two admitted ones of the first address keep working
            assert (await status_of(first, tid=2))[:2] == b"\x00\x02"
            assert (await counter_over(other, OVER_PEER_LIMIT)) == 2
            assert (await counter_over(other, OVER_LIMIT)) == 2
    counters = gw.frontend.counters
    assert (counters.connections_over_peer_limit, counters.connections_over_limit) == (2, 2)
    assert counters.connections_accepted == 3  # the refused ones were never connected
    assert warnings(caplog, "refused Modbus client") == [
        "refused Modbus client 127.0.0.1: modbus.max_connections_per_peer (2) connections"
        " of its address are open"
    ]  # the second refusal, within the interval, at DEBUG only
    assert gw.frontend.counted().connections_over_limit == 2  # what /metrics reports


async def counter_over(stream: Stream, address: int) -> int:
    """A 32-bit counter of the gateway unit, read over a raw connection."""
    reader, writer = stream
    writer.write(mbap(0, b"\x04" + address.to_bytes(2, "big") + b"\x00\x02", tid=77))
    await writer.drain()
    reply = await asyncio.wait_for(reader.readexactly(STATUS_REPLY), TIMEOUT)
    assert reply[7] == 4, reply
    return int.from_bytes(reply[9:13], "big")


async def test_a_peer_at_its_limit_makes_room_from_its_own_idle_connection(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A client that reconnects without closing its old connection (a PLC after a
    power cut) gets in: its own connection idle longest makes room, nobody else's."""
    monkeypatch.setattr(limits, "EVICT_MIN_IDLE", 0.0)  # any idle connection may make room
    gw = await start_gateway(max_connections_per_peer=1, idle_timeout=0)
    async with raw_from(gw.port, SECOND_PEER) as other, raw_from(gw.port) as old:
        assert (await status_of(other))[7] == 4
        assert (await status_of(old))[7] == 4  # connected, then silent
        async with raw_from(gw.port) as new:
            assert (await status_of(new))[7] == 4
            assert await closed_by_gateway(old[0])
            assert (await status_of(other, tid=2))[:2] == b"\x00\x02"  # not its to give
    counters = gw.frontend.counters
    assert (counters.idle_evicted, counters.connections_over_limit) == (1, 0)


async def test_the_per_peer_limit_is_off_by_default(start_gateway: StartGateway) -> None:
    gw = await start_gateway(max_connections=3)
    async with raw_from(gw.port) as a, raw_from(gw.port) as b, raw_from(gw.port) as c:
        replies = [await status_of(s) for s in (a, b, c)]
        assert all(r[7] == 4 for r in replies)
    assert gw.frontend.counters.connections_over_limit == 0


# ---------------------------------------------------------------- allow-list


async def test_a_peer_outside_allow_is_closed_before_anything_is_made_for_it(
    start_gateway: StartGateway, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Refused on the bare accepted socket: no handler, no transport, no byte read."""
    made: list[GatewayRequestHandler] = []
    original = GatewayServer.callback_new_connection

    def counting(self: GatewayServer) -> GatewayRequestHandler:
        handler = original(self)
        made.append(handler)
        return handler

    monkeypatch.setattr(GatewayServer, "callback_new_connection", counting)
    gw = await start_gateway(allow=[f"{SECOND_PEER}/32"])
    assert await refused_at_accept(gw.port)
    assert made == []
    async with raw_from(gw.port, SECOND_PEER) as allowed:
        assert (await status_of(allowed))[7] == 4
    assert len(made) == 1
    counters = gw.frontend.counters
    assert (counters.connections_refused, counters.connections_accepted) == (1, 1)
    assert counters.requests == 1  # the allowed client's only
    refused = [r for r in gw.daemon.runtime.audit.newest() if r["type"] == "request_refused"]
    assert [(r["interface"], r["peer"], r["result"]) for r in refused] == [
        ("modbus", "127.0.0.1", "failure")
    ]
    assert refused[0]["detail"].startswith("modbus.allow: connection from 127.0.0.1 closed")


# ---------------------------------------------------------------- no descriptor left


@contextlib.contextmanager
def no_descriptor_left() -> Iterator[None]:
    """Every file descriptor number below the (lowered) soft limit taken: the next
    ``accept`` fails with EMFILE, as in a process at its LimitNOFILE."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    highest = max(int(name) for name in os.listdir("/proc/self/fd"))
    resource.setrlimit(resource.RLIMIT_NOFILE, (highest + 1, hard))
    fillers: list[int] = []
    try:
        while True:
            try:
                fillers.append(os.open(os.devnull, os.O_RDONLY))
            except OSError as exc:
                if exc.errno != errno.EMFILE:
                    raise
                break
        yield
    finally:
        for fd in fillers:
            os.close(fd)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


async def test_no_descriptor_left_is_one_line_with_a_count_and_the_open_are_served(
    start_gateway: StartGateway,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    failures = 3
    failed_enough = asyncio.Event()
    original = GatewayServer.accept_failed

    def counting(self: GatewayServer, exc: OSError) -> None:
        original(self, exc)
        if self.counters.accept_failures >= failures:
            failed_enough.set()

    monkeypatch.setattr(GatewayServer, "accept_failed", counting)
    caplog.set_level(logging.DEBUG)
    gw = await start_gateway()
    plc = await gw.client()
    loop = asyncio.get_running_loop()
    with contextlib.closing(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) as late:
        late.setblocking(False)  # made before: connecting needs no new descriptor
        with no_descriptor_left():
            await asyncio.wait_for(loop.sock_connect(late, ("127.0.0.1", gw.port)), TIMEOUT)
            await asyncio.wait_for(failed_enough.wait(), TIMEOUT)
            # the connection already open is served all the while
            rr = await plc.read_input_registers(0, count=2, device_id=1)
            assert not rr.isError(), rr
        # descriptors again: the waiting client is accepted and served
        await loop.sock_sendall(late, READ_STATUS)
        reply = b""
        while len(reply) < STATUS_REPLY:
            chunk = await asyncio.wait_for(loop.sock_recv(late, STATUS_REPLY), TIMEOUT)
            assert chunk, "closed by the gateway"
            reply += chunk
        assert reply[7] == 4
    counted = gw.frontend.counters.accept_failures
    assert counted >= failures
    assert await counter(plc, ACCEPT_FAILURES) == counted
    [line] = warnings(caplog, "cannot accept connections")
    assert line.startswith(
        "Modbus server cannot accept connections: the process has no file descriptor left"
    )
    assert "(EMFILE); 1 connection(s) open are still served, accepting again every 0.1 s" in line
    assert not [r for r in caplog.records if "out of system resource" in r.getMessage()]
    assert not [r for r in caplog.records if r.exc_info], "no traceback"
    assert any(
        r.getMessage() == f"Modbus server accepts connections again ({counted} accept(s) failed"
        " before)"
        for r in caplog.records
    )


# ---------------------------------------------------------------- config


def load_modbus(tmp_path: Path, body: str) -> ModbusSection:
    path = tmp_path / "site.toml"
    path.write_text(f"[modbus]\n{body}\n")
    return load(path).modbus


def test_max_connections_per_peer_is_read(tmp_path: Path) -> None:
    assert load_modbus(tmp_path, "").max_connections_per_peer == 0
    assert load_modbus(tmp_path, "max_connections_per_peer = 8").max_connections_per_peer == 8
    section = load_modbus(tmp_path, "max_connections = 10\nmax_connections_per_peer = 10")
    assert section.max_connections_per_peer == 10


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "max_connections_per_peer = -1",
            "modbus.max_connections_per_peer: -1 is below the minimum 0",
        ),
        (
            "max_connections = 10\nmax_connections_per_peer = 11",
            "modbus.max_connections_per_peer: 11 is above modbus.max_connections (10): it"
            " would limit nothing; 0 means no limit per address",
        ),
        (
            "max_connections_per_peer = 'few'",
            "modbus.max_connections_per_peer: must be an integer, not a string",
        ),
    ],
)
def test_bad_per_peer_values_give_their_exact_message(
    tmp_path: Path, body: str, message: str
) -> None:
    with pytest.raises(ConfigErrors) as err:
        load_modbus(tmp_path, body)
    assert [str(e) for e in err.value.errors] == [f"{tmp_path / 'site.toml'}: {message}"]
