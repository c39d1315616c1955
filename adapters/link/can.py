"""A python-can bus on the event loop, for any bus on CAN: read from the loop, never blocking.

Fact sheet Part 3: no blocking receive in a coroutine. A bus with a file descriptor
(SocketCAN, and any interface whose ``fileno()`` gives one) is read by the event loop
itself: ``loop.add_reader`` on the descriptor, and each readiness drains what is waiting
(``bus.recv(0)``, at most :data:`RX_BATCH` frames) into a plain list. A bus without one
(``virtual``, vendor interfaces) is read by python-can's ``can.Notifier`` thread, which
hands each message to the loop (``call_soon_threadsafe``) into the same list.
:meth:`CanLink.receive` waits on one future that the reader completes, bounded by one
``loop.call_at`` timer (cancelled when it is not needed): no ``asyncio.Queue`` and no
``asyncio.timeout`` per wait, the per-frame cost on a busy line. A held receive
(``receive(wait, hold=True)``, the driver's receive hold) is not ended by frames: the
descriptor is not watched meanwhile (the reader is removed, put back by the next receive
that is not held) and the Notifier's frames are kept without completing the wait; at its
end everything waiting is drained (at most :data:`RX_DRAIN` frames). Any python-can
interface works (``socketcan``, ``virtual``, vendor interfaces); ``udp_multicast`` is
refused (it sends multicast out of the network interface and is lossy). Frames go out
with 11-bit identifiers (``is_extended_id=False``: DeviceNet, CANopen). Send failures
(``CanOperationError``: transmit buffer full, interface down) are reported, never
raised, so the engine can back off; so are receive failures (a SocketCAN socket reports
ENETDOWN once when its interface goes down): never an exception in the reader.
:meth:`CanLink.close` always removes the reader (or stops the Notifier) and shuts the bus
down: no thread and no watched descriptor is left behind.

A received message becomes one event (:func:`convert`): :class:`RxFrame` with the frame as
the bus's codec builds it (the ``make`` function a bus adapter gives the link: it raises a
:class:`~gateway.errors.FrameDecodeError` for a frame its protocol cannot carry, which
becomes :class:`RxBad`), :class:`RxError` for a SocketCAN error frame (:mod:`.canerror`),
:class:`RxBad`, :class:`RxFailed`.

On real SocketCAN (not ``virtual``) a send fails with ENOBUFS when the interface's transmit
queue (``txqueuelen``) is full and with ENETDOWN while the interface is down: the first is
a back-off, the second means every connection on the line is gone (``link_down``).

A SocketCAN socket's receive queue is bounded by SO_RCVBUF; a frame that arrives while the
queue is full is dropped by the kernel without a word (python-can cannot read the drop
count, SO_RXQ_OVFL). The default (``net.core.rmem_default``, 208 KiB) holds only about 300
frames, a quarter of a second of a busy 500 kbit/s line: a garbage-collection pause or a
loaded machine lost explicit responses that way
(docs/decisions/0030-socketcan-receive-buffer.md). The link asks for
:data:`RX_BUFFER_BYTES` (SO_RCVBUFFORCE with CAP_NET_ADMIN, else SO_RCVBUF, which the
kernel caps at ``net.core.rmem_max``) and reports what it got as ``rx_buffer_bytes``.

An adapter gets its link from a :class:`CanLinks` factory, given by the composition root:
the configured interface, or a simulated line (the bus's simulator package, for
``simulate = true``) that starts its devices on the same in-process channel.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import select
import socket
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Generic, Protocol, Self, TypeAlias, TypeVar

import can

from adapters.link.canerror import LineCondition, decode_error_frame
from gateway.errors import AdapterError, FrameDecodeError

log = logging.getLogger(__name__)

RX_BUFFER_BYTES = 4 * 1024 * 1024  # asked for; about 5,000 frames, a second of a full line
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux: needs CAP_NET_ADMIN
NOTIFIER_TIMEOUT = 0.05  # s: the reader thread of fd-less buses (virtual) wakes this often
BITRATE_SET_BY_SYSTEM = frozenset({"socketcan", "virtual"})  # `ip link ... bitrate`, or none
REFUSED_INTERFACES = {
    "udp_multicast": "udp_multicast is not supported: it sends multicast out of the network "
    "interface and loses frames; use virtual (in-process) or socketcan (vcan0)",
}


@dataclass(frozen=True, slots=True)
class CanConfig:
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int | None = None  # passed on only to interfaces that set it themselves


class Frame(Protocol):
    """A CAN data frame as a bus's codec has it."""

    @property
    def arbitration_id(self) -> int: ...

    @property
    def data(self) -> bytes: ...


