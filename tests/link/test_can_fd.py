"""The CAN link on a bus with a file descriptor (as SocketCAN): read by the event loop
itself (``add_reader``), no Notifier thread; frames, error and bad frames, receive
failures, wake, close and a cancellation at the instant a frame arrives.

The bus is a python-can bus over a Unix socket pair (one record per frame), registered
as an interface for the test: the test writes frames into the other end."""

from __future__ import annotations

import asyncio
import errno
import socket
import struct
import threading
import time
import uuid
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from typing import Any

import can
import pytest

from adapters.link.can import (
    RX_BATCH,
    CanConfig,
    CanEvent,
    CanLink,
    RxBad,
    RxError,
    RxFailed,
    RxFrame,
    SendResult,
    bus_fileno,
)
from adapters.link.candriver import Burst, CanDriver, CanProtocol
from adapters.link.canerror import LineCondition
from adapters.link.timer import loop_wake
from gateway.errors import AdapterError, FrameDecodeError
from tests.support.timing import scaled

INTERFACE = "pairtest"
RECORD = struct.Struct("<IBB8s")  # identifier, flags, dlc, data
EXTENDED, REMOTE, ERROR = 1, 2, 4
PAIRS: dict[str, PairBus] = {}  # channel -> the bus the link opened


class PairBus(can.BusABC):
    """One end of a socket pair; the test holds the other (``peer``)."""

    def __init__(self, channel: Any, can_filters: Any = None, **kwargs: object) -> None:
        self._sock, self.peer = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._sock.setblocking(False)
        self.recv_calls = 0
        self.fail_next: OSError | None = None
        self.channel_info = f"pair {channel}"
        super().__init__(channel, can_filters=can_filters, **kwargs)
        PAIRS[str(channel)] = self

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._sock.send(RECORD.pack(msg.arbitration_id, 0, msg.dlc, bytes(msg.data)))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self.recv_calls += 1
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise can.CanOperationError(exc.strerror or "", exc.errno)
        try:
            record = self._sock.recv(RECORD.size)
        except BlockingIOError:
            return None, False
        ident, flags, dlc, data = RECORD.unpack(record)
        msg = can.Message(
            arbitration_id=ident,
            is_extended_id=bool(flags & EXTENDED),
            is_remote_frame=bool(flags & REMOTE),
            is_error_frame=bool(flags & ERROR),
            dlc=dlc,
            data=data[:dlc],
        )
        return msg, False

    def fileno(self) -> int:
        return self._sock.fileno()

    def write(self, ident: int, data: bytes = b"", flags: int = 0) -> None:
        """A frame from the line (the test's end)."""
        self.peer.send(RECORD.pack(ident, flags, len(data), data))

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()


@dataclass(frozen=True)
class Frame:
    arbitration_id: int
    data: bytes


def make(arbitration_id: int, data: bytes, is_extended_id: bool) -> Frame:
    if is_extended_id:
        raise FrameDecodeError(f"extended identifier 0x{arbitration_id:X}")
    return Frame(arbitration_id, data)


@pytest.fixture
def pair_interface(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    import can.interfaces
    import can.util

    monkeypatch.setitem(can.interfaces.BACKENDS, INTERFACE, (__name__, "PairBus"))
    valid = frozenset({*can.util.VALID_INTERFACES, INTERFACE})  # type: ignore[attr-defined]
    monkeypatch.setattr(can.util, "VALID_INTERFACES", valid)
    yield
    for bus in PAIRS.values():
        bus.peer.close()
    PAIRS.clear()


@pytest.fixture
async def link(pair_interface: None) -> AsyncIterator[tuple[CanLink[Frame], PairBus]]:
    channel = f"pair-{uuid.uuid4().hex[:8]}"
    async with CanLink(CanConfig(INTERFACE, channel), make) as opened:
        yield opened, PAIRS[channel]


async def test_a_bus_with_a_descriptor_is_read_by_the_loop_not_by_a_thread(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    assert bus_fileno(bus) == bus.fileno() and lnk._fd == bus.fileno()
    assert lnk._notifier is None
    assert not [t for t in threading.enumerate() if "can.notifier" in t.name.lower()]
    bus.write(0x3CA, b"\x10\x03")
    bus.write(0x3CB, b"")
    got: list[object] = []
    while len(got) < 2:
        got.extend(await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)))
    assert got == [RxFrame(Frame(0x3CA, b"\x10\x03")), RxFrame(Frame(0x3CB, b""))]
    assert lnk.figures.frames_rx == 2
    assert lnk.send([Frame(0x455, b"\x01\x02")]).sent == 1
    assert RECORD.unpack(bus.peer.recv(RECORD.size))[0] == 0x455
    assert lnk.figures.frames_tx == 1


