"""Issue 32 on the WEG drives, profile and simulator (bus-free loop, fake clock).

Item 2: until P0741 is verified the telegram is a stop in both data profiles; P0741 is
checked at every connect; a written P0741 asks for a new Set_Prm; the simulated drive takes
P0741 only without cyclic data. Item 4: the CFW320's quick stop is a ramp stop, never a
refusal. Item 5: P0313 read at connect (failsafe), check-config's warning. Item 6: local
control from the status word. Item 8: a jogging drive is running.
"""

from __future__ import annotations

import struct

import pytest

from adapters.profibus.adapter import ProfibusAdapter, unconfigured_outputs
from adapters.profibus.weg import words as w
from adapters.profibus.weg.cfw320 import Cfw320Profile
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.programming import DataProfilePending, DriveProgrammingMismatch
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.drive import Cfw700Sim
from adapters.profibus.weg.spec import CFW11, CFW320, DataProfile, failsafe_warning
from gateway.config import parse
from gateway.errors import CommandRejected
from gateway.hub import Hub
from gateway.model import (
    CommState,
    DesiredCommand,
    Device,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    StopAction,
)
from tests.profibus.weg.helpers import Loop, drive, profile

PD = WegOptions(data_profile=DataProfile.PROFIDRIVE)
SYNC = WegOptions(sync_rpm=1800.0)
VF = {202: 0}  # P0202 = V/f 60 Hz: the CFW700 ignores P0684 bit 6 (Table 4.3 note)


def control_word(data: bytes) -> int:
    word: int = struct.unpack(">H", data[:2])[0]
    return word


# ----------------------------------------------------------------- item 2


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
@pytest.mark.parametrize("options", [WegOptions(), PD], ids=["manufacturer", "profidrive"])
def test_unconfigured_telegram_is_a_stop_in_both_profiles(
    device: Device, options: WegOptions
) -> None:
    if device is Device.CFW320 and options.data_profile is DataProfile.PROFIDRIVE:
        pytest.skip("the CFW320 speaks only the manufacturer profile")
    p = profile(device, options)
    running = DesiredCommand(run=True, jog=True, speed_rpm=900.0)
    safe = running.stopped(StopAction.RAMP_STOP, Source.GATEWAY)
    data = unconfigured_outputs(p, safe, 0.0)
    assert data == bytes.fromhex("04 16 00 00")  # golden: spec.NEUTRAL_STOP_WORD, no speed
    weg = w.ManufacturerControl.decode(control_word(data), w.MANUFACTURER_CONTROL_BITS)
    assert (weg.run, weg.jog, weg.quick_stop, weg.remote) == (False, False, False, True)
    stw1 = w.ProfidriveControl.decode(control_word(data), w.STW1_BITS)
    assert (stw1.on, stw1.jog, stw1.control_by_plc) == (False, False, True)


@pytest.mark.parametrize("verify_mapping", [True, False])
async def test_p0741_is_checked_at_every_connect(verify_mapping: bool) -> None:
    """Probes 2 and 5: a drive at factory P0741 = 1 is never brought online as PROFIdrive."""
    options = WegOptions(data_profile=DataProfile.PROFIDRIVE, verify_mapping=verify_mapping)
    loop = Loop(Device.CFW700, options, params=VF)
    loop.sim.values[741] = 1
    loop.sim.set_prm(b"")  # the drive speaks the manufacturer profile
    with pytest.raises(DriveProgrammingMismatch, match="P0741 = 1"):
        await loop.connect()


async def test_unconfigured_telegram_does_not_jog_a_vf_cfw700() -> None:
    """Probe 1: the stop the adapter sends before P0741 is verified keeps the motor still."""
    loop = Loop(Device.CFW700, PD, params=VF)
    loop.sim.values[741] = 1
    loop.sim.set_prm(b"")
    safe = DesiredCommand().stopped(StopAction.RAMP_STOP, Source.GATEWAY)
    for _ in range(60):  # 3 s
        loop.now += loop.dt
        loop.sim.exchange(unconfigured_outputs(loop.profile, safe, loop.now), loop.now)
        assert loop.sim.motor.speed == 0.0 and not loop.sim.net.jog


async def test_written_p0741_asks_for_new_parameters() -> None:
    """Probe 6: P0741 written by startup_params is in force only after cyclic data stops."""
    options = WegOptions(data_profile=DataProfile.PROFIDRIVE, startup_params=((741, 0),))
    loop = Loop(Device.CFW700, options, params=VF)
    loop.sim.values[741] = 1
    loop.sim.set_prm(b"")
    loop.sim.exchange(bytes(4), 0.0)  # online, manufacturer profile
    with pytest.raises(DataProfilePending) as err:
        await loop.connect()
    assert err.value.reparameterise is True
    assert "P0741 written" in str(err.value)
    assert loop.sim.values[741] == 0
    assert loop.sim.data_profile.value == "manufacturer"  # not while exchanging
    loop.profile.on_comm_lost()  # the adapter's restart: out of data exchange, Set_Prm
    loop.sim.set_prm(b"")
    assert loop.sim.data_profile is DataProfile.PROFIDRIVE
    await loop.connect()  # nothing written now: configured
    loop.command(run=True, speed_rpm=600.0)
    assert loop.until(lambda s: bool(s.get("at_reference")), 5.0)["speed_rpm"] == pytest.approx(
        600, abs=30
    )


async def test_p0741_changed_during_cyclic_data_is_not_trusted() -> None:
    """Changed at the HMI between two connect attempts: not in force, parameterise again."""
    loop = Loop(Device.CFW700, PD, params=VF)
    loop.sim.values[741] = 1
    loop.sim.set_prm(b"")
    loop.sim.exchange(bytes(4), 0.0)
    with pytest.raises(DriveProgrammingMismatch):
        await loop.connect()
    loop.sim.values[741] = 0  # at the HMI: the drive still speaks the manufacturer words
    with pytest.raises(DataProfilePending, match="P0741 changed from 1 to 0"):
        await loop.connect()
    assert loop.sim.data_profile is DataProfile.MANUFACTURER


