"""A serial port on the event loop, for any bus on a serial line: pyserial, non-blocking.

:func:`open_port` opens a device path (``/dev/ttyUSB0``, ``/dev/ttyS1``, a pty) or a pyserial
URL (``rfc2217://host:port``, ``socket://host:port``) with the bus's character format
(:class:`CharFormat`: Profibus DP uses 8E1, its fact sheet 1.1) and the baud rate. On a pty
the kernel accepts and ignores what it cannot do: parity is dropped silently, some baud
rates are refused (EINVAL), RTS ioctls fail; :func:`open_port` carries on there instead of
failing.

:class:`SerialLink` reads with ``loop.add_reader`` (never a blocking read), hands the bytes
and their arrival time to ``on_data``, writes without blocking (a short write waits for
``add_writer``) and reports a dead port (the USB converter unplugged, EOF, EIO) once to
``on_error``. A port without a file descriptor (rfc2217, whose pyserial class reads in a
thread of its own) is polled every :data:`POLL_INTERVAL` instead.

One master per line: a local port is held exclusively (:class:`ExclusiveSerial`: an
advisory flock taken before any setting changes, then ``TIOCEXCL``; :mod:`.portlock`
says why both). A port another process holds is refused with :class:`PortHeld`, naming the
holder where ``/proc`` shows it, before anything is sent or set.

RS-485 direction control: a converter with automatic direction control (most USB ones)
needs nothing; a UART wired to a transceiver needs the kernel's RS-485 mode, RTS driving the
transmitter (``TIOCSRS485``). :class:`Rs485` says what to do: ``auto`` (the default) asks
for it on a local port and carries on where the driver has no RS-485 mode, ``on`` insists
(opening fails where the driver refuses, a pty excepted: it accepts nothing of the kind and
means nothing by it), ``off`` leaves RTS alone. URL ports have no local UART to set.

pyserial's URL ports block when they open (a TCP connect, up to 5 s) and close (socket://
sleeps 0.3 s): :func:`open_link` and :meth:`SerialLink.aclose` run those calls in a
short-lived thread of their own, never on the event loop. A ``socket://`` connection gets
TCP_NODELAY: a master sends one short request and waits for the answer, which Nagle's
algorithm and delayed acknowledgements would hold back by tens of milliseconds.

An adapter opens its line through a :class:`SerialLinks` factory, given by the composition
root: :class:`SerialPort` (the configured port), or a simulated line (the bus's simulator
package, for ``simulate = true``) that starts its devices on a pty and opens that.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import math
import os
import select
import socket
import stat
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any, Final, Protocol, TypeVar

import serial
import serial.rs485

from adapters.link.portlock import PortHeld, clear_exclusive, find_holder, held, set_exclusive
from adapters.link.timer import loop_clock

log = logging.getLogger(__name__)

POLL_INTERVAL: Final = 0.001  # s, ports without a file descriptor
READ_CHUNK: Final = 4096
PTY_MAJORS: Final = range(136, 144)  # Linux Unix98 pty slaves (/dev/pts/N)
URL_SCHEMES: Final = ("rfc2217", "socket", "loop", "spy", "alt", "hwgrep")

OPEN_ERRORS: Final = (OSError, ValueError, termios.error, serial.SerialException)
"""What opening a port may raise (a missing device, a refused setting)."""


@dataclass(frozen=True, slots=True)
class CharFormat:
    """The character format of a line: data bits, parity (a pyserial ``PARITY_*``), stop bits."""

    bytesize: int = serial.EIGHTBITS
    parity: str = serial.PARITY_NONE
    stopbits: float = serial.STOPBITS_ONE


class Rs485(Enum):
    """The kernel's RS-485 mode on a local port (see the module docstring)."""

    AUTO = "auto"  # ask for it; a driver without it (auto-direction converter) is fine
    ON = "on"  # required: opening fails where the driver refuses (not on a pty)
    OFF = "off"  # leave RTS alone


def rs485_settings() -> serial.rs485.RS485Settings:
    """RTS high while sending, low while receiving, no extra delays (no gaps in a frame)."""
    return serial.rs485.RS485Settings(rts_level_for_tx=True, rts_level_for_rx=False)


def is_url(port: str) -> bool:
    return "://" in port


def is_pty(port: str) -> bool:
    """A pty slave device: its settings (baud rate, parity) mean nothing to the kernel."""
    if is_url(port):
        return False
    try:
        st = os.stat(port)
    except OSError:
        return False
    return stat.S_ISCHR(st.st_mode) and os.major(st.st_rdev) in PTY_MAJORS


