"""Runs a :class:`SimLine` on a port, on the event loop: the other end of a pty pair, or a
serial port for the standalone simulator.

One reader for the whole line (several slaves share it, as on a real bus); replies that are
due later (an injected delay) are written by a loop timer. A periodic tick advances the
devices' physics and the DP watchdogs, and tells the decoder the line went quiet when a
partial telegram has waited :data:`IDLE_AFTER` (noise may have eaten its end).

A tick that comes more than :data:`STALL` late means the process itself stood still (a busy
machine): the simulated slaves do not count that time against their DP watchdog
(:meth:`SimLine.stood_still`). A real slave keeps its own clock, but a simulated one could
not have seen a telegram meanwhile even from a master that sent one; in the demo the master
shares the same process and stood still too.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import logging
import os
import struct
import termios
import tty
from typing import Any, Final

from adapters.profibus.link import OPEN_ERRORS, Rs485, open_port
from adapters.profibus.sim.line import SimLine

log = logging.getLogger(__name__)

TICK: Final = 0.01  # s between device ticks
STALL: Final = 0.1  # s: a tick this late means the process stood still (not scheduled)
IDLE_AFTER: Final = 0.002  # s of silence that ends a partial telegram
SETTLE_STEP: Final = 0.001


class SimPort:
    """A simulated line on a file descriptor (see the module docstring)."""

    def __init__(
        self,
        line: SimLine,
        fd: int,
        *,
        owned_fds: tuple[int, ...] = (),
        serial_port: Any = None,
        tick: float = TICK,
    ) -> None:
        self.line = line
        self.fd = fd
        self.tick_interval = tick
        self._owned = owned_fds
        self._serial = serial_port
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timers: set[asyncio.TimerHandle] = set()
        self._ticker: asyncio.TimerHandle | None = None
        self._out = bytearray()
        self._writer = False
        self._last_rx = 0.0
        self._closed = False
        self.failed: BaseException | None = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.stalls = 0  # ticks that found the process had stood still
        self._tick_due = 0.0

    @classmethod
    def on_pty(cls, line: SimLine, tick: float = TICK) -> tuple[SimPort, str]:
        """A pty pair: the simulator holds the master side, the path is for the master."""
        master_fd, slave_fd = os.openpty()
        try:
            tty.setraw(slave_fd)  # no echo, no line discipline before pyserial opens it
            os.set_blocking(master_fd, False)
            path = os.ttyname(slave_fd)
        except OSError:
            os.close(master_fd)
            os.close(slave_fd)
            raise
        # the slave fd stays open: with no slave side open, reads of the master side fail
        return cls(line, master_fd, owned_fds=(master_fd, slave_fd), tick=tick), path

    @classmethod
    def on_serial(
        cls,
        line: SimLine,
        port: str,
        baudrate: int,
        tick: float = TICK,
        rs485: Rs485 = Rs485.AUTO,
    ) -> SimPort:
        """A serial port (or pyserial URL with a file descriptor): the standalone simulator."""
        ser = open_port(port, baudrate, rs485)
        try:
            fd = ser.fileno()
        except (*OPEN_ERRORS, AttributeError):
            ser.close()
            raise ValueError(f"{port}: the simulator needs a port with a file descriptor") from None
        os.set_blocking(fd, False)
        return cls(line, fd, serial_port=ser, tick=tick)

    # ------------------------------------------------------------------ life

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(self.fd, self._readable)
        self._schedule_tick()

    def _schedule_tick(self) -> None:
        if self._loop is None:
            return
        self._tick_due = self._loop.time() + self.tick_interval
        self._ticker = self._loop.call_at(self._tick_due, self._tick)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(ValueError, OSError):
                loop.remove_reader(self.fd)
                if self._writer:
                    loop.remove_writer(self.fd)
        for handle in [*self._timers, self._ticker]:
            if handle is not None:
                handle.cancel()
        self._timers.clear()
        if self._serial is not None:
            with contextlib.suppress(*OPEN_ERRORS):
                self._serial.close()
        for fd in self._owned:
            with contextlib.suppress(OSError):
                os.close(fd)

    async def settle(self, limit: float = 0.5) -> None:
        """Wait (at most ``limit`` s) until everything sent to the simulator was answered."""
        loop = asyncio.get_running_loop()
        end = loop.time() + limit
        while loop.time() < end and not self._closed:
            if not self._timers and not self._out and _unread(self.fd) == 0:
                return
            await asyncio.sleep(SETTLE_STEP)

    # ------------------------------------------------------------------ I/O

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    def _readable(self) -> None:
        try:
            data = os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._fail(exc)
            return
        if not data:
            self._fail(OSError("end of file"))
            return
        now = self._now()
        self.bytes_in += len(data)
        self._last_rx = now
        self._send(self.line.receive(data, now), now)

    def _send(self, outgoing: list[Any], now: float) -> None:
        for out in outgoing:
            if out.at <= now:
                self._write(out.data)
            elif self._loop is not None:
                self._later(out.at, out.data)

    def _later(self, at: float, data: bytes) -> None:
        if self._loop is None:
            return
        handles: list[asyncio.TimerHandle] = []

        def fire() -> None:
            self._timers.discard(handles[0])
            self._write(data)

        handles.append(self._loop.call_at(at, fire))
        self._timers.add(handles[0])

    def _write(self, data: bytes) -> None:
        if self._closed:
            return
        self.bytes_out += len(data)
        self._out += data
        self._flush()

    def _flush(self) -> None:
        if self._closed:
            return
        try:
            n = os.write(self.fd, self._out)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError as exc:
            self._fail(exc)
            return
        del self._out[:n]
        loop = self._loop
        if loop is None:
            return
        if self._out and not self._writer:
            loop.add_writer(self.fd, self._flush)
            self._writer = True
        elif not self._out and self._writer:
            loop.remove_writer(self.fd)
            self._writer = False

    def _tick(self) -> None:
        self._ticker = None
        if self._closed or self._loop is None:
            return
        now = self._now()
        late = now - self._tick_due
        if late > STALL:
            self.stalls += 1
            self.line.stood_still(late)
        self.line.tick(now)
        if self.line.decoder.buffered and now - self._last_rx >= IDLE_AFTER:
            self.line.idle()
            self._send(self.line.receive(b"", now), now)
        self._schedule_tick()

    def _fail(self, exc: BaseException) -> None:
        if self.failed is None:
            log.warning("simulated line: port failed: %s", exc)
            self.failed = exc
        if self._loop is not None:
            with contextlib.suppress(ValueError, OSError):
                self._loop.remove_reader(self.fd)


def _unread(fd: int) -> int:
    try:
        raw = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
    except OSError:
        return 0
    return int(struct.unpack("i", raw)[0])
