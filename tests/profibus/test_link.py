"""The serial link and the driver on real file descriptors (ptys), without blocking the loop."""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import resource
import select
import socket
import termios
import time
from collections.abc import Iterator
from typing import Any

import pytest
import serial

from adapters.link.stream import SLEEP_LIMIT
from adapters.profibus.codec.fdl import SHORT_ACK
from adapters.profibus.driver import LineDriver
from adapters.profibus.link import Rs485, in_thread, is_pty, open_link, open_port, set_rs485
from adapters.profibus.master import FrameIn, Transmit, Written
from tests.profibus.support import until


@contextlib.contextmanager
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("baudrate", [9600, 45450, 93750, 187500, 500000, 1500000, 12000000])
def test_every_baud_rate_opens_on_a_pty(baudrate: int) -> None:
    with pty_pair() as (_, path):
        ser = open_port(path, baudrate)
        try:
            attrs = termios.tcgetattr(ser.fileno())
            assert attrs[2] & termios.CSIZE == termios.CS8
            assert ser.parity == serial.PARITY_EVEN or not attrs[2] & termios.PARENB
        finally:
            ser.close()


class _Port:
    """Stands for a pyserial port on a real UART: its driver has RS-485 mode or not."""

    def __init__(self, supported: bool) -> None:
        self.supported = supported
        self.applied: list[Any] = []
        self._mode: Any = None

    @property
    def rs485_mode(self) -> Any:
        return self._mode

    @rs485_mode.setter
    def rs485_mode(self, value: Any) -> None:
        self._mode = value  # pyserial keeps the value, then applies it (TIOCSRS485)
        if value is not None and not self.supported:
            raise ValueError("Failed to set RS485 mode: [Errno 25] Inappropriate ioctl")
        self.applied.append(value)


def test_rs485_mode_is_set_on_a_real_port() -> None:
    for mode in (Rs485.AUTO, Rs485.ON):
        port = _Port(supported=True)
        assert set_rs485(port, "/dev/ttyS1", mode)
        (settings,) = port.applied
        assert settings.rts_level_for_tx is True  # RTS drives the transmitter
        assert settings.rts_level_for_rx is False
        assert port.rs485_mode is settings


def test_a_driver_without_rs485_mode() -> None:
    port = _Port(supported=False)
    assert not set_rs485(port, "/dev/ttyUSB0", Rs485.AUTO)  # auto-direction converter
    assert port.rs485_mode is None  # left as it was, not half set
    with pytest.raises(serial.SerialException, match="the driver refuses RS-485 mode"):
        set_rs485(_Port(supported=False), "/dev/ttyUSB0", Rs485.ON)


def test_rs485_off_and_url_ports_are_left_alone() -> None:
    for port_name, mode in (("/dev/ttyS1", Rs485.OFF), ("socket://127.0.0.1:1", Rs485.ON)):
        port = _Port(supported=True)
        assert not set_rs485(port, port_name, mode)
        assert port.applied == []


@pytest.mark.parametrize("mode", list(Rs485))
def test_rs485_mode_on_a_pty_is_tolerated(mode: Rs485) -> None:
    with pty_pair() as (_, path):
        ser = open_port(path, 500000, mode)  # the pty refuses TIOCSRS485: no failure
        try:
            assert ser.is_open
            assert ser.rs485_mode is None  # no stale RS-485 request left in pyserial
        finally:
            ser.close()


def test_is_pty() -> None:
    with pty_pair() as (_, path):
        assert is_pty(path)
    assert not is_pty("/dev/null")
    assert not is_pty("socket://127.0.0.1:1")
    assert not is_pty("/dev/ttyNOSUCH")


async def test_bytes_both_ways_and_a_full_buffer_does_not_block() -> None:
    loop = asyncio.get_running_loop()
    received: list[bytes] = []
    errors: list[BaseException] = []
    with pty_pair() as (master, path):
        os.set_blocking(master, False)
        link = await open_link(path, 500000, loop, lambda d, now: received.append(d), errors.append)
        try:
            os.write(master, b"\x10\x02\x05\x00\x07\x16")
            await until(lambda: b"".join(received) == b"\x10\x02\x05\x00\x07\x16")
            big = bytes(range(256)) * 1024  # more than the pty holds
            link.write(big)
            assert link.pending_output > 0  # the rest waits for the port, the loop goes on
            got = bytearray()

            def drain() -> bool:
                with contextlib.suppress(BlockingIOError):
                    got.extend(os.read(master, 65536))
                return len(got) == len(big)

            await until(drain)
            assert bytes(got) == big and link.pending_output == 0
            assert (link.bytes_out, link.bytes_in) == (len(big), 6)
        finally:
            await link.aclose()
        assert errors == []


