"""The CANopen adapter against simulated CiA 402 drives on python-can ``virtual``."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import can
import pytest

from adapters.canopen.codec.cia402 import State
from adapters.canopen.codec.frames import NmtState
from adapters.canopen.sim.node import SimNodeConfig
from gateway.errors import CommandRejected, DriveOffline, ParameterError, ParameterNotWritable
from gateway.model import CommState, Direction, DriveCommand, DriveState, DriveStatus, Source
from tests.canopen.integration.conftest import EDS, drive, gateway_side, rig
from tests.support.timing import scaled


def online(s: DriveState) -> bool:
    return s.comm is CommState.ONLINE


async def test_two_drives_come_online_and_run() -> None:
    async with rig([drive(5), drive(6, mode="profile_velocity")]) as r:
        for d in ("d5", "d6"):
            state = await r.wait(d, online)
            assert state.status is DriveStatus.READY
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=900.0))
        state = await r.wait(
            "d5", lambda s: s.running and s.speed_rpm is not None and s.speed_rpm > 890
        )
        assert state.status is DriveStatus.RUNNING
        assert state.direction is Direction.FORWARD
        assert r.sim.node(5).drive.motor.speed > 0
        r.hub.submit("d6", Source.MODBUS, DriveCommand(run=True, speed_rpm=-600.0))
        state = await r.wait("d6", lambda s: s.speed_rpm is not None and s.speed_rpm < -590)
        assert state.direction is Direction.REVERSE


async def test_quick_stop_is_honoured_and_released_without_a_restart() -> None:
    async with rig([drive(5, quick_stop_option=6)]) as r:
        ev = await r.event(lambda e: e.kind.value == "config" and "0x605A = 6" in e.text)
        assert "stay in quick stop active" in ev.text
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d5", lambda s: s.speed_rpm is not None and s.speed_rpm > 890)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(quick_stop=True))
        await r.until(lambda: r.sim.node(5).drive.state is State.QUICK_STOP_ACTIVE)
        state = await r.wait("d5", lambda s: s.speed_rpm == 0.0)
        assert state.status is DriveStatus.STOPPING  # held in quick stop active (option 6)
        assert not r.hub.desired("d5").run
        r.hub.submit("d5", Source.MODBUS, DriveCommand(quick_stop=False))
        # released through Disable voltage (transition 12), never straight back to operation
        state = await r.wait("d5", lambda s: s.status is DriveStatus.READY)
        assert r.sim.node(5).drive.state is not State.OPERATION_ENABLED


async def test_fault_reads_code_and_reset_is_one_edge() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", lambda s: s.running)
        r.sim.node(5).inject_fault(0x2310)
        state = await r.wait("d5", lambda s: s.status is DriveStatus.FAULTED)
        ev = await r.event(lambda e: e.text.startswith("EMCY 0x2310"))
        assert "continuous over current" in ev.text
        await r.event(lambda e: e.text.startswith("fault read: 0x603F = 0x2310"))
        state = await r.wait("d5", lambda s: s.fault_code == 0x2310)
        assert state.fault_text == "continuous over current"
        assert not r.hub.desired("d5").run
        with pytest.raises(CommandRejected):
            r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True))
        resets = r.sim.node(5).drive
        r.hub.submit("d5", Source.MODBUS, DriveCommand(fault_reset=True))
        await r.event(lambda e: e.text.startswith("fault reset sent"))
        state = await r.wait("d5", lambda s: s.status is DriveStatus.READY)
        assert state.fault_code is None and not state.running
        assert resets.state is not State.FAULT
        # the reset bit went back to 0 and stays there: no second edge on its own
        await r.until(lambda: not r.sim.node(5).drive.controlword & 0x80)
        r.sim.node(5).inject_fault(0x4310)
        await r.wait("d5", lambda s: s.status is DriveStatus.FAULTED and s.fault_code == 0x4310)
        for _ in range(10):
            await r.sim.until(lambda: True)
        assert r.sim.node(5).drive.state is State.FAULT


async def test_heartbeat_loss_takes_the_drive_offline_and_it_returns_stopped() -> None:
    async with rig([drive(5, comm_loss_option=3)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", lambda s: s.running and s.speed_rpm is not None and s.speed_rpm > 590)
        r.sim.node(5).silence(True)
        state = await r.wait("d5", lambda s: s.comm is CommState.OFFLINE)
        ev = await r.event(lambda e: e.text.startswith("drive offline: no "))  # TPDO1 or heartbeat
        assert ev.kind.value == "comm"
        r.sim.node(5).silence(False)
        state = await r.wait("d5", online, within=10)
        assert not r.hub.desired("d5").run  # the hub cleared the run: rule 1
        await r.event(lambda e: "run command cleared" in e.text)
        state = await r.wait("d5", lambda s: s.status is DriveStatus.READY and s.speed_rpm == 0)
        assert not state.running
        assert r.sim.node(5).drive.state is not State.OPERATION_ENABLED


async def test_parameters_by_sdo_with_abort_texts() -> None:
    async with rig([drive(5, writable_params=["0x605A", "0x2000:4"])]) as r:
        await r.wait("d5", online)
        assert await r.hub.read_param("d5", 0x6046, 2) == 1800
        await r.hub.write_param("d5", 0x605A, 1, 0)
        assert await r.hub.read_param("d5", 0x605A, 0) == 1
        with pytest.raises(ParameterError) as info:
            await r.hub.write_param("d5", 0x605A, 3, 0)  # the simulator implements 0, 1, 2, 5, 6
        assert str(info.value.text).startswith("0x06090030 value range of parameter exceeded")
        assert info.value.code == 0x06090030
        assert await r.hub.read_param("d5", 0x605A, 0) == 1  # nothing changed
        with pytest.raises(ParameterError) as info:
            await r.hub.read_param("d5", 0x6099, 0)
        assert "0x06020000 object does not exist" in str(info.value)
        with pytest.raises(ParameterNotWritable):
            await r.hub.write_param("d5", 0x2000, 1, 3)  # only 0x2000:4 of 0x2000
        await r.hub.write_param("d5", 0x2000, 1800, 4)


@pytest.fixture
def drive_eds(tmp_path: Path) -> Path:
    """The drive's own dictionary: 0x6078 is not mappable there."""
    text = Path(EDS).read_text()
    section = text.index("[6078]")
    end = text.index("[", section + 1)
    drive_eds = tmp_path / "drive.eds"
    drive_eds.write_text(
        text[:section] + text[section:end].replace("PDOMapping=1", "PDOMapping=0") + text[end:]
    )
    return drive_eds