FrameT = TypeVar("FrameT", bound=Frame)
FrameT_co = TypeVar("FrameT_co", bound=Frame, covariant=True)


class FrameMaker(Protocol[FrameT_co]):
    """Builds a received frame; raises :class:`FrameDecodeError` for one its bus cannot carry."""

    def __call__(self, arbitration_id: int, data: bytes, is_extended_id: bool) -> FrameT_co: ...


@dataclass(frozen=True, slots=True)
class RxFrame(Generic[FrameT_co]):
    frame: FrameT_co


@dataclass(frozen=True, slots=True)
class RxError:
    """A SocketCAN error frame."""

    conditions: frozenset[LineCondition]


@dataclass(frozen=True, slots=True)
class RxBad:
    """A frame the bus cannot carry (extended id, remote, FD, too long)."""

    reason: str


@dataclass(frozen=True, slots=True)
class RxFailed:
    """Receiving failed (the socket reported an error); ``link_down``: the interface is down."""

    reason: str
    link_down: bool


CanEvent: TypeAlias = RxFrame[FrameT] | RxError | RxBad | RxFailed

# errnos that mean the interface is not there to carry frames (down, or removed)
LINK_DOWN_ERRNOS = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO})


@dataclass(frozen=True, slots=True)
class SendResult:
    sent: int
    dropped: int = 0
    error: str | None = None
    link_down: bool = False  # the interface is down: nothing can be sent on it


@dataclass(slots=True)
class LinkFigures:
    frames_tx: int = 0
    frames_rx: int = 0
    error_frames: int = 0
    bad_frames: int = 0
    send_failures: int = 0
    last_send_error: str | None = None
    receive_failures: int = 0
    last_receive_error: str | None = None


RX_BATCH = 64  # frames read per readiness of a bus's descriptor (SocketCAN), at most
RX_DRAIN = 8 * RX_BATCH  # frames read at the end of a held receive, at most (the rest: next)


def bus_fileno(bus: can.BusABC) -> int | None:
    """The bus's file descriptor, the loop watches it; None for a bus without one
    (``virtual``, most vendor interfaces: python-can's ``fileno`` raises then)."""
    try:
        fd = bus.fileno()
    except (NotImplementedError, AttributeError, OSError, ValueError):
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


def _release(waiter: asyncio.Future[None]) -> None:
    """End a :meth:`CanLink.receive` wait (something came, a wake, or the wait is over)."""
    if not waiter.done():
        waiter.set_result(None)


class _Listener(can.Listener):
    """For a bus without a descriptor: python-can's Notifier thread reads it and calls this
    on the loop (``call_soon_threadsafe``, as ``Notifier(loop=...)`` does)."""

    def __init__(self, link: CanLink[Any]) -> None:
        self._link = link

    def on_message_received(self, msg: can.Message) -> None:
        self._link._arrived(msg)

    def stop(self) -> None:
        return


def error_number(exc: BaseException) -> int | None:
    """The errno behind a python-can or OS error (python-can keeps it in ``error_code``)."""
    number = getattr(exc, "errno", None)
    if number is None:
        number = getattr(exc, "error_code", None)
    return number if isinstance(number, int) else None


def open_problem(config: CanConfig, exc: BaseException) -> str:
    """Why the bus did not open, with what to do about it where we know."""
    text = f"cannot open CAN interface {config.interface!r} channel {config.channel!r}: {exc}"
    if config.interface != "socketcan":
        return text
    number = error_number(exc)
    ch = config.channel
    make_vcan = (
        f"`sudo modprobe vcan && sudo ip link add dev {ch} type vcan && sudo ip link set up {ch}`"
    )
    if number == errno.EAFNOSUPPORT:
        return (
            f"{text}. This kernel has no SocketCAN (AF_CAN, module can-raw). Where the "
            f"kernel has it as modules: {make_vcan}; otherwise use the in-process "
            'interface `virtual` (`--interface virtual`, or interface = "virtual" in the '
            "config; simulated drives in the same process only)"
        )
    if number == errno.ENODEV:
        make = (
            make_vcan
            if ch.startswith("vcan")
            else f"check the adapter, then `sudo ip link set {ch} up type can bitrate 125000`"
        )
        return f"{text}. There is no network interface {ch!r}: {make}"
    return text


