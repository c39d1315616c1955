"""Connections: allow-list, many clients, garbage, the daemon serving Modbus."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from pathlib import Path

import pytest

from gateway import __version__
from gateway.config import load
from gateway.modbus.frontend import ModbusFrontEnd
from gateway.modbus.health import parse_version
from gateway.modbus.server import ModbusBindError
from gateway.runtime.daemon import Daemon
from gateway.runtime.systemd import Notifier
from tests.modbus.conftest import D1, INPUTS, TIMEOUT, StartGateway, config_text, connect, mbap
from tests.support.net import free_port

READ_STATUS = mbap(D1, b"\x04\x00\x00\x00\x02")


async def test_client_outside_the_allow_list_is_disconnected_at_accept(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(allow=["10.0.0.0/8"])
    reader, writer = await asyncio.open_connection("127.0.0.1", gw.port)
    try:
        writer.write(READ_STATUS)
        try:
            reply = await asyncio.wait_for(reader.read(100), TIMEOUT)
        except ConnectionResetError:
            reply = b""
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()
    assert reply == b""
    assert gw.frontend.counters.connections_refused == 1
    assert gw.frontend.counters.connections_accepted == 0
    assert gw.frontend.counters.requests == 0


async def test_32_clients_at_once(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    clients = await asyncio.gather(*(gw.client() for _ in range(32)))

    async def reads(i: int) -> list[list[int]]:
        out = []
        for _ in range(5):
            rr = await clients[i].read_input_registers(0, count=INPUTS, device_id=D1)
            assert not rr.isError()
            out.append(list(rr.registers))
        return out

    results = await asyncio.gather(*(reads(i) for i in range(32)))
    assert all(len(r) == 5 for r in results)
    health = await clients[0].read_input_registers(9, count=3, device_id=0)
    assert health.registers[0] == 32  # open
    assert (health.registers[1] << 16 | health.registers[2]) == 32  # accepted


async def test_garbage_and_half_frames_do_not_hurt_others(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    good = await gw.client()

    # bad protocol id: the connection is closed
    reader, writer = await asyncio.open_connection("127.0.0.1", gw.port)
    writer.write(b"\x00\x01\x12\x34\x00\x06\x01\x04\x00\x00\x00\x01")
    assert await asyncio.wait_for(reader.read(100), TIMEOUT) == b""
    writer.close()

    # half a header, half a frame, then gone
    for chunk in (b"\x00\x02\x00", READ_STATUS[:9]):
        _, w = await asyncio.open_connection("127.0.0.1", gw.port)
        w.write(chunk)
        await w.drain()
        w.close()
        with contextlib.suppress(ConnectionError):
            await w.wait_closed()

    # a valid request split in two writes is served
    reader2, writer2 = await asyncio.open_connection("127.0.0.1", gw.port)
    writer2.write(READ_STATUS[:5])
    await writer2.drain()
    writer2.write(READ_STATUS[5:])
    reply = await asyncio.wait_for(reader2.readexactly(9 + 4), TIMEOUT)
    assert reply[7:9] == b"\x04\x04"
    writer2.close()

    rr = await good.read_input_registers(0, count=INPUTS, device_id=D1)
    assert not rr.isError()
    health = await good.read_input_registers(22, count=2, device_id=0)
    assert health.registers == [0, 1]  # one bad frame
    with contextlib.suppress(ConnectionError):
        await writer.wait_closed()
        await writer2.wait_closed()


class _Serving(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.event = asyncio.Event()

    def emit(self, record: logging.LogRecord) -> None:
        if record.getMessage().startswith("Modbus TCP serving"):
            self.event.set()


async def test_the_daemon_runs_the_modbus_front_end(tmp_path: Path) -> None:
    port = free_port()
    cfg = tmp_path / "site.toml"
    cfg.write_text(config_text(port, modbus_enabled=True))
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    logger = logging.getLogger("gateway.modbus.frontend")
    handler, level = _Serving(), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    task = asyncio.create_task(daemon.run())
    try:
        await asyncio.wait_for(handler.event.wait(), TIMEOUT)
        client = await connect(port)
        try:
            rr = await client.read_input_registers(0, count=3, device_id=0)
            assert tuple(rr.registers) == parse_version(__version__)
        finally:
            client.close()
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        daemon.request_stop()
        assert await asyncio.wait_for(task, TIMEOUT) == 0
    try:
        _, writer = await asyncio.open_connection("127.0.0.1", port)
    except ConnectionRefusedError:
        return
    writer.close()  # pragma: no cover - the port must be closed after shutdown
    raise AssertionError("the Modbus port is still open after shutdown")


async def test_a_port_in_use_is_a_typed_error(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        cfg = tmp_path / "site.toml"
        cfg.write_text(config_text(port))
        daemon = Daemon(load(cfg), notifier=Notifier({}))  # not started: only its runtime
        with pytest.raises(ModbusBindError, match=f"127.0.0.1:{port}"):
            await ModbusFrontEnd(daemon.runtime).run()
