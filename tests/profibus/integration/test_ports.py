"""Ports under the master: a pty the test made, an RS-485-over-Ethernet converter reached
through a pyserial ``socket://`` URL (and losing it), a port that vanishes or never was."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator

from adapters.profibus.sim.echo import EchoSim
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.port import SimPort
from adapters.profibus.sim.slave import DpSlave
from gateway.adapter import EventKind
from gateway.model import CommState
from tests.profibus.support import line_config, running_line, until


def echo_line(*addresses: int) -> SimLine:
    return SimLine(DpSlave(a, EchoSim()) for a in addresses)


async def test_a_pty_made_outside_the_adapter() -> None:
    sim, path = SimPort.on_pty(echo_line(5, 6))
    sim.start()
    try:
        async with running_line(line_config([5, 6], port=path)) as line:
            await line.online("d5", "d6")
            diag = line.adapter.diagnostics()
            assert (diag["port"], diag["simulated"], diag["port_state"]) == (path, False, "open")
            assert sim.line[5].counters.exchanges > 0
        assert sim.line[5].counters.clears >= 1  # left the line with Clear
    finally:
        sim.close()


async def test_the_port_vanishing_takes_the_drives_offline_not_the_gateway() -> None:
    sim, path = SimPort.on_pty(echo_line(5))
    sim.start()
    try:
        async with running_line(line_config([5], port=path)) as line:
            await line.online("d5")
            with line.hub.subscribe_events() as events:
                sim.close()  # the USB converter is unplugged
                await line.until("d5", lambda s: s.comm is CommState.OFFLINE)
                await until(lambda: line.adapter.diagnostics()["port_state"] == "reopening")
                texts = [e.text for e in events.drain() if e.kind is EventKind.BUS]
            assert any(t.startswith(f"serial port {path} lost") for t in texts)
            assert not line.task.done()
    finally:
        sim.close()


async def test_a_port_that_is_not_there_is_retried() -> None:
    config = line_config([5], port="/dev/ttyNOSUCHPORT0")
    async with running_line(config) as line:
        with line.hub.subscribe_events() as events:
            event = await asyncio.wait_for(events.get(), 2.0)
        assert event.kind is EventKind.BUS
        assert event.text.startswith("cannot open /dev/ttyNOSUCHPORT0")
        assert line.adapter.diagnostics()["port_state"] == "reopening"
        assert line.hub.state("d5").comm is CommState.OFFLINE


@contextlib.asynccontextmanager
async def converter(line: SimLine) -> AsyncIterator[tuple[int, list[asyncio.StreamWriter]]]:
    """A TCP server standing for an RS-485-over-Ethernet converter with the line behind it."""
    loop = asyncio.get_running_loop()
    clients: list[asyncio.StreamWriter] = []
    handlers: set[asyncio.Task[None]] = set()

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        handlers.add(task)
        clients.append(writer)
        try:
            while data := await reader.read(4096):
                for out in line.receive(data, loop.time()):
                    writer.write(out.data)
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            writer.close()
            handlers.discard(task)

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    for sock in server.sockets:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # accepted sockets inherit it
    port = server.sockets[0].getsockname()[1]
    try:
        yield port, clients
    finally:
        server.close()
        for w in clients:
            w.close()
        for task in list(handlers):
            task.cancel()
        await asyncio.gather(*handlers, return_exceptions=True)
        await server.wait_closed()


async def test_a_socket_url_converter_and_its_reconnection() -> None:
    sim = echo_line(5)
    async with converter(sim) as (tcp_port, clients):
        url = f"socket://127.0.0.1:{tcp_port}"
        async with running_line(line_config([5], port=url)) as line:
            await line.online("d5")
            assert line.adapter.diagnostics()["port"] == url
            clients[0].close()  # the converter drops the connection
            await line.until("d5", lambda s: s.comm is CommState.OFFLINE)
            await line.online("d5", limit=5.0)  # reopened with back-off, back in exchange
            assert line.adapter.diagnostics()["reopens"] == 1