async def test_a_dead_port_is_reported_once() -> None:
    loop = asyncio.get_running_loop()
    errors: list[BaseException] = []
    master, slave = os.openpty()
    path = os.ttyname(slave)
    link = await open_link(path, 500000, loop, lambda d, now: None, errors.append)
    try:
        os.close(master)  # the other end is gone: reads fail (EIO)
        os.close(slave)
        await until(lambda: bool(errors))
        link.write(b"\x00")
        for _ in range(3):  # turns of the loop: a failure shows in the first (writer ready)
            await asyncio.sleep(0)
        assert len(errors) == 1 and isinstance(errors[0], OSError)
    finally:
        link.close()
        link.close()  # twice is fine
    assert link.closed


async def test_a_missing_device_raises_on_open() -> None:
    loop = asyncio.get_running_loop()
    with pytest.raises(serial.SerialException):
        await open_link("/dev/ttyNOSUCHPORT9", 500000, loop, lambda d, n: None, lambda e: None)


async def test_a_socket_url_with_no_delay() -> None:
    loop = asyncio.get_running_loop()
    got: list[bytes] = []
    server_seen: list[bytes] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        server_seen.append(await reader.read(100))
        writer.write(b"\xe5")
        await writer.drain()
        await reader.read(100)
        writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    link = await open_link(
        f"socket://127.0.0.1:{port}", 500000, loop, lambda d, n: got.append(d), print
    )
    try:
        fd = link.ser.fileno()
        with socket.fromfd(fd, socket.AF_INET, socket.SOCK_STREAM) as s:
            assert s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)
        link.write(b"\x10\x05\x02\x49\x50\x16")
        await until(lambda: got == [b"\xe5"])
        assert server_seen == [b"\x10\x05\x02\x49\x50\x16"]
    finally:
        await link.aclose()
        server.close()
        await server.wait_closed()


async def test_in_thread_returns_and_raises() -> None:
    assert await in_thread(lambda: 42) == 42
    with pytest.raises(ZeroDivisionError):
        await in_thread(lambda: 1 / 0)


class _Engine:
    """Sends what it is told, when told; counts its steps."""

    def __init__(self) -> None:
        self.queue: list[Any] = []  # Transmits and other actions
        self.steps = 0
        self.deadline: float | None = None

    def step(self, now: float, event: Any = None) -> list[Any]:
        self.steps += 1
        out, self.queue = self.queue, []
        return out

    def next_deadline(self) -> float | None:
        return self.deadline

    def awaiting_reply(self) -> bool:
        return False


async def test_the_driver_keeps_the_idle_time_before_a_request() -> None:
    loop = asyncio.get_running_loop()
    with pty_pair() as (master, path):
        os.set_blocking(master, False)
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Recorder()
        driver = LineDriver(engine, link)
        try:
            soon = loop.time() + 0.0005  # TSYN-sized: slept on the precise timer, not spun
            engine.queue.append(Transmit(b"\x01", soon))
            driver.poke()
            assert link.bytes_out == 0  # the loop goes on meanwhile
            later = soon + 0.25
            engine.queue.append(Transmit(b"\x02", later))
            driver.poke()
            got = bytearray()

            def read() -> bool:
                with contextlib.suppress(BlockingIOError):
                    got.extend(os.read(master, 10))
                return bool(got)

            await until(read)
            first = loop.time()
            assert got == b"\x01" and engine.written()[0] >= soon
            got.clear()
            await until(read)
            assert got == b"\x02" and loop.time() >= later > first
            assert engine.written()[1] >= later
        finally:
            driver.stop()
            link.close()