def enlarge_receive_buffer(bus: can.BusABC, size: int = RX_BUFFER_BYTES) -> int | None:
    """Ask for a ``size`` receive queue on a bus with a kernel socket (SocketCAN); the
    size the kernel granted (it doubles the figure for its own bookkeeping), or None for
    a bus without a socket (``virtual``, vendor interfaces)."""
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return None
    for option in (SO_RCVBUFFORCE, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, size)
            break
        except OSError:  # EPERM: no CAP_NET_ADMIN for the forced size
            continue
    granted = int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    if granted < size:
        log.info(
            "CAN receive queue is %d bytes (asked for %d): raise net.core.rmem_max or "
            "give the service CAP_NET_ADMIN for a larger one",
            granted,
            size,
        )
    return granted


def convert(msg: can.Message, make: FrameMaker[FrameT]) -> CanEvent[FrameT]:
    """A python-can message as the bus's codec sees it (``make``); never raises."""
    data = bytes(msg.data or b"")
    if msg.is_error_frame:
        return RxError(decode_error_frame(msg.arbitration_id, data))
    if msg.is_remote_frame:
        return RxBad("remote frame")
    if msg.is_fd:
        return RxBad("CAN FD frame")
    try:
        return RxFrame(make(msg.arbitration_id, data, msg.is_extended_id))
    except FrameDecodeError as exc:
        return RxBad(exc.message)


