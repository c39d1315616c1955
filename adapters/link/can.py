"""A python-can bus on the event loop, for any bus on CAN: its Notifier, an async reader.

Fact sheet Part 3: python-can only through ``can.Notifier(bus, [reader], loop=loop)``
with a ``can.AsyncBufferedReader`` (no blocking receive in a coroutine). Any python-can
interface works (``socketcan``, ``virtual``, vendor interfaces); ``udp_multicast`` is
refused (it sends multicast out of the network interface and is lossy). Frames go out
with 11-bit identifiers (``is_extended_id=False``: DeviceNet, CANopen). Send failures
(``CanOperationError``: transmit buffer full, interface down) are reported, never
raised, so the engine can back off; so are receive failures (a SocketCAN socket reports
ENETDOWN once when its interface goes down): never an exception in the Notifier.
:meth:`CanLink.close` always stops the Notifier and shuts the bus down: no thread is left
behind.

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
loaded machine lost explicit responses that way (docs/decisions.md). The link asks for
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
import socket
import threading
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


_WAKE = can.Message(arbitration_id=0, is_extended_id=False)  # marker put in our own queue
RX_BATCH = 64  # frames read per readiness of a socket (SocketCAN), at most


class _Notifier(can.Notifier):
    """python-can's Notifier, reading everything waiting when a socket is readable.

    On a bus with a file descriptor (SocketCAN) python-can's Notifier reads one frame per
    readiness callback, so a busy line costs one event-loop pass per frame (``virtual``'s
    reader thread hands frames over in batches). Up to :data:`RX_BATCH` are read at once.
    """

    def _on_message_available(self, bus: can.BusABC) -> None:
        for _ in range(RX_BATCH):
            msg = bus.recv(0)
            if msg is None:
                return
            self._on_message_received(msg)


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
    if getattr(msg, "is_fd", False):
        return RxBad("CAN FD frame")
    try:
        frame = make(msg.arbitration_id, data, msg.is_extended_id)
    except FrameDecodeError as exc:
        return RxBad(exc.message)
    return RxFrame(frame)


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
        self._reader: can.AsyncBufferedReader | None = None
        self._notifier: can.Notifier | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._failures: list[RxFailed] = []
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
            self._bus = can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
            raise AdapterError(open_problem(self.config, exc)) from exc
        self._rx_buffer = enlarge_receive_buffer(self._bus)
        self._guard_receive(self._bus)
        self._reader = can.AsyncBufferedReader()
        try:
            self._notifier = _Notifier(
                self._bus, [self._reader], timeout=NOTIFIER_TIMEOUT, loop=loop
            )
        except Exception:
            self._bus.shutdown()
            self._bus = None
            raise
        log.debug("CAN %s %s open", self.config.interface, self.config.channel)

    def _guard_receive(self, bus: can.BusABC) -> None:
        """A receive error becomes an :class:`RxFailed` event, never an exception in the
        Notifier (whose thread would end, or whose loop callback would raise)."""
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

    def _receive_failed(self, exc: BaseException) -> None:
        self.figures.receive_failures += 1
        self.figures.last_receive_error = str(exc)
        failure = RxFailed(str(exc), error_number(exc) in LINK_DOWN_ERRNOS)
        reader, loop = self._reader, self._loop
        if reader is None or loop is None:
            return
        if threading.get_ident() == self._loop_thread:
            self._failures.append(failure)
            reader.buffer.put_nowait(_WAKE)
        else:  # the Notifier's thread (buses without a file descriptor)
            loop.call_soon_threadsafe(self._failures.append, failure)
            loop.call_soon_threadsafe(reader.buffer.put_nowait, _WAKE)

    def close(self) -> None:
        """Stop the Notifier (joins its thread) and shut the bus down; idempotent."""
        notifier, self._notifier = self._notifier, None
        bus, self._bus = self._bus, None
        self._reader = None
        if notifier is not None:
            notifier.stop(timeout=1.0)
        if bus is not None:
            with contextlib.suppress(can.CanError, OSError):
                bus.shutdown()

    @property
    def is_open(self) -> bool:
        return self._bus is not None

    def wake(self) -> None:
        """Make a pending :meth:`receive` return now (for work queued from elsewhere)."""
        if self._reader is not None:
            self._reader.buffer.put_nowait(_WAKE)

    async def receive(self, wait: float) -> list[CanEvent[FrameT]]:
        """Everything waiting, or what arrives within ``wait`` seconds (possibly nothing)."""
        reader = self._reader
        if reader is None:
            raise AdapterError("CAN link is closed")
        buffer = reader.buffer
        messages: list[can.Message] = []
        if buffer.empty():
            if wait <= 0:
                await asyncio.sleep(0)  # never a coroutine that returns without yielding
                return []
            try:
                # asyncio.timeout, not wait_for: wait_for can swallow a cancellation that
                # arrives as the message does (Python 3.11), leaving a task that never ends.
                async with asyncio.timeout(wait):
                    messages.append(await buffer.get())
            except TimeoutError:
                return []
        while not buffer.empty():
            messages.append(buffer.get_nowait())
        events: list[CanEvent[FrameT]] = []
        if self._failures:
            events.extend(self._failures)
            self._failures.clear()
        for msg in messages:
            if msg is _WAKE:
                continue
            event = convert(msg, self.make)
            self._count(event)
            events.append(event)
        return events

    def _count(self, event: CanEvent[FrameT]) -> None:
        if isinstance(event, RxFrame):
            self.figures.frames_rx += 1
        elif isinstance(event, RxError):
            self.figures.error_frames += 1
        else:
            self.figures.bad_frames += 1

    def send(self, frames: Iterable[Frame]) -> SendResult:
        """Send frames in order; stop at the first failure and say how many were dropped."""
        batch = list(frames)
        bus = self._bus
        if bus is None:
            return SendResult(0, len(batch), "CAN link is closed")
        for i, frame in enumerate(batch):
            msg = can.Message(
                arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=False
            )
            try:
                bus.send(msg, timeout=0)
            except (can.CanError, OSError) as exc:
                self.figures.send_failures += 1
                self.figures.last_send_error = str(exc)
                down = error_number(exc) in LINK_DOWN_ERRNOS
                return SendResult(i, len(batch) - i, str(exc), link_down=down)
            self.figures.frames_tx += 1
        return SendResult(len(batch))

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