def test_sim_takes_p0741_when_cyclic_data_stops() -> None:
    sim = Cfw700Sim(params={**sp.NETWORK_SOURCES})
    sim.exchange(bytes(4), 0.0)
    assert sim.write_param(741, 0) is None
    sim.exchange(bytes(4), 0.05)
    assert sim.data_profile.value == "manufacturer"  # [700] l.922-924
    sim.comm_lost(1.0)  # the watchdog expired: no cyclic data
    assert sim.data_profile is DataProfile.PROFIDRIVE


# ----------------------------------------------------------------- item 4


def test_cfw320_quick_stop_with_run_off_is_a_stop_not_a_refusal() -> None:
    """Probe 3 through the real hub and the CFW320's real capabilities."""
    hub = Hub(clock=lambda: 0.0, wallclock=lambda: 0.0)
    hub.add_drive(DriveState(id="d1", device=Device.CFW320, bus="pb", address=5))
    hub.set_capabilities("d1", Cfw320Profile(drive(Device.CFW320, SYNC)).capabilities())
    hub.update("d1", comm=CommState.ONLINE, status=DriveStatus.READY)
    hub.submit("d1", Source.ZENOH, DriveCommand(run=True, speed_rpm=600.0), "scada")
    assert hub.desired("d1").run
    try:
        hub.submit("d1", Source.ZENOH, DriveCommand(run=False, quick_stop=True), "scada")
    except CommandRejected as exc:
        pytest.fail(f"the stop was refused: {exc}")
    assert not hub.desired("d1").run and not hub.desired("d1").jog


# ----------------------------------------------------------------- item 5


@pytest.mark.parametrize(
    ("device", "params", "failsafe", "text"),
    [
        (Device.CFW11, {}, False, "P0313 = 0: inactive, the drive keeps running"),
        (Device.CFW700, {313: 4}, False, "P0313 = 4: go to local keeping commands"),
        (Device.CFW700, {313: 1}, True, "P0313 = 1: ramp stop when the master is lost"),
        (Device.CFW320, {}, True, "P313 = 1: ramp stop"),
        (Device.CFW320, {313: 5}, True, "P313 = 5: cause a fault"),
        (Device.CFW11, {313: 5, 206: 3}, False, "P0313 = 5: cause a fault, but P0206 = 3 s"),
    ],
)
async def test_p0313_read_at_connect(
    device: Device, params: dict[int, int], failsafe: bool, text: str
) -> None:
    """P0313, and P0206 (auto-reset: a fault reset by itself while the master is away)."""
    loop = Loop(device, params=params)
    changes = await loop.connect()
    assert changes["failsafe"] is failsafe
    assert str(changes["failsafe_text"]).startswith(text)


def test_check_config_warns_of_watchdog_off_and_p0313() -> None:
    assert failsafe_warning(CFW320, None, 0.5) is None  # factory P313 = 1
    assert "P0313 = 0" in str(failsafe_warning(CFW11, None, 0.5))
    assert failsafe_warning(CFW11, 1, 0.5) is None
    assert "watchdog = 0" in str(failsafe_warning(CFW320, 1, 0.0))
    drives = [
        {"id": "a", "device": "CFW-11", "address": 3},
        {"id": "b", "device": "CFW-11", "address": 4, "startup_params": {"P0313": 1}},
        {"id": "c", "device": "CFW320", "address": 5, "watchdog": 0},
        {"id": "d", "device": "CFW320", "address": 6},
    ]
    table = {"adapter": "profibus", "simulate": True, "drives": drives}
    config = parse({"buses": {"pb": table}}, "site.toml")
    bus = config.buses[0]
    said = {d.id: ProfibusAdapter.safety_warnings(bus, d) for d in bus.drives}
    assert said["b"] == [] and said["d"] == []
    assert said["a"][0].startswith("drive a: P0313 = 0: inactive")
    assert said["c"][0].startswith("drive c: watchdog = 0")


# ----------------------------------------------------------------- items 6 and 8


@pytest.mark.parametrize("options", [WegOptions(), PD], ids=["manufacturer", "profidrive"])
async def test_local_control_from_the_status_word(options: WegOptions) -> None:
    loop = Loop(Device.CFW11, options)
    await loop.connect()
    assert loop.step(2)["local_control"] is False
    loop.sim.values[220] = sp.SRC_LOCREM_ALWAYS_LOCAL  # the HMI's LOC/REM: local
    assert loop.step(2)["local_control"] is True


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
async def test_a_jogging_drive_is_running(device: Device) -> None:
    """Probe 4: P0680 bit 11 JOG; the CFW320 was `stopping`, the others `starting`."""
    loop = Loop(device)
    await loop.connect()
    loop.command(jog=True)
    state = loop.until(lambda s: s.get("speed_rpm") == pytest.approx(sp.JOG_RPM, abs=1), 5.0)
    state = loop.step(4)
    assert state["status"] is DriveStatus.RUNNING
    assert state["running"] and state["at_reference"]
    loop.command(jog=False)
    assert loop.step()["status"] is DriveStatus.STOPPING


async def test_a_jogging_profidrive_drive_is_running() -> None:
    loop = Loop(Device.CFW700, PD)
    await loop.connect()
    loop.command(jog=True)
    loop.until(lambda s: s.get("speed_rpm") == pytest.approx(sp.JOG_RPM, abs=1), 5.0)
    assert loop.step(4)["status"] is DriveStatus.RUNNING