class ExclusiveSerial(serial.Serial):  # type: ignore[misc]  # pyserial has no types
    """A local port held exclusively while open (module docstring, :mod:`.portlock`)."""

    def __init__(self) -> None:
        super().__init__(exclusive=True)  # pyserial flocks before it sets anything

    def open(self) -> None:
        try:
            super().open()
        except serial.SerialException as exc:
            if not held(exc):
                raise
            raise PortHeld(str(self.port), find_holder(str(self.port))) from None
        set_exclusive(self.fd)

    def close(self) -> None:
        if self.is_open and self.fd is not None:
            clear_exclusive(self.fd)
        super().close()


def _configure(ser: Any, baudrate: int, char: CharFormat) -> None:
    ser.baudrate = baudrate
    ser.bytesize = char.bytesize
    ser.parity = char.parity
    ser.stopbits = char.stopbits
    ser.timeout = 0
    ser.write_timeout = 0
    ser.xonxoff = False
    ser.rtscts = False
    ser.dsrdtr = False


def open_port(port: str, baudrate: int, char: CharFormat, rs485: Rs485 = Rs485.AUTO) -> Any:
    """An open pyserial port set to ``char`` at ``baudrate``, RS-485 as ``rs485`` says (a
    pty keeps what it can), held exclusively (a local port); :class:`PortHeld` if another
    process holds it.

    Blocks for a URL port (see the module docstring): call :func:`open_link` from a loop.
    """
    if is_url(port):
        ser = serial.serial_for_url(port, do_not_open=True)
    else:
        ser = ExclusiveSerial()
        ser.port = port
    _configure(ser, baudrate, char)
    try:
        ser.open()
    except termios.error:
        if not is_pty(port):
            raise
        _open_pty_anyway(ser, port, baudrate)
    if port.startswith("socket://"):
        _no_delay(ser)
    try:
        set_rs485(ser, port, rs485)
    except BaseException:
        ser.close()
        raise
    return ser


def _open_pty_anyway(ser: Any, port: str, baudrate: int) -> None:
    """Open a pty that refused the settings (EINVAL); it ignores rate and parity anyway.

    A pty drops parity (PARENB): asked for settings where only the parity differs from
    what it has (a second open at the same rate), tcsetattr fails with EINVAL. So without
    parity first, then also at 9600 (a rate every pty has). Retrying at 9600 with parity on
    failed at 9600 itself: the intermittent ``(22, 'Invalid argument')`` (issue 20).
    """
    log.info("%s is a pty: parity at %d baud not settable there, ignored", port, baudrate)
    ser.parity = serial.PARITY_NONE
    try:
        ser.open()
    except termios.error:
        ser.baudrate = 9600
        ser.open()


def set_rs485(ser: Any, port: str, mode: Rs485) -> bool:
    """Put an open local port in the kernel's RS-485 mode as ``mode`` says; True if set.

    A refusal is logged and tolerated (``auto``, or any pty), else SerialException.
    """
    if mode is Rs485.OFF or is_url(port):
        return False
    try:
        ser.rs485_mode = rs485_settings()
    except (*OPEN_ERRORS, NotImplementedError) as exc:  # a pty: EINVAL or ENOTTY
        with contextlib.suppress(*OPEN_ERRORS, NotImplementedError):
            ser.rs485_mode = None  # the port stays as it was: RS-485 mode off
        if mode is Rs485.ON and not is_pty(port):
            raise serial.SerialException(f"{port}: the driver refuses RS-485 mode: {exc}") from None
        log.info("%s: no kernel RS-485 mode (%s); the converter controls direction", port, exc)
        return False
    log.info("%s: kernel RS-485 mode on (RTS drives the transmitter)", port)
    return True