async def test_a_pdo_mapping_the_node_refuses(drive_eds: Path) -> None:
    """The gateway's EDS says 0x6078 maps; the drive's own dictionary says it does not."""
    sims = [SimNodeConfig(node_id=5, eds=drive_eds, ramp_time=0.2)]
    async with rig([drive(5)], sims=sims) as r:
        ev = await r.event(lambda e: e.text.startswith("not configured"))
        assert ev.text == (
            "not configured: node 5: TPDO1 mapping 0x1A00:3 = 0x6078: write of 0x1A00:3 = "
            "0x60780010 refused: 0x06040041 object cannot be mapped to the PDO; the drive is "
            "not started"
        )
        assert ev.data["abort_code"] == 0x06040041
        assert r.hub.state("d5").comm is CommState.OFFLINE
        assert r.sim.node(5).nmt_state is NmtState.PRE_OPERATIONAL  # never started
        with pytest.raises(DriveOffline):
            await r.hub.read_param("d5", 0x6041, 0)
        assert r.adapter.diagnostics()["drives"]["d5"]["problem"] == ev.text


async def test_leaving_the_line_stops_and_pre_operational() -> None:
    """Shutdown (rule 4): the last RPDO carries the stop, then NMT enter pre-operational."""
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.until(lambda: r.sim.node(5).drive.state is State.OPERATION_ENABLED)
        r.hub.apply_shutdown()
        r.task.cancel()
        await asyncio.gather(r.task, return_exceptions=True)
        node = r.sim.node(5)
        await r.until(lambda: node.nmt_state is NmtState.PRE_OPERATIONAL)
        assert node.drive.state is not State.OPERATION_ENABLED
        assert r.hub.state("d5").comm is CommState.OFFLINE