class CanLink(Generic[FrameT]):
    """One python-can bus used from asyncio. Use ``async with CanLink(cfg, make) as link``."""

    def __init__(self, config: CanConfig, make: FrameMaker[FrameT]) -> None:
        reason = REFUSED_INTERFACES.get(config.interface)
        if reason is not None:
            raise AdapterError(reason)
        self.config = config
        self.make = make
        self.figures = LinkFigures()
        self._bus: can.BusABC | None = None
        self._fd: int | None = None  # watched by the loop (a bus with a descriptor)
        self._notifier: can.Notifier | None = None  # a bus without one
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._rx: list[can.Message] = []  # received, not yet taken by receive()
        self._failures: list[RxFailed] = []
        self._woken = False  # wake() since the last receive()
        self._waiter: asyncio.Future[None] | None = None  # a receive() waiting
        self._reading = False  # the loop watches the descriptor (not during a hold)
        self._holding = False  # a held receive: the Notifier's frames do not end it
        self._rx_buffer: int | None = None

    async def __aenter__(self) -> Self:
        self.open(asyncio.get_running_loop())
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def open(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop, self._loop_thread = loop, threading.get_ident()
        kwargs: dict[str, Any] = {
            "interface": self.config.interface,
            "channel": self.config.channel,
            "receive_own_messages": False,
        }
        if self.config.bitrate and self.config.interface not in BITRATE_SET_BY_SYSTEM:
            kwargs["bitrate"] = self.config.bitrate
        try:
            bus = can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
            raise AdapterError(open_problem(self.config, exc)) from exc
        self._bus = bus
        self._rx_buffer = enlarge_receive_buffer(bus)
        self._guard_receive(bus)
        fd = bus_fileno(bus)
        try:
            if fd is not None:
                loop.add_reader(fd, self._readable)
                self._fd, self._reading = fd, True
            else:
                self._notifier = can.Notifier(
                    bus, [_Listener(self)], timeout=NOTIFIER_TIMEOUT, loop=loop
                )
        except Exception:
            self._bus = None
            bus.shutdown()
            raise
        log.debug("CAN %s %s open", self.config.interface, self.config.channel)

    def _guard_receive(self, bus: can.BusABC) -> None:
        """A receive error becomes an :class:`RxFailed` event, never an exception in the
        reader (the loop's callback would raise, the Notifier's thread would end)."""
        bus.recv = self._guarded(bus.recv)  # type: ignore[method-assign,assignment]

    def _guarded(
        self, recv: Callable[[float | None], can.Message | None]
    ) -> Callable[[float | None], can.Message | None]:
        def guarded(timeout: float | None = None) -> can.Message | None:
            try:
                return recv(timeout)
            except (can.CanError, OSError) as exc:
                self._receive_failed(exc)
                return None

        return guarded

    def _readable(self) -> None:
        """The bus's descriptor is readable: take what is waiting, at most RX_BATCH (the
        loop gets its turn; the rest comes at the next readiness)."""
        bus = self._bus
        if bus is None:
            return
        self._drain(bus, RX_BATCH)
        waiter = self._waiter
        if waiter is not None and (self._rx or self._failures):
            self._waiter = None
            _release(waiter)

    def _drain(self, bus: can.BusABC, limit: int = RX_DRAIN, ask: int | None = None) -> None:
        """Read what is waiting on the descriptor, at most ``limit`` frames (RX_DRAIN at
        the end of a hold, RX_BATCH per readiness). With ``ask`` (the descriptor: a
        burst's) whether more waits is asked of it after each frame, cheaper than a read
        that finds nothing."""
        recv, rx = bus.recv, self._rx
        for _ in range(limit):
            msg = recv(0)
            if msg is None:
                break
            rx.append(msg)
            if ask is not None and not select.select((ask,), (), (), 0.0)[0]:
                break

    def _arrived(self, msg: can.Message) -> None:
        """A message from the Notifier (a bus without a descriptor), on the loop."""
        if self._bus is None:
            return
        self._rx.append(msg)
        if not self._holding:
            self._wake_waiter()

    def _receive_failed(self, exc: BaseException) -> None:
        self.figures.receive_failures += 1
        self.figures.last_receive_error = str(exc)
        failure = RxFailed(str(exc), error_number(exc) in LINK_DOWN_ERRNOS)
        loop = self._loop
        if self._bus is None or loop is None:
            return
        if threading.get_ident() == self._loop_thread:
            self._failed(failure)
        else:  # the Notifier's thread (buses without a file descriptor)
            loop.call_soon_threadsafe(self._failed, failure)

    def _failed(self, failure: RxFailed) -> None:
        self._failures.append(failure)
        self._wake_waiter()

    def _wake_waiter(self) -> None:
        waiter = self._waiter
        if waiter is not None:
            self._waiter = None
            _release(waiter)

    def close(self) -> None:
        """Stop reading (the loop's reader removed, or the Notifier stopped and its thread
        joined) and shut the bus down; idempotent."""
        notifier, self._notifier = self._notifier, None
        fd, self._fd = self._fd, None
        bus, self._bus = self._bus, None
        if fd is not None and self._loop is not None and self._reading:
            self._loop.remove_reader(fd)
        self._reading = self._holding = False
        if notifier is not None:
            notifier.stop(timeout=1.0)
        self._rx.clear()
        self._failures.clear()
        if bus is not None:
            with contextlib.suppress(can.CanError, OSError):
                bus.shutdown()

    @property
    def is_open(self) -> bool:
        return self._bus is not None

    def wake(self) -> None:
        """Make a pending :meth:`receive` return now, or the next one at once (for work
        queued from elsewhere)."""
        if self._bus is not None:
            self._woken = True
            self._wake_waiter()

    async def receive(self, wait: float, hold: bool = False) -> list[CanEvent[FrameT]]:
        """Everything waiting, or what arrives within ``wait`` seconds (possibly nothing).
        Held (``hold``): frames do not end the wait, only its time, :meth:`wake` or a
        receive failure; then everything waiting is taken."""
        loop = self._loop
        bus = self._bus
        if bus is None or loop is None:
            raise AdapterError("CAN link is closed")
        fd = self._fd
        if fd is not None and self._reading is hold:
            if hold:  # the loop stops watching: no wake-up per frame during the hold
                loop.remove_reader(fd)
                self._reading = False
            else:  # after a hold: take what came since, then watch again
                self._drain(bus)
                loop.add_reader(fd, self._readable)
                self._reading = True
        if not ((self._rx and not hold) or self._failures or self._woken):
            if wait <= 0:
                await asyncio.sleep(0)  # never a coroutine that returns without yielding
            else:
                # One future the reader (or wake, or the timer) completes. A cancellation
                # that arrives as a frame does is never swallowed (the task ends
                # cancelled, the frame stays for the next receive), unlike wait_for on
                # Python 3.11, which can leave a task that never ends.
                waiter: asyncio.Future[None] = loop.create_future()
                self._waiter, self._holding = waiter, hold
                timer = loop.call_at(loop.time() + wait, _release, waiter)
                try:
                    await waiter
                finally:
                    timer.cancel()
                    self._holding = False
                    if self._waiter is waiter:
                        self._waiter = None
        if hold and fd is not None and self._bus is not None:
            self._drain(bus)
        self._woken = False
        return self._collect()

    def burst(self, until: float, wake: int) -> list[CanEvent[FrameT]] | None:
        """What arrives by ``until`` (``time.monotonic``), waited for on the bus's
        descriptor itself, beside ``wake`` (the loop's wake descriptor: a callback handed
        to the loop from another thread), without a turn of the loop: the driver's burst
        (docs/decisions/0108). The frames read (at most :data:`RX_BATCH`) as
        :meth:`receive` gives them; ``[]`` when the time is over with none; None when the
        burst is not for now (a bus without a descriptor, a held receive, something
        already waiting or a wake asked for, ``wake`` readable): the caller awaits
        :meth:`receive`."""
        bus, fd = self._bus, self._fd
        if (
            bus is None
            or fd is None
            or not self._reading
            or self._rx
            or self._failures
            or self._woken
        ):
            return None
        left = until - time.monotonic()
        if left <= 0.0:
            return []
        try:
            ready = select.select((fd, wake) if wake >= 0 else (fd,), (), (), left)[0]
        except (OSError, ValueError):  # a descriptor beyond select's limit, or closed
            return None
        if not ready:
            return []
        if fd not in ready:
            return None
        self._drain(bus, RX_BATCH, fd)
        return self._collect()

    def _collect(self) -> list[CanEvent[FrameT]]:
        """Everything received and every failure since the last time, as events."""
        messages, self._rx = self._rx, []
        events: list[CanEvent[FrameT]] = []
        if self._failures:
            events.extend(self._failures)
            self._failures.clear()
        if not messages:
            return events
        make, figures = self.make, self.figures
        for msg in messages:
            event = convert(msg, make)
            if type(event) is RxFrame:
                figures.frames_rx += 1
            elif type(event) is RxError:
                figures.error_frames += 1
            else:
                figures.bad_frames += 1
            events.append(event)
        return events

    def send(self, frames: Iterable[Frame]) -> SendResult:
        """Send frames in order; stop at the first failure and say how many were dropped."""
        batch = frames if isinstance(frames, list) else list(frames)
        bus = self._bus
        if bus is None:
            return SendResult(0, len(batch), "CAN link is closed")
        send, message, figures = bus.send, can.Message, self.figures
        sent = 0
        for frame in batch:
            msg = message(
                arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=False
            )
            try:
                send(msg, 0)
            except (can.CanError, OSError) as exc:
                figures.frames_tx += sent
                figures.send_failures += 1
                figures.last_send_error = str(exc)
                down = error_number(exc) in LINK_DOWN_ERRNOS
                return SendResult(sent, len(batch) - sent, str(exc), link_down=down)
            sent += 1
        figures.frames_tx += sent
        return SendResult(sent)

    def diagnostics(self) -> dict[str, Any]:
        f = self.figures
        return {
            "interface": self.config.interface,
            "channel": self.config.channel,
            "link_frames_tx": f.frames_tx,
            "link_frames_rx": f.frames_rx,
            "error_frames": f.error_frames,
            "link_bad_frames": f.bad_frames,
            "send_failures": f.send_failures,
            "last_send_error": f.last_send_error,
            "receive_failures": f.receive_failures,
            "last_receive_error": f.last_receive_error,
            "rx_buffer_bytes": self._rx_buffer,
        }


class CanLinks(Protocol[FrameT]):
    """How an adapter gets its CAN line: the configured interface, or a simulated line.
    The composition root chooses."""

    def link(self) -> CanLink[FrameT]:
        """A new, unopened link on the line (``async with`` opens and closes it)."""
        ...

    async def start(self) -> None:
        """The adapter's link is open: a simulated line starts its devices (and raises what
        broke them); a real line has nothing to start."""
        return

    async def stop(self) -> None:
        """The adapter is done with the line: a simulated line ends its devices."""
        return