async def test_a_readable_bus_is_drained_in_batches(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    """Each readiness reads what is waiting, at most RX_BATCH (the loop gets its turn)."""
    lnk, bus = link
    asyncio.get_running_loop().remove_reader(bus.fileno())  # the test plays the loop
    for i in range(RX_BATCH + 3):
        bus.write(0x100 + i, bytes([i % 256]))
    lnk._readable()
    assert len(lnk._rx) == RX_BATCH and bus.recv_calls == RX_BATCH  # no read past the batch
    lnk._readable()
    assert len(lnk._rx) == RX_BATCH + 3 and bus.recv_calls == RX_BATCH + 4  # the last: none
    got = await lnk.receive(0.0)
    assert [e.frame.arbitration_id for e in got if isinstance(e, RxFrame)] == [
        0x100 + i for i in range(RX_BATCH + 3)
    ]


async def test_error_and_bad_frames_are_events_and_counted(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    bus.write(0x040, bytes(8), ERROR)  # controller problems: bus-off
    bus.write(0x1ABCDEF, b"\x01", EXTENDED)
    bus.write(0x3CA, b"", REMOTE)
    got: list[object] = []
    while len(got) < 3:
        got.extend(await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)))
    assert got == [
        RxError(frozenset({LineCondition.BUS_OFF})),
        RxBad("extended identifier 0x1ABCDEF"),
        RxBad("remote frame"),
    ]
    assert (lnk.figures.error_frames, lnk.figures.bad_frames, lnk.figures.frames_rx) == (1, 2, 0)


async def test_a_receive_failure_is_an_event_and_reading_goes_on(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    bus.fail_next = OSError(errno.ENETDOWN, "Network is down")
    bus.write(0x3CA, b"\x01")  # readable: the read fails, the frame stays for the next one
    events = await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0))
    assert events[0] == RxFailed("Network is down [Error Code 100]", link_down=True)
    got = events[1:]
    while not got:
        got.extend(await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)))
    assert got == [RxFrame(Frame(0x3CA, b"\x01"))]
    assert lnk.diagnostics()["receive_failures"] == 1
    bus.fail_next = OSError(errno.ENOBUFS, "No buffer space available")
    bus.write(0x3CB)
    events = await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0))
    assert events[0] == RxFailed("No buffer space available [Error Code 105]", link_down=False)


async def test_wake_ends_a_wait_and_a_wake_before_makes_the_next_receive_return(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, _ = link
    loop = asyncio.get_running_loop()
    loop.call_soon(lnk.wake)
    # without the wake the receive would wait an hour: the bound fails the test
    assert await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)) == []
    lnk.wake()
    assert await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)) == []
    assert await lnk.receive(0.001) == []  # the wake was taken: this one waits, for nothing


async def test_receive_without_waiting_still_yields(link: tuple[CanLink[Frame], PairBus]) -> None:
    lnk, _ = link
    ran = asyncio.Event()

    async def other() -> None:
        ran.set()

    task = asyncio.create_task(other())
    assert await lnk.receive(0.0) == []
    assert ran.is_set()
    await task


