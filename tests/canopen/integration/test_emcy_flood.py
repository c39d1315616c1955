"""A flood of forged EMCY frames on the line (adapters/canopen/master/emcy.py, the hub's
folding): counted, a bounded number decoded and a bounded number of events; the drive
stays online and running, and a genuine fault after it still shows with its code. The
adapter against a simulated CiA 402 drive on python-can ``virtual``, with the real hub."""

from __future__ import annotations

import asyncio
import time

import can

from adapters.canopen.codec import frames as f
from adapters.canopen.master.emcy import EMCY_BURST, EMCY_RATE
from gateway.adapter import Event, EventKind
from gateway.eventlog import REPEATS
from gateway.model import CommState, DriveCommand, DriveState, DriveStatus, Source
from tests.canopen.integration.conftest import Rig, drive, rig

FLOOD = 2000


def online(s: DriveState) -> bool:
    return s.comm is CommState.ONLINE


def turning(s: DriveState) -> bool:
    return s.running and s.speed_rpm is not None and s.speed_rpm > 590


async def flood(r: Rig, frame: f.CanFrame, count: int) -> None:
    """``count`` copies of ``frame`` from another station, 10 every 5 ms (2,000 a second:
    the line's own frames go on between them, as on a wire)."""
    other = can.Bus(interface="virtual", channel=r.adapter.options.channel)
    msg = can.Message(arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=False)
    try:
        for i in range(count):
            other.send(msg)
            if i % 10 == 9:
                await asyncio.sleep(0.005)
    finally:
        other.shutdown()


def heard(r: Rig) -> int:
    """EMCY frames of node 5 the engine took or dropped."""
    engine = r.adapter.engine
    assert engine is not None
    return engine.nodes[5].figures["emcy_rx"] + engine.figures["emcy_dropped"]


async def test_an_emcy_flood_is_counted_and_gives_a_bounded_number_of_events() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", turning)
        r.events.drain()  # the bring-up's
        before, folded = heard(r), r.hub.events_folded
        start = time.monotonic()
        await flood(r, f.encode_emcy(5, f.Emcy(0x8110, 0x11)), FLOOD)
        await r.until(lambda: heard(r) >= before + FLOOD)
        elapsed = time.monotonic() - start
        diag = r.adapter.diagnostics()
        dropped = diag["emcy_dropped"]
        taken = FLOOD - dropped
        assert diag["drives"]["d5"]["emcy_dropped"] == dropped
        assert taken <= EMCY_BURST + EMCY_RATE * elapsed + 1
        seen: list[Event] = r.events.drain()
        forged = [e for e in seen if e.kind is EventKind.FAULT and "EMCY 0x8110" in e.text]
        assert 1 <= len(forged) <= taken
        assert forged[0].data["code"] == 0x8110
        # every frame taken is an event, or a repeat the hub counted (told once per window)
        firsts = [e for e in forged if REPEATS not in e.data]
        assert len(firsts) + r.hub.events_folded - folded >= taken
        assert not [e for e in seen if e.kind is EventKind.COMM]  # never offline
        state = r.hub.state("d5")
        assert state.comm is CommState.ONLINE and state.running
        assert r.hub.desired("d5").run  # nothing cleared the run
        # a genuine fault after the flood: the statusword and the 0x603F read show it
        r.sim.node(5).inject_fault(0x2310)
        state = await r.wait(
            "d5", lambda s: s.status is DriveStatus.FAULTED and s.fault_code == 0x2310
        )
        assert state.fault_text == "continuous over current"