def _no_delay(ser: Any) -> None:
    fd = _fileno(ser)
    if fd is None:
        return
    with contextlib.suppress(OSError), socket.fromfd(fd, socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # on a dup of the fd


_T = TypeVar("_T")


async def in_thread(func: Callable[[], _T]) -> _T:
    """Run a blocking call in a thread of its own (it ends with the call)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[_T] = loop.create_future()

    def deliver(result: _T | None, error: BaseException | None) -> None:
        if future.cancelled():
            return
        if error is not None:
            future.set_exception(error)
        else:
            future.set_result(result)  # type: ignore[arg-type]

    def work() -> None:
        try:
            result, error = func(), None
        except BaseException as exc:  # handed to the awaiting coroutine
            result, error = None, exc
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(deliver, result, error)

    threading.Thread(target=work, name="serial-port", daemon=True).start()
    return await future


async def open_link(
    port: str,
    baudrate: int,
    loop: asyncio.AbstractEventLoop,
    on_data: Callable[[bytes, float], None],
    on_error: Callable[[BaseException], None],
    *,
    char: CharFormat,
    rs485: Rs485 = Rs485.AUTO,
) -> SerialLink:
    """Open ``port`` without blocking the loop and wrap it in a :class:`SerialLink`."""
    if is_url(port):
        ser = await in_thread(lambda: open_port(port, baudrate, char, rs485))
    else:
        ser = open_port(port, baudrate, char, rs485)
    return SerialLink(ser, loop, on_data, on_error, port)


class SerialLinks(Protocol):
    """How an adapter opens its line, again after each loss: the real port
    (:class:`SerialPort`) or a simulated line. The composition root chooses."""

    def start(self) -> str:
        """Make the line ready (a simulated line starts its devices); the port's name."""
        ...

    async def open(
        self,
        loop: asyncio.AbstractEventLoop,
        on_data: Callable[[bytes, float], None],
        on_error: Callable[[BaseException], None],
    ) -> SerialLink:
        """Open the port (:func:`open_link`); raises what opening raises."""
        ...

    async def settle(self) -> None:
        """Until the far end has taken what was written (a simulated line answers from
        this process); a real port has nothing to wait for."""
        return

    def close(self) -> None:
        """End what :meth:`start` started (a simulated line's devices); idempotent."""
        return

    def far_end_apart(self) -> bool:
        """Whether the far end answers whatever this process's loop does (a device, a
        process of its own): a driver may then wait for a reply without its loop
        (docs/decisions/0101). A line simulated on the loop says False."""
        return True


@dataclass(frozen=True)
class SerialPort(SerialLinks):
    """The configured port of a real line."""

    port: str
    baudrate: int
    char: CharFormat
    rs485: Rs485 = Rs485.AUTO

    def start(self) -> str:
        return self.port

    async def open(
        self,
        loop: asyncio.AbstractEventLoop,
        on_data: Callable[[bytes, float], None],
        on_error: Callable[[BaseException], None],
    ) -> SerialLink:
        return await open_link(
            self.port, self.baudrate, loop, on_data, on_error, char=self.char, rs485=self.rs485
        )


class SerialLink:
    """One open port on the event loop (see the module docstring)."""

    def __init__(
        self,
        ser: Any,
        loop: asyncio.AbstractEventLoop,
        on_data: Callable[[bytes, float], None],
        on_error: Callable[[BaseException], None],
        name: str = "",
    ) -> None:
        self.ser = ser
        self.loop = loop
        self._clock = loop_clock(loop)
        self.name = name or str(getattr(ser, "port", "port"))
        self.on_data = on_data
        self.on_error = on_error
        self.bytes_in = 0
        self.bytes_out = 0
        self._out = bytearray()
        self._fd: int | None = _fileno(ser)
        self._writer = False
        self._poll: asyncio.TimerHandle | None = None
        self._closed = False
        self._failed = False
        if self._fd is not None:
            os.set_blocking(self._fd, False)
            loop.add_reader(self._fd, self._readable)
        else:
            self._poll = loop.call_later(POLL_INTERVAL, self._polled)

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------------ reading

    def _readable(self) -> None:
        if self._closed or self._fd is None:
            return
        try:
            data = os.read(self._fd, READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._fail(exc)
            return
        if not data:
            if self._hung_up():  # the device is gone (a pty's other end closed, unplugged)
                self._fail(OSError(errno.EIO, f"{self.name}: end of file (device gone?)"))
            # else a tty (VMIN = 0) read nothing: what made it readable was read meanwhile
            # (read_now, in a callback of the same loop turn), and bytes that came just
            # after that read are read on the next call
            return
        self.bytes_in += len(data)
        self.on_data(data, self._clock())

    def _hung_up(self) -> bool:
        """The port says hang-up or error (``poll``: any descriptor number, and new bytes
        are never taken for a hang-up)."""
        if self._fd is None:
            return False
        try:
            events = _poll_once(self._fd, 0.0)
        except OSError:
            return True  # a descriptor that cannot be polled is no good either
        return bool(events & _GONE)

    def wait_readable(self, timeout: float) -> bool:
        """Block up to ``timeout`` s until bytes can be read (True) or the time is over
        (False, never before it). The stream driver sleeps an idle time shorter than its
        ``SLEEP_LIMIT`` in this, holding the loop; anything longer is a loop timer."""
        if self._fd is None:  # a URL port without a descriptor: sleep, then poll
            time.sleep(timeout)
            return True
        try:
            return _ready(self._fd, timeout)
        except OSError:
            return True  # the reader reports what is wrong with the port

    def read_now(self) -> None:
        """Read what has arrived now (as the reader callback would) and hand it on (a
        driver's timer does, before it judges a reply deadline)."""
        if self._fd is None:
            self._polled_once()
            return
        try:
            ready = _ready(self._fd, 0.0)
        except OSError:
            ready = True  # the read says what is wrong with the port
        if ready:  # a tty (VMIN = 0) reads nothing, not EAGAIN: look first
            self._readable()

    @property
    def has_descriptor(self) -> bool:
        """A port read through its file descriptor (not a URL port, which is polled)."""
        return self._fd is not None

    @property
    def descriptor(self) -> int:
        """The port's file descriptor (-1: a URL port, polled)."""
        return -1 if self._fd is None else self._fd

    def counted(self, bytes_in: int, bytes_out: int) -> None:
        """Bytes read and written on the descriptor by someone else (a steady ring)."""
        self.bytes_in += bytes_in
        self.bytes_out += bytes_out

    def take(self) -> bytes:
        """What has arrived, read now and returned (not handed to ``on_data``): b"" when
        nothing has, and on an error or a hang-up, which the loop's reader then reports."""
        if self._closed or self._fd is None:
            return b""
        try:
            data = os.read(self._fd, READ_CHUNK)
        except OSError:
            return b""
        self.bytes_in += len(data)
        return data

    def _polled_once(self) -> None:
        if self._closed:
            return
        try:
            waiting = self.ser.in_waiting
            data = self.ser.read(waiting) if waiting else b""
        except OPEN_ERRORS as exc:
            self._fail(exc)
            return
        if data:
            self.bytes_in += len(data)
            self.on_data(data, self.loop.time())

    def _polled(self) -> None:
        self._poll = None
        self._polled_once()
        if not self._closed:
            self._poll = self.loop.call_later(POLL_INTERVAL, self._polled)

    # ------------------------------------------------------------------ writing

    def write(self, data: bytes) -> None:
        """Queue ``data``; it goes out now, or as soon as the port takes more."""
        if self._closed:
            return
        self.bytes_out += len(data)
        if self._out or self._fd is None:
            self._out += data
            self._flush()
            return
        try:
            n = os.write(self._fd, data)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError as exc:
            self._fail(exc)
            return
        if n < len(data):
            self._out += data[n:]
            self._want_writer()

    def _flush(self) -> None:
        if self._closed or not self._out:
            return
        try:
            if self._fd is None:
                n = self.ser.write(bytes(self._out)) or 0
            else:
                n = os.write(self._fd, self._out)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OPEN_ERRORS as exc:
            self._fail(exc)
            return
        del self._out[:n]
        if self._out:
            self._want_writer()
        elif self._writer and self._fd is not None:
            self.loop.remove_writer(self._fd)
            self._writer = False

    def _want_writer(self) -> None:
        if self._fd is None:
            self.loop.call_later(POLL_INTERVAL, self._flush)
        elif not self._writer:
            self.loop.add_writer(self._fd, self._flush)
            self._writer = True

    @property
    def pending_output(self) -> int:
        return len(self._out)

    # ------------------------------------------------------------------ closing

    def _fail(self, exc: BaseException) -> None:
        if self._failed or self._closed:
            return
        self._failed = True
        log.warning("serial port %s failed: %s", self.name, exc)
        self._detach()
        self.on_error(exc)

    def _detach(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(ValueError, OSError):
                self.loop.remove_reader(self._fd)
                if self._writer:
                    self.loop.remove_writer(self._fd)
        self._writer = False
        if self._poll is not None:
            self._poll.cancel()
            self._poll = None

    def close(self) -> None:
        """Close now (a URL port closes in a thread: its close may block)."""
        if self._closed:
            return
        self._detach()
        self._closed = True
        if is_url(self.name):
            threading.Thread(target=self._close_port, name="serial-close", daemon=True).start()
        else:
            self._close_port()

    async def aclose(self) -> None:
        """Close, waiting for a URL port's close to finish."""
        if self._closed:
            return
        self._detach()
        self._closed = True
        if is_url(self.name):
            await in_thread(self._close_port)
        else:
            self._close_port()

    def _close_port(self) -> None:
        with contextlib.suppress(*OPEN_ERRORS):
            self.ser.close()


def _fileno(ser: Any) -> int | None:
    try:
        fd = ser.fileno()
    except (AttributeError, OSError, ValueError, serial.SerialException):
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


_GONE = select.POLLHUP | select.POLLERR | select.POLLNVAL


def _poll_once(fd: int, timeout: float) -> int:
    """The events of ``fd`` within ``timeout`` s, rounded up to a millisecond (0: none).
    ``poll`` takes any descriptor number (``select`` none above 1023: a gateway with many
    connections open may give a reopened port such a number)."""
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    ready = poller.poll(math.ceil(timeout * 1000) if timeout > 0 else 0)
    return ready[0][1] if ready else 0


def _ready(fd: int, timeout: float) -> bool:
    """Whether ``fd`` can be read (or says why not) within ``timeout`` s: ``select`` to the
    microsecond (an idle time of 66 us) where it can, ``poll`` above its descriptor limit."""
    if fd < _SELECT_LIMIT:
        return bool(select.select([fd], [], [], timeout)[0])
    return bool(_poll_once(fd, timeout))


_SELECT_LIMIT = 1024  # FD_SETSIZE on Linux