@pytest.mark.parametrize("order", ["frame, then cancel", "cancel, then frame"])
async def test_a_cancellation_as_a_frame_arrives_ends_the_task_and_keeps_the_frame(
    link: tuple[CanLink[Frame], PairBus], order: str
) -> None:
    """The frame completes the wait and the cancellation comes in the same loop turn:
    the task must end cancelled (not swallow it and wait on, as wait_for could on
    Python 3.11), and the frame must come with the next receive."""
    lnk, bus = link
    task = asyncio.create_task(lnk.receive(3600.0))
    await asyncio.sleep(0)  # the task runs up to its wait
    assert lnk._waiter is not None
    bus.write(0x3CA, b"\x07")
    if order == "frame, then cancel":
        lnk._readable()  # the loop's reader callback, as it runs when the frame is there
        task.cancel()
    else:
        task.cancel()
        lnk._readable()
    with pytest.raises(asyncio.CancelledError):
        await asyncio.wait_for(task, scaled(10.0))
    assert task.cancelled()
    assert lnk._waiter is None
    got = await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0))
    assert got == [RxFrame(Frame(0x3CA, b"\x07"))]


async def test_a_timed_out_wait_leaves_no_timer_and_no_waiter(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    assert await lnk.receive(0.001) == []
    assert lnk._waiter is None
    bus.write(0x3CA)  # what comes after a timed-out wait is taken by the next receive
    got: list[object] = []
    while not got:
        got.extend(await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0)))
    assert got == [RxFrame(Frame(0x3CA, b""))]


async def test_close_removes_the_reader_and_is_idempotent(pair_interface: None) -> None:
    loop = asyncio.get_running_loop()
    channel = f"pair-{uuid.uuid4().hex[:8]}"
    lnk = CanLink(CanConfig(INTERFACE, channel), make)
    async with lnk:
        bus = PAIRS[channel]
        fd = bus.fileno()
        assert loop.remove_reader(fd) is True  # the loop watches it...
        loop.add_reader(fd, lnk._readable)  # ...(put back)
    assert loop.remove_reader(fd) is False  # close removed it
    lnk.close()  # again: nothing to do, no error
    assert not lnk.is_open and bus._sock.fileno() == -1  # the bus was shut down
    lnk.wake()  # nothing to wake: no error
    assert lnk.send([Frame(0x455, b"")]).error == "CAN link is closed"
    with pytest.raises(AdapterError, match="closed"):
        await lnk.receive(0.0)


