"""Issue 32 items 11 and 12 on a line: the adapter against simulated CiA 402 drives on
python-can ``virtual``, with the real hub."""

from __future__ import annotations

import asyncio
from pathlib import Path

import can
import pytest

from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import State
from adapters.canopen.sim.node import SimNodeConfig, _maps
from gateway.adapter import EventKind
from gateway.errors import CommandRejected, LineHeld
from gateway.model import CommState, DriveCommand, DriveState, Source
from tests.canopen.integration.conftest import EDS, drive, gateway_side, rig
from tests.support.timing import scaled


def online(s: DriveState) -> bool:
    return s.comm is CommState.ONLINE


def turning(s: DriveState) -> bool:
    return s.running and s.speed_rpm is not None and s.speed_rpm > 590


async def test_a_second_gateway_on_the_line_refuses_to_start_and_the_first_runs_on() -> None:
    """A second CANopen master joining the channel knocked the first gateway's running
    drive out (it ended faulted)."""
    async with rig([drive(5, comm_loss_option=1)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", turning)
        hub2, second = gateway_side([drive(5)], r.adapter.options.channel)
        with hub2.subscribe_events() as events:
            with pytest.raises(LineHeld) as info:
                await asyncio.wait_for(second.run(hub2), scaled(5))
            ev = await asyncio.wait_for(events.get(), scaled(1))
        assert "another master is on this line" in str(info.value)
        assert ev.kind is EventKind.BUS and "the gateway does not start on it" in ev.text
        assert not second.claimed.is_set()
        assert r.adapter.claimed.is_set()
        state = r.hub.state("d5")
        assert state.comm is CommState.ONLINE and state.running
        assert r.sim.node(5).drive.state is State.OPERATION_ENABLED


async def test_a_heartbeat_with_the_gateways_node_id_is_another_master() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        other = can.Bus(interface="virtual", channel=r.adapter.options.channel)
        try:
            hb = f.encode_heartbeat(127, f.NmtState.OPERATIONAL)
            other.send(can.Message(arbitration_id=hb.cob_id, data=hb.data, is_extended_id=False))
            ev = await r.event(lambda e: "another master on the line" in e.text)
            assert "a heartbeat with the gateway's own node id 127" in ev.text
            state = await r.wait("d5", lambda s: s.doubtful)
            assert state.comm is CommState.ONLINE
        finally:
            other.shutdown()


async def test_a_forged_tpdo1_makes_the_drive_doubtful_and_a_run_is_refused() -> None:
    """A second node sending TPDO1 with a drive's id showed a stopped drive running."""
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        other = can.Bus(interface="virtual", channel=r.adapter.options.channel)
        try:
            running = bytes.fromhex("2702dc05") + bytes(4)  # operation enabled, 1500 rpm
            for _ in range(3):
                other.send(
                    can.Message(arbitration_id=f.tpdo_id(1, 5), data=running, is_extended_id=False)
                )
            ev = await r.event(lambda e: "a second TPDO1 in one SYNC cycle" in e.text)
            assert ev.kind is EventKind.BUS and ev.data["node"] == 5
            await r.wait("d5", lambda s: s.doubtful)
        finally:
            other.shutdown()
        with pytest.raises(CommandRejected, match="doubtful"):
            r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        assert r.sim.node(5).drive.state is not State.OPERATION_ENABLED


async def test_a_silent_drive_goes_offline_on_its_missing_tpdo1() -> None:
    """A powered-off drive was shown running for 8 s while another node sent heartbeats
    with its id: its TPDO1 is what keeps it online."""
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", turning)
        node = r.sim.node(5)
        node.refuse_sdo(True)
        with node.lock:  # its TPDO1 stops, its heartbeat goes on
            for pdo_map in _maps(node.local.tpdo).values():
                pdo_map.enabled = False
        ev = await r.event(lambda e: e.text.startswith("drive offline: no TPDO1"), within=2)
        assert ev.kind.value == "comm"
        state = r.hub.state("d5")
        assert state.comm is CommState.OFFLINE and not state.running


@pytest.fixture
def refusing_eds(tmp_path: Path) -> Path:
    """The drive's own dictionary: 0x6078 is not mappable there (the bring-up fails after
    the heartbeat consumer is written)."""
    text = Path(EDS).read_text()
    section = text.index("[6078]")
    end = text.index("[", section + 1)
    path = tmp_path / "drive.eds"
    path.write_text(
        text[:section] + text[section:end].replace("PDOMapping=1", "PDOMapping=0") + text[end:]
    )
    return path


async def test_a_drive_whose_bring_up_failed_does_not_watch_the_gateway(
    refusing_eds: Path,
) -> None:
    """Its 0x1016 still watched the gateway's heartbeat, so a clean stop faulted it (EMCY
    0x8130)."""
    sims = [SimNodeConfig(node_id=5, eds=refusing_eds, ramp_time=0.2, abort_connection_option=1)]
    async with rig([drive(5)], sims=sims) as r:
        await r.event(lambda e: e.text.startswith("not configured"))
        node = r.sim.node(5)
        await r.until(lambda: node._hb_node == 0)  # 0x1016:1 switched off by SDO
        r.task.cancel()
        await asyncio.gather(r.task, return_exceptions=True)
        assert node.drive.state is not State.FAULT
        assert node._hb_watch.deadline() is None  # nothing left to fire