async def test_the_driver_steps_at_the_engines_deadline() -> None:
    loop = asyncio.get_running_loop()
    with pty_pair() as (_, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Engine()
        engine.deadline = loop.time() + 0.01
        driver = LineDriver(engine, link)
        try:
            driver.start()
            steps = engine.steps
            engine.deadline = None
            await until(lambda: engine.steps > steps)
        finally:
            driver.stop()
            link.close()


async def test_the_driver_writes_the_next_request_before_handling_the_other_actions() -> None:
    """The line never waits on the adapter: a reply's handling (decoding the inputs,
    updating the hub) comes after the next request is on its way."""
    loop = asyncio.get_running_loop()
    with pty_pair() as (_, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Engine()
        written_when_handled: list[tuple[Any, int]] = []
        driver = LineDriver(
            engine, link, lambda action: written_when_handled.append((action, link.bytes_out))
        )
        try:
            engine.queue += ["inputs", Transmit(b"\x01\x02", loop.time()), "state"]
            driver.poke()
            assert written_when_handled == [("inputs", 2), ("state", 2)]
        finally:
            driver.stop()
            link.close()


@pytest.mark.parametrize("baudrate", [9600, 19200, 500000])
def test_a_pty_opens_again_at_the_same_rate(baudrate: int) -> None:
    """The intermittent ``(22, 'Invalid argument')`` of a second scan at 9600 (issue 20).

    A pty drops even parity (PARENB); asked again for the same settings, only the parity
    differs from what it has, and tcsetattr fails with EINVAL. The fallback used to retry
    at 9600 with parity still on: at 9600 that is the same request, refused again.
    """
    with pty_pair() as (_, path):
        for _ in range(3):
            ser = open_port(path, baudrate)
            ser.close()


class _Recorder(_Engine):
    """Records every step's time and event; forgets its deadline once bytes came."""

    def __init__(self) -> None:
        super().__init__()
        self.events: list[tuple[float, Any]] = []

    def step(self, now: float, event: Any = None) -> list[Any]:
        self.events.append((now, event))
        if isinstance(event, FrameIn):
            self.deadline = None
        return super().step(now, event)

    def written(self) -> list[float]:
        return [e.at for _, e in self.events if isinstance(e, Written)]


async def test_the_driver_confirms_a_late_write_with_the_time_it_happened() -> None:
    """The loop stands still past a write's time: the engine learns when the bytes went,
    not when they were planned (issue 18: idle times counted from the planned time)."""
    loop = asyncio.get_running_loop()
    with pty_pair() as (_, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Recorder()
        driver = LineDriver(engine, link)
        try:
            due = loop.time() + 0.02
            engine.queue.append(Transmit(b"\x01", due))
            driver.poke()
            time.sleep(0.05)  # noqa: ASYNC251 - the stalled loop under test: its callback runs late
            await until(lambda: bool(engine.written()))
            (at,) = engine.written()
            assert at >= due + 0.025 and link.bytes_out == 1
            engine.queue.append(Transmit(b"\x02", loop.time()))  # due now: written at once
            before = loop.time()
            driver.poke()
            assert len(engine.written()) == 2 and engine.written()[1] >= before
        finally:
            driver.stop()
            link.close()


async def test_bytes_arriving_before_a_short_deadline_are_stepped_before_it() -> None:
    """A sub-millisecond deadline is slept on the loop's precise timer, so the port is
    watched meanwhile: a stray reply that arrived reaches the engine before the deadline's
    step (it restarts the idle time before the next request is decided)."""
    loop = asyncio.get_running_loop()
    with pty_pair() as (master, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Recorder()
        driver = LineDriver(engine, link)
        try:
            os.write(master, SHORT_ACK.encode())
            fd = link.ser.fileno()
            assert select.select([fd], [], [], 5.0)[0]  # arrived, not read yet
            engine.deadline = due = loop.time() + 0.0005
            driver.poke()  # no await: the loop's reader had no chance yet
            await until(lambda: any(isinstance(e, FrameIn) for _, e in engine.events))
            frame = next(i for i, (_, e) in enumerate(engine.events) if isinstance(e, FrameIn))
            # no step for the deadline came before the reply was stepped
            assert not [now for now, e in engine.events[:frame] if e is None and now >= due]
        finally:
            driver.stop()
            link.close()


SHORT_IDLE = 0.00005  # s: an idle time the driver sleeps in the step (500 kbit/s TSYN: 66 us)


class _Idle(_Recorder):
    """Sends one request once its idle time is over (as the master after a reply)."""

    def __init__(self, due: float) -> None:
        super().__init__()
        self.deadline = self.due = due

    def step(self, now: float, event: Any = None) -> list[Any]:
        if self.deadline == self.due and now >= self.due:
            self.deadline = None
            self.queue.append(Transmit(b"\x01", self.due))
        return super().step(now, event)


async def test_an_idle_time_under_the_sleep_limit_is_slept_in_the_step() -> None:
    """500 kbit/s TSYN after a reply (66 us) costs no loop turn: the request goes in the
    step that took the reply, never before its time."""
    loop = asyncio.get_running_loop()
    with pty_pair() as (_, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        assert SHORT_IDLE < SLEEP_LIMIT
        engine = _Idle(math.inf)
        driver = LineDriver(engine, link)
        try:
            engine.deadline = engine.due = loop.time() + SHORT_IDLE
            driver.poke()  # no await: written in this call
            assert link.bytes_out == 1
            assert engine.written()[0] >= engine.due
            assert [now >= engine.due for now, e in engine.events if e is None][-1]
        finally:
            driver.stop()
            link.close()


async def test_bytes_arriving_during_a_slept_idle_time_are_stepped_before_it() -> None:
    """The short idle time is slept watching the port: bytes on the line meanwhile reach
    the engine before the step at the idle time's end (they restart the idle time)."""
    loop = asyncio.get_running_loop()
    with pty_pair() as (master, path):
        link = await open_link(path, 500000, loop, lambda d, n: None, lambda e: None)
        engine = _Recorder()
        driver = LineDriver(engine, link)
        try:
            os.write(master, SHORT_ACK.encode())
            assert select.select([link.ser.fileno()], [], [], 5.0)[0]  # arrived, not read
            engine.deadline = due = loop.time() + SHORT_IDLE
            driver.poke()  # no await: the loop's reader had no chance
            frame = next(i for i, (_, e) in enumerate(engine.events) if isinstance(e, FrameIn))
            assert not [now for now, e in engine.events[:frame] if e is None and now >= due]
        finally:
            driver.stop()
            link.close()


async def test_an_empty_read_with_bytes_just_arrived_is_no_device_gone() -> None:
    """A tty read that gives nothing while the next bytes arrive just after it: the port
    is readable again, but not hung up; nothing fails, and the bytes are read."""
    loop = asyncio.get_running_loop()
    errors: list[BaseException] = []
    received: list[bytes] = []
    with pty_pair() as (master, path):
        link = await open_link(path, 500000, loop, lambda d, now: received.append(d), errors.append)
        try:
            real_read = os.read

            def read_then_bytes_come(fd: int, n: int) -> bytes:
                os.read = real_read  # once: an empty read, and the bytes come meanwhile
                os.write(master, b"\x10\x02")
                time.sleep(0.01)  # the pty hands them over
                return b""

            os.read = read_then_bytes_come
            try:
                link._readable()
            finally:
                os.read = real_read
            assert errors == []
            await until(lambda: b"".join(received) == b"\x10\x02")
        finally:
            link.close()


def test_a_port_above_descriptor_1023_is_waited_on_and_read() -> None:
    """``select`` takes no descriptor above 1023; a gateway with many connections open may
    give a reopened port such a number."""
    from adapters.link.serial import _poll_once, _ready

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 2048:
        pytest.skip(f"the descriptor limit ({hard}) is below 2048")
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, 2048), hard))
    read_end, write_end = os.pipe()
    high = os.dup2(read_end, 1500)
    try:
        assert not _ready(high, 0.0)
        os.write(write_end, b"x")
        assert _ready(high, 0.0)
        assert _poll_once(high, 0.0) & select.POLLIN
        os.close(write_end)
        write_end = -1
        assert _poll_once(high, 0.0) & select.POLLHUP  # the other end gone: a hang-up
    finally:
        for fd in (read_end, high, write_end):
            if fd >= 0:
                os.close(fd)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
