"""What only a kernel's SocketCAN gives, on vcan0: a transmit queue that fills up (ENOBUFS),
the interface going down and coming back, and two processes on one bus (the gateway here,
``drive-gateway sim devicenet`` in another process). ``virtual`` can give none of these.

All are marked ``vcan``: ``make test-vcan`` runs them (tests/vcan_vm), in a VM where this
kernel has no AF_CAN. Waits are on hub states and events, scaled by the suite's time scale.
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Callable

import can
import pytest

from adapters.devicenet.link import CanLink, LinkConfig, RxFrame
from adapters.link.can import RX_BUFFER_BYTES
from gateway.adapter import Event, EventKind
from gateway.model import CommState, DriveCommand, DriveState, DriveStatus, Source
from tests.devicenet.integration.conftest import (
    SIM_STOP_BOUND,
    VCAN,
    Rig,
    aadmin,
    drive,
    rig,
    sim_process,
)
from tests.support.timing import scaled

pytestmark = pytest.mark.vcan

Z = Source.ZENOH


def online(s: DriveState) -> bool:
    return s.comm is CommState.ONLINE


def offline(s: DriveState) -> bool:
    return s.comm is CommState.OFFLINE


def line_figures(r: Rig) -> dict[str, object]:
    return {k: v for k, v in r.adapter.diagnostics().items() if k != "drives"}


def nothing_lost_silently(r: Rig) -> None:
    """Every frame the scanner asked for went out or is counted as dropped."""
    line = line_figures(r)
    assert line["frames_tx"] == line["link_frames_tx"] + line["tx_dropped"], line  # type: ignore[operator]


async def test_a_full_transmit_queue_is_counted_and_backed_off(vcan_admin: LinkConfig) -> None:
    """A transmit queue that fills up: ENOBUFS on the socket (python-can's virtual bus
    never gives it). The scanner counts every frame not sent, reports once, backs off
    (no spinning on a full queue), and the line recovers when the queue drains.

    The queue: a token bucket on vcan0 passing about 60 frames/s with room for two
    (16-byte frames at 8 kbit/s, limit 32 bytes), against ten drives polled every 10 ms.
    """
    macs = range(1, 11)
    async with rig(vcan_admin, [drive(m) for m in macs]) as r:
        for m in macs:
            await r.wait(f"d{m}", online, within=15.0)
        r.hub.submit("d1", Z, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d1", lambda s: s.running)
        link = r.adapter.link
        assert link is not None
        before = link.figures.send_failures
        started = time.monotonic()
        await aadmin("tc", "qdisc", "replace", "dev", VCAN, "root", "tbf", "rate", "8kbit",
              "burst", "1000", "limit", "32")  # fmt: skip
        ev = await r.event(lambda e: "cannot send" in e.text and "No buffer space" in e.text)
        assert ev.kind is EventKind.BUS and "backing off" in ev.text
        await r.until(lambda: link.figures.send_failures >= before + 20, within=20.0)
        window = time.monotonic() - started
        await aadmin("tc", "qdisc", "del", "dev", VCAN, "root")
        failures = link.figures.send_failures - before
        assert failures < 20 + window / 0.01  # backing off from 10 ms, never spinning
        line = line_figures(r)
        assert line["tx_failures"] == link.figures.send_failures
        assert line["tx_dropped"] >= line["tx_failures"]  # type: ignore[operator]
        assert "No buffer space" in str(line["last_tx_failure"])
        nothing_lost_silently(r)
        for m in macs:  # the line recovers by itself: no restart
            await r.wait(f"d{m}", online, within=15.0)
        assert not r.task.done()
        nothing_lost_silently(r)


async def test_interface_down_takes_the_drives_offline_and_up_brings_them_back_stopped(
    vcan_admin: LinkConfig,
) -> None:
    """``ip link set vcan0 down`` while a drive runs: every drive goes offline at once
    with the reason (not after 4 x EPR of silence); ``up``: they come back stopped, and
    the one that ran needs a new run command (rule 1)."""
    async with rig(vcan_admin, [drive(2), drive(3)]) as r:
        await r.wait("d2", online)
        await r.wait("d3", online)
        r.hub.submit("d2", Z, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d2", lambda s: s.running)
        await aadmin("ip", "link", "set", "down", VCAN)
        for drive_id in ("d2", "d3"):
            ev = await r.event(_event_starting(drive_id, "CAN interface down"))
            assert ev.kind is EventKind.BUS and "Network is down" in ev.text, ev.text
            await r.wait(drive_id, offline)
        # the drives' own offline events say so too, unless silence (4 x EPR) was noticed first
        gone = [e for e in r.seen if e.text.startswith("drive offline")]
        assert all("CAN interface down" in e.text or "no data" in e.text for e in gone), gone
        line = line_figures(r)
        assert line["link_down"] >= 1  # type: ignore[operator]
        await aadmin("ip", "link", "set", "up", VCAN)
        for drive_id in ("d2", "d3"):  # P313 = 2 (no action): d2 ran on alone, is stopped
            back = await r.wait(drive_id, lambda s: online(s) and not s.running, within=15.0)
            assert back.status is DriveStatus.READY
        assert not r.hub.desired("d2").run
        await r.until(lambda: not r.sim.node(2).drive.motor.running)
        assert not r.task.done()
        r.hub.submit("d2", Z, DriveCommand(run=True, speed_rpm=600.0))  # a new command runs it
        await r.wait("d2", lambda s: s.running)


async def test_the_gateway_and_a_simulator_process_share_vcan0(vcan_line: LinkConfig) -> None:
    """Two processes on one bus: the scanner here, a simulated CFW-08 in another process.
    It comes online, runs, stops, and goes offline when the other process ends."""
    async with (
        sim_process("9", "--ramp-time", "0.2") as proc,
        rig(vcan_line, [drive(9)], sims=[]) as r,
    ):
        state = await r.wait("d9", online, within=15.0)
        assert state.status is DriveStatus.READY and not state.running
        assert state.values["P313"] == 2
        r.hub.submit("d9", Z, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d9", lambda s: s.at_reference and s.speed_rpm == 900.0)
        r.hub.submit("d9", Z, DriveCommand(run=False))
        await r.wait("d9", lambda s: not s.running and s.speed_rpm == 0.0)
        proc.terminate()
        assert await asyncio.wait_for(proc.wait(), scaled(SIM_STOP_BOUND)) == 0
        ev = await r.event(_event_starting("d9", "drive offline"))
        assert "no data" in ev.text
        await r.wait("d9", offline)


def _event_starting(drive_id: str, text: str) -> Callable[[Event], bool]:
    return lambda e: e.drive_id == drive_id and e.text.startswith(text)


BURST = 2000  # frames: several times what the kernel's default receive queue holds (~300)


async def test_the_receive_queue_holds_a_burst_while_the_loop_is_busy(
    vcan_line: LinkConfig,
) -> None:
    """A socket's receive queue is all that holds frames while the event loop is busy
    (a GC pause, a loaded machine); a full queue drops frames in the kernel, silently.
    The link asks for a queue of about a second of a full line: a burst of 2,000 frames
    sent while the loop cannot read arrives whole. With the kernel's default queue
    (208 KiB) only a few hundred arrived, and explicit responses were lost that way."""
    async with CanLink(vcan_line) as link:
        with can.Bus(interface="socketcan", channel=vcan_line.channel) as sender:
            for i in range(BURST):  # the loop is blocked here: nothing is read meanwhile
                msg_id = 0x400 | (i % 64) << 3 | 3
                data = i.to_bytes(2, "little")
                sender.send(can.Message(arbitration_id=msg_id, data=data, is_extended_id=False))
        got: list[int] = []
        while events := await link.receive(scaled(1.0)):
            got.extend(
                int.from_bytes(e.frame.data, "little") for e in events if isinstance(e, RxFrame)
            )
        assert got == list(range(BURST)), f"{len(got)} of {BURST} frames arrived"
        granted = link.diagnostics()["rx_buffer_bytes"]
        assert granted is not None and granted >= (RX_BUFFER_BYTES if os.geteuid() == 0 else 1)