# the rig's consumer time of the gateway's heartbeat: heartbeat x heartbeat_factor (3)
CONSUMER_S = 3 * round(scaled(100)) / 1000.0


async def _run_then_leave(r: Any, *, clean: bool) -> None:
    r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
    await r.until(lambda: r.sim.node(5).drive.state is State.OPERATION_ENABLED)
    r.hub.apply_shutdown()
    if not clean:  # a killed master: nothing more goes out, not even its leave

        async def killed(*_: object) -> None:
            return None

        r.adapter.leave = killed
    r.task.cancel()
    await asyncio.gather(r.task, return_exceptions=True)


async def test_a_clean_leave_switches_the_heartbeat_consumer_off_first() -> None:
    """comm_loss_option = 1: after a clean shutdown the drive is stopped, in
    pre-operational, its consumer of the gateway's heartbeat (0x1016:1) off, and not
    faulted however long the gateway stays away."""
    async with rig([drive(5, comm_loss_option=1)]) as r:
        await r.wait("d5", online)
        node = r.sim.node(5)
        assert node._value(0x1016, 1) >> 16 == 127  # the bring-up armed it
        await _run_then_leave(r, clean=True)
        await r.until(lambda: node.nmt_state is NmtState.PRE_OPERATIONAL)
        assert node._value(0x1016, 1) == 0
        left = node.now
        await r.until(lambda: node.now > left + 3 * CONSUMER_S)
        assert node.drive.state not in (State.FAULT, State.OPERATION_ENABLED)
        assert node.drive.state is State.SWITCH_ON_DISABLED or node.drive.state in (
            State.READY_TO_SWITCH_ON,
            State.SWITCHED_ON,
        )


async def test_a_killed_master_still_trips_the_drive_per_0x6007() -> None:
    async with rig([drive(5, comm_loss_option=1)]) as r:
        await r.wait("d5", online)
        node = r.sim.node(5)
        await _run_then_leave(r, clean=False)
        await r.until(lambda: node.drive.state is State.FAULT)
        assert node._value(0x603F, 0) == 0x8130  # heartbeat error (CiA 301)
        assert node._value(0x1016, 1) >> 16 == 127


async def test_a_pulled_cable_still_trips_the_drive_per_0x6007() -> None:
    async with rig([drive(5, comm_loss_option=1)]) as r:
        await r.wait("d5", online)
        node = r.sim.node(5)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.until(lambda: node.drive.state is State.OPERATION_ENABLED)
        node.silence(True)
        await r.until(lambda: node.drive.state is State.FAULT)
        assert node._value(0x603F, 0) == 0x8130


async def test_a_drive_found_running_is_stopped_before_it_is_configured() -> None:
    """A gateway restart finds the drive running (nothing stopped it: no 0x6007 reaction,
    no gateway heartbeat): the new gateway's bring-up stops it, and it stays stopped."""
    bus = {"heartbeat": 0}
    async with rig([drive(5, comm_loss_option=0)], bus=bus) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d5", lambda s: s.speed_rpm is not None and s.speed_rpm > 890)
        r.task.cancel()  # the gateway dies with the run command in force
        await asyncio.gather(r.task, return_exceptions=True)
        node = r.sim.node(5)
        assert node.drive.state is State.OPERATION_ENABLED and node.drive.motor.speed > 890
        hub, adapter = gateway_side([drive(5, comm_loss_option=0)], r.adapter.options.channel, bus)
        task = asyncio.create_task(adapter.run(hub))
        try:
            await asyncio.wait_for(hub.wait_for("d5", online), scaled(10))
            assert node.drive.state is not State.OPERATION_ENABLED
            await r.until(lambda: node.drive.motor.speed == 0.0)
            assert not hub.desired("d5").run
            state = await asyncio.wait_for(
                hub.wait_for("d5", lambda s: s.status is DriveStatus.READY), scaled(10)
            )
            assert not state.running
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)


