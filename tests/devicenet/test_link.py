"""The python-can link on the virtual interface: conversion, send/receive, failures, close."""

from __future__ import annotations

import asyncio
import errno
import os
import socket
import uuid
from types import SimpleNamespace

import can
import pytest

from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.link import (
    CanLink,
    LinkConfig,
    RxBad,
    RxError,
    RxFailed,
    RxFrame,
    convert,
)
from adapters.link.can import (
    LINK_DOWN_ERRNOS,
    RX_BUFFER_BYTES,
    enlarge_receive_buffer,
    error_number,
    open_problem,
)
from adapters.link.canerror import LineCondition
from gateway.errors import AdapterError
from tests.support.timing import scaled


def channel() -> str:
    return f"link-{uuid.uuid4().hex[:10]}"


def test_convert() -> None:
    ok = can.Message(arbitration_id=0x3CA, data=b"\x10\x03\x00\x00", is_extended_id=False)
    assert convert(ok) == RxFrame(CanFrame(0x3CA, b"\x10\x03\x00\x00"))
    error = can.Message(arbitration_id=0x040, is_error_frame=True, data=bytes(8))
    assert convert(error) == RxError(frozenset({LineCondition.BUS_OFF}))
    ext = can.Message(arbitration_id=0x3CA, is_extended_id=True)
    assert isinstance(convert(ext), RxBad)
    remote = can.Message(arbitration_id=0x3CA, is_extended_id=False, is_remote_frame=True)
    assert convert(remote) == RxBad("remote frame")
    fd = can.Message(arbitration_id=0x3CA, is_extended_id=False, is_fd=True, data=bytes(12))
    assert convert(fd) == RxBad("CAN FD frame")


def test_frames_as_socketcan_delivers_them_on_vcan() -> None:
    """On vcan every frame comes from a socket of this host, and python-can marks such
    frames ``is_rx=False`` (MSG_DONTROUTE); they come with a channel name and a timestamp.
    None of that may make a frame be dropped (virtual never sets them so)."""
    looped = can.Message(
        arbitration_id=0x3CA,
        data=b"\x10\x03\x00\x00",
        is_extended_id=False,
        is_rx=False,
        channel="vcan0",
        timestamp=1234.5,
    )
    assert convert(looped) == RxFrame(CanFrame(0x3CA, b"\x10\x03\x00\x00"))


async def test_receive_without_waiting_still_yields() -> None:
    """A loop that polls the link with no wait must still let the event loop run."""
    async with CanLink(LinkConfig("virtual", channel())) as link:
        ran = asyncio.Event()

        async def other() -> None:
            ran.set()

        task = asyncio.create_task(other())
        assert await link.receive(0.0) == []
        assert ran.is_set()
        await task


def test_udp_multicast_is_refused() -> None:
    with pytest.raises(AdapterError, match="udp_multicast is not supported"):
        CanLink(LinkConfig("udp_multicast", "x"))


async def test_open_failure_is_an_adapter_error() -> None:
    link = CanLink(LinkConfig("no-such-interface", "x"))
    with pytest.raises(AdapterError, match="cannot open CAN interface 'no-such-interface'"):
        async with link:
            pass
    assert not link.is_open


async def test_frames_go_both_ways_with_11_bit_ids() -> None:
    ch = channel()
    async with CanLink(LinkConfig("virtual", ch)) as a, CanLink(LinkConfig("virtual", ch)) as b:
        raw = can.Bus(interface="virtual", channel=ch)
        try:
            result = a.send([CanFrame(0x455, b"\x61\x00\x08\x07"), CanFrame(0x7EF, b"")])
            assert (result.sent, result.dropped, result.error) == (2, 0, None)
            got: list[object] = []
            while len(got) < 2:
                got.extend(await b.receive(1.0))
            assert got == [
                RxFrame(CanFrame(0x455, b"\x61\x00\x08\x07")),
                RxFrame(CanFrame(0x7EF, b"")),
            ]
            seen = raw.recv(1.0)
            assert (
                seen is not None and seen.is_extended_id is False and seen.arbitration_id == 0x455
            )
            assert await a.receive(0.01) == []  # our own frames do not come back
            assert a.figures.frames_tx == 2 and b.figures.frames_rx == 2
        finally:
            raw.shutdown()