async def test_a_held_receive_is_not_ended_by_frames_and_takes_them_all_at_its_end(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    """During a hold the loop does not watch the descriptor (no read, no wake-up per
    frame); a wake ends it and everything waiting is drained; the next receive that is
    not held watches the descriptor again."""
    lnk, bus = link
    loop = asyncio.get_running_loop()
    task = asyncio.create_task(lnk.receive(3600.0, True))
    await asyncio.sleep(0)  # the task runs up to its wait
    assert lnk._waiter is not None and not lnk._reading
    for i in range(3):
        bus.write(0x180 + i, bytes([i]))
    for _ in range(10):  # loop turns: a watched descriptor would have been read by now
        await asyncio.sleep(0)
    assert not task.done() and bus.recv_calls == 0
    assert loop.remove_reader(bus.fileno()) is False  # not watched during the hold
    lnk.wake()  # work queued from elsewhere ends the hold at once
    got = await asyncio.wait_for(task, scaled(10.0))
    assert got == [RxFrame(Frame(0x180 + i, bytes([i]))) for i in range(3)]
    assert lnk.figures.frames_rx == 3
    bus.write(0x1A0, b"")  # came after the drain: taken by the next receive
    got = await asyncio.wait_for(lnk.receive(3600.0), scaled(10.0))
    assert got == [RxFrame(Frame(0x1A0, b""))] and lnk._reading
    assert loop.remove_reader(bus.fileno()) is True  # watched again
    loop.add_reader(bus.fileno(), lnk._readable)


async def test_a_held_receive_ends_at_its_time_with_what_came(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    bus.write(0x181, b"\x01")
    await asyncio.sleep(0)  # a watched descriptor: the frame is read into the link
    bus.write(0x182, b"\x02")  # this one waits in the socket
    got = await asyncio.wait_for(lnk.receive(0.01, True), scaled(10.0))
    assert [e.frame.arbitration_id for e in got if isinstance(e, RxFrame)] == [0x181, 0x182]
    assert await lnk.receive(0.0, True) == []  # nothing waiting: nothing, no error


async def test_a_hold_on_a_bus_without_a_descriptor_keeps_frames_a_failure_ends_it() -> None:
    """The Notifier's frames are kept during a hold without ending it; a wake ends it."""
    channel = f"hold-{uuid.uuid4().hex[:8]}"
    async with CanLink(CanConfig("virtual", channel), make) as lnk:
        assert lnk._notifier is not None
        peer = can.Bus(interface="virtual", channel=channel)
        try:
            arrived = asyncio.Event()
            kept = lnk._arrived

            def note(msg: can.Message) -> None:
                kept(msg)
                arrived.set()

            lnk._arrived = note  # type: ignore[method-assign]
            task = asyncio.create_task(lnk.receive(3600.0, True))
            await asyncio.sleep(0)
            peer.send(can.Message(arbitration_id=0x181, data=b"\x05", is_extended_id=False))
            await asyncio.wait_for(arrived.wait(), scaled(10.0))
            assert lnk._rx
            assert not task.done()  # the frame did not end the hold
            lnk._failed(RxFailed("Network is down", link_down=True))  # a failure does
            got = await asyncio.wait_for(task, scaled(10.0))
            assert got == [RxFailed("Network is down", True), RxFrame(Frame(0x181, b"\x05"))]
        finally:
            peer.shutdown()


# ---------------------------------------------------------------------- the burst (0108)


async def test_a_burst_takes_frames_on_the_descriptor_without_the_loop(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    loop = asyncio.get_running_loop()
    bus.write(0x3CA, b"\x10")
    got = lnk.burst(time.monotonic() + scaled(10.0), loop_wake(loop))
    assert got == [RxFrame(Frame(0x3CA, b"\x10"))]
    assert lnk.figures.frames_rx == 1
    # a frame written from another thread while the burst waits: taken when it comes
    writer = threading.Timer(0.01, bus.write, (0x3CB, b"\x01"))
    writer.start()
    try:
        got = lnk.burst(time.monotonic() + scaled(10.0), loop_wake(loop))
    finally:
        writer.join()
    assert got == [RxFrame(Frame(0x3CB, b"\x01"))]


async def test_a_burst_ends_with_nothing_at_its_time_and_none_when_not_for_now(
    link: tuple[CanLink[Frame], PairBus],
) -> None:
    lnk, bus = link
    loop = asyncio.get_running_loop()
    wake = loop_wake(loop)
    assert lnk.burst(time.monotonic() + 0.005, wake) == []  # the time is over, no frame
    assert lnk.burst(time.monotonic() - 1.0, wake) == []
    lnk.wake()  # a wake asked for: the loop's turn
    assert lnk.burst(time.monotonic() + scaled(10.0), wake) is None
    assert await lnk.receive(0.0) == []
    # a callback handed to the loop from another thread: its wake descriptor ends the burst
    handed = threading.Timer(0.01, loop.call_soon_threadsafe, (lambda: None,))
    handed.start()
    try:
        start = time.monotonic()
        assert lnk.burst(start + scaled(10.0), wake) is None
        assert time.monotonic() - start < scaled(5.0)
    finally:
        handed.join()
    bus.write(0x3CA)
    lnk._readable()  # the loop's reader, played by the test: a frame already waiting
    assert lnk.burst(time.monotonic() + scaled(10.0), wake) is None  # already waiting
    assert await lnk.receive(0.0) == [RxFrame(Frame(0x3CA, b""))]


async def test_a_burst_on_a_bus_without_a_descriptor_is_never_for_now() -> None:
    channel = f"burst-{uuid.uuid4().hex[:8]}"
    async with CanLink(CanConfig("virtual", channel), make) as lnk:
        assert lnk.burst(time.monotonic() + 1.0, -1) is None


class _Echo(CanProtocol[Frame, Any, Any]):
    """A CAN protocol of the driver that counts the frames stepped and asks nothing (the
    optional hooks keep their defaults)."""

    def __init__(self, frames: int) -> None:
        self.stepped = 0
        self.frames = frames
        self.all_in = asyncio.Event()
        self.taken = threading.Semaphore(0)  # one release per frame stepped (a far end's cue)

    def event(self, received: CanEvent[Frame]) -> Any:
        self.stepped += 1
        self.taken.release()
        if self.stepped == self.frames:
            self.all_in.set()
        return received

    def frame(self, action: Any) -> None:
        return None

    def handle(self, now: float, action: Any) -> None:
        return None

    def send_failed(self, result: SendResult) -> list[Any]:
        return []


class _Quiet:
    """An engine with nothing to do (a deadline far off)."""

    def step(self, now: float, event: object = None) -> list[object]:
        return []

    def next_deadline(self) -> float | None:
        return time.monotonic() + 3600.0


@pytest.mark.parametrize("mode", ["on", "off"])
async def test_the_driver_takes_frames_in_bursts_without_a_loop_turn_each(
    link: tuple[CanLink[Frame], PairBus], monkeypatch: pytest.MonkeyPatch, mode: str
) -> None:
    """Frames one after the other, each once the one before was stepped, as poll responses
    come: with the burst the driver takes them on the bus's descriptor, the link's receive
    awaited only when a burst ends (the loop's turn); without it
    (DRIVE_GATEWAY_CAN_BURST=off) one await per frame or so."""
    monkeypatch.setenv("DRIVE_GATEWAY_CAN_BURST", mode)
    lnk, bus = link
    frames = 200
    protocol = _Echo(frames)
    awaited = 0
    waiting = asyncio.Event()  # the driver reached its first wait
    receive = lnk.receive

    async def counted(wait: float, hold: bool = False) -> list[Any]:
        nonlocal awaited
        awaited += 1
        waiting.set()
        return await receive(wait, hold)

    monkeypatch.setattr(lnk, "receive", counted)
    driver = CanDriver(_Quiet(), lnk, protocol)
    task = asyncio.create_task(driver.run())

    def write() -> None:  # the far end: the next response once the last one was taken
        for i in range(frames):
            bus.write(0x300 + i % 64, bytes([i % 256]))
            if not protocol.taken.acquire(timeout=scaled(10.0)):
                return  # the driver stopped taking frames: the test's bound fails it

    writer = threading.Thread(target=write)
    try:
        await asyncio.wait_for(waiting.wait(), scaled(10.0))
        start = awaited
        writer.start()
        await asyncio.wait_for(protocol.all_in.wait(), scaled(30.0))  # no timer meanwhile
        turns = awaited - start
    finally:
        if writer.ident is not None:
            writer.join()
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    assert protocol.stepped == frames
    if mode == "on":
        assert turns < frames / 4, turns
    else:
        assert turns > frames / 2, turns


async def test_the_driver_bursts_only_while_its_loop_has_nothing_else_to_do(
    link: tuple[CanLink[Frame], PairBus], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("DRIVE_GATEWAY_CAN_BURST", raising=False)
    lnk, _ = link
    loop = asyncio.get_running_loop()
    burst = Burst.of(loop, time.monotonic)
    assert burst is not None
    assert Burst.of(loop, lambda: 0.0) is None  # a test's clock: never
    now = time.monotonic()
    assert burst.wait(lnk, now + 0.001) == []  # the engine's deadline came, no frame
    assert burst.wait(lnk, now - 1.0) is None  # a deadline already past: the loop's turn
    ran: asyncio.Future[None] = loop.create_future()
    loop.call_soon(ran.set_result, None)  # a callback waiting: the loop's turn
    assert burst.wait(lnk, time.monotonic() + 1.0) is None
    await ran  # the loop ran it: nothing waits any more
    timer = loop.call_later(0.001, lambda: None)  # the loop's next timer ends the burst
    try:
        start = time.monotonic()
        assert burst.wait(lnk, start + scaled(10.0)) is None
        assert time.monotonic() - start < scaled(1.0)
    finally:
        timer.cancel()
    monkeypatch.setenv("DRIVE_GATEWAY_CAN_BURST", "off")
    assert Burst.of(loop, time.monotonic) is None