async def test_coast_stop_disables_voltage_and_jog_is_refused() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=900.0))
        await r.until(lambda: r.sim.node(5).drive.state is State.OPERATION_ENABLED)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(coast_stop=True))
        await r.until(lambda: r.sim.node(5).drive.state is State.SWITCH_ON_DISABLED)  # 9
        state = await r.wait("d5", lambda s: not s.running)
        assert state.status is DriveStatus.READY
        r.hub.submit("d5", Source.MODBUS, DriveCommand(coast_stop=False))
        with pytest.raises(CommandRejected, match="no jog"):
            r.hub.submit("d5", Source.MODBUS, DriveCommand(jog=True))


async def test_without_sync_rpdos_go_every_pdo_period_and_tpdo1_on_its_timer() -> None:
    async with rig([drive(5)], bus={"sync_period": 0}) as r:
        await r.wait("d5", online)
        assert r.adapter.diagnostics()["syncs_tx"] == 0
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=-450.0))
        state = await r.wait("d5", lambda s: s.speed_rpm == -450.0)
        assert state.direction is Direction.REVERSE and state.at_reference


async def test_not_the_nmt_master_configures_a_node_another_master_started() -> None:
    async with rig([drive(5, sim_boot_operational=True)], bus={"nmt_master": False}) as r:
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=300.0))
        await r.wait("d5", lambda s: s.speed_rpm == 300.0)


async def test_reset_if_operational_resets_a_self_started_node() -> None:
    async with rig([drive(5, sim_boot_operational=True, reset_if_operational=True)]) as r:
        ev = await r.event(lambda e: "NMT reset node sent" in e.text)
        assert ev.text == "node sends no heartbeat: NMT reset node sent"
        await r.wait("d5", online)


async def _frames_after(channel: str, wanted: int, count: int) -> list[int]:
    """The COB-IDs heard on the line by a listener of its own until ``count`` frames of
    COB-ID ``wanted`` came."""
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    reader = can.AsyncBufferedReader()
    notifier = can.Notifier(bus, [reader], loop=asyncio.get_running_loop())
    heard: list[int] = []
    try:
        while heard.count(wanted) < count:
            msg = await asyncio.wait_for(reader.get_message(), scaled(5))
            heard.append(msg.arbitration_id)
    finally:
        notifier.stop()
        bus.shutdown()
    return heard


async def test_the_pdos_the_gateway_does_not_use_are_switched_off() -> None:
    """The shipped EDS enables TPDO2 synchronous: after the bring-up the line carries
    SYNC, RPDO1 and TPDO1 only (CiA 301 §7.5.2.36: 0x1801:1 bit 31, PDO not valid)."""
    async with rig([drive(5)]) as r:
        await r.wait("d5", online)
        # read from the drive by SDO: bit 31 set, the id as the EDS gives it
        assert await r.hub.read_param("d5", 0x1801, 1) == 0x80000285
        assert await r.hub.read_param("d5", 0x1401, 1) == 0x80000305
        heard = await _frames_after(r.adapter.options.channel, 0x185, 10)
        assert 0x285 not in heard and 0x185 in heard and 0x80 in heard
        assert not any(
            "switched off" in e.text for e in r.seen if hasattr(e, "text")
        )  # nothing refused


@pytest.fixture
def fixed_pdo_eds(tmp_path: Path) -> Path:
    """The drive's own dictionary: TPDO2's COB-ID is read-only (a fixed PDO)."""
    text = Path(EDS).read_text()
    section = text.index("[1801sub1]")
    end = text.index("[", section + 1)
    path = tmp_path / "fixed.eds"
    path.write_text(
        text[:section] + text[section:end].replace("AccessType=rw", "AccessType=ro") + text[end:]
    )
    return path


async def test_a_pdo_the_drive_will_not_switch_off_is_reported_and_it_runs(
    fixed_pdo_eds: Path,
) -> None:
    sims = [SimNodeConfig(node_id=5, eds=fixed_pdo_eds, ramp_time=0.2)]
    async with rig([drive(5)], sims=sims) as r:
        ev = await r.event(lambda e: e.text.startswith("TPDO2 switched off"))
        assert ev.text == (
            "TPDO2 switched off (not used): 0x1801:1 bit 31: write of 0x1801:1 = 0x80000285 "
            "refused: 0x06010002 attempt to write a read only object (the bring-up goes on)"
        )
        await r.wait("d5", online)
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.wait("d5", lambda s: s.running)