async def test_bad_frames_are_counted_not_raised() -> None:
    ch = channel()
    async with CanLink(LinkConfig("virtual", ch)) as link:
        raw = can.Bus(interface="virtual", channel=ch)
        try:
            raw.send(can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01"))
            events = await link.receive(1.0)
            assert len(events) == 1 and isinstance(events[0], RxBad)
            assert link.figures.bad_frames == 1
        finally:
            raw.shutdown()


async def test_wake_ends_a_wait() -> None:
    async with CanLink(LinkConfig("virtual", channel())) as link:
        loop = asyncio.get_running_loop()
        loop.call_later(0.02, link.wake)
        # without the wake the receive would wait an hour: the bound fails the test
        assert await asyncio.wait_for(link.receive(3600.0), 60.0) == []


async def test_send_failure_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    async with CanLink(LinkConfig("virtual", channel())) as link:
        calls = []

        def full(msg: can.Message, timeout: float | None = None) -> None:
            calls.append(msg)
            if len(calls) > 1:
                raise can.CanOperationError("Transmit buffer full")

        monkeypatch.setattr(link._bus, "send", full)
        frames = [CanFrame(0x455, b""), CanFrame(0x45D, b""), CanFrame(0x465, b"")]
        result = link.send(frames)
        assert (result.sent, result.dropped, result.error) == (1, 2, "Transmit buffer full")
        assert link.diagnostics()["send_failures"] == 1


async def test_close_is_idempotent_and_sending_after_close_fails() -> None:
    link = CanLink(LinkConfig("virtual", channel()))
    async with link:
        assert link.is_open
    link.close()
    assert link.send([CanFrame(0x455, b"")]).error == "CAN link is closed"
    with pytest.raises(AdapterError, match="closed"):
        await link.receive(0.0)


def test_open_problem_says_what_is_missing_and_what_to_do() -> None:
    """A kernel without AF_CAN fails with a bare errno 97; say what to do instead."""
    vcan = LinkConfig("socketcan", "vcan0")
    no_af_can = OSError(errno.EAFNOSUPPORT, "Address family not supported by protocol")
    text = open_problem(vcan, no_af_can)
    assert text.startswith("cannot open CAN interface 'socketcan' channel 'vcan0': [Errno 97]")
    assert "no SocketCAN (AF_CAN" in text and "modprobe vcan" in text
    assert "ip link add dev vcan0 type vcan" in text and "--interface virtual" in text
    no_device = OSError(errno.ENODEV, "No such device")
    text = open_problem(vcan, no_device)
    assert "ip link add dev vcan0 type vcan && sudo ip link set up vcan0" in text
    text = open_problem(LinkConfig("socketcan", "can0"), no_device)
    assert "ip link set can0 up type can bitrate" in text
    other = LinkConfig("virtual", "x")
    assert (
        open_problem(other, no_af_can)
        == f"cannot open CAN interface 'virtual' channel 'x': {no_af_can}"
    )


def test_send_failures_say_whether_the_interface_is_down() -> None:
    """ENETDOWN: the interface is down (every connection is gone); ENOBUFS: a full queue."""
    down = can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
    full = can.CanOperationError("Failed to transmit: No buffer space available", errno.ENOBUFS)
    assert error_number(down) in LINK_DOWN_ERRNOS
    assert error_number(full) not in LINK_DOWN_ERRNOS
    assert error_number(can.CanOperationError("Transmit buffer full")) is None


async def test_a_receive_error_is_an_event_not_an_exception_in_the_notifier() -> None:
    """A SocketCAN socket reports ENETDOWN once on receive when its interface goes down;
    it comes out of receive() as RxFailed and the link keeps receiving."""
    ch = channel()
    async with CanLink(LinkConfig("virtual", ch)) as link:
        assert link._bus is not None
        inner = link._bus
        raw = can.Bus(interface="virtual", channel=ch)
        try:
            failing = True
            recv = type(inner).recv

            def flaky(timeout: float | None = None) -> can.Message | None:
                nonlocal failing
                if failing:
                    failing = False
                    raise can.CanOperationError("Error receiving: Network is down", errno.ENETDOWN)
                return recv(inner, timeout)

            link._bus.recv = link._guarded(flaky)  # type: ignore[method-assign,assignment]
            events = await link.receive(scaled(2.0))
            assert events == [
                RxFailed("Error receiving: Network is down [Error Code 100]", link_down=True)
            ]
            raw.send(can.Message(arbitration_id=0x3CA, data=b"\x01", is_extended_id=False))
            assert await link.receive(scaled(2.0)) == [RxFrame(CanFrame(0x3CA, b"\x01"))]
            assert link.diagnostics()["receive_failures"] == 1
        finally:
            raw.shutdown()


def test_a_socket_bus_gets_a_large_receive_queue() -> None:
    """SocketCAN's queue (a kernel socket) is enlarged; as root past net.core.rmem_max."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        default = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        granted = enlarge_receive_buffer(SimpleNamespace(socket=sock))  # type: ignore[arg-type]
        assert granted == sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        assert granted >= (RX_BUFFER_BYTES if os.geteuid() == 0 else default)


def test_a_bus_without_a_socket_has_no_receive_queue_to_size() -> None:
    with can.Bus(interface="virtual", channel=channel()) as bus:
        assert enlarge_receive_buffer(bus) is None
