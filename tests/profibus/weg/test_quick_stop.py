"""Quick stop and coast stop on the WEG drives (issue 17 item 4).

Golden control words per profile: a quick stop or coast stop goes with the run and JOG bits
cleared, so a drive that does not execute the stop bit still ramps down and the release of
either stop never restarts the motor. P0202 (type of control) is read at connect on the
CFW-11 and CFW700: in V/f or VVW the quick stop is sent as a ramp stop, said once in the
events and shown in ``DriveState.values``; the simulated CFW700 ignores bit 6 there (its
manual: "not allowed with control types (P0202) V/f or VVW").
"""

from __future__ import annotations

import struct
from typing import Any

import pytest

from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.spec import CFW11, CFW320, CFW700, DataProfile
from gateway.model import DesiredCommand, Device
from tests.profibus.weg.helpers import Loop, profile

SYNC = WegOptions(sync_rpm=1800.0, max_rpm=1800.0)
PD = WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1800.0)
RUN = 0x0001  # P0684 bit 0
JOG = 0x0008  # P0684 bit 3
QUICK = 0x0040  # P0684 bit 6
STW1_ON = 0x0001
STW1_NO_OFF2 = 0x0002
STW1_NO_OFF3 = 0x0004
STW1_JOG = 0x0100
ZSW1_OPERATION = 0x0237  # bits 0, 1, 2, 4, 5, 9: operation, no OFF2/OFF3, remote
V_F_60HZ, VVW, SENSORLESS = 0, 5, 3


def control(p: WegProfile, now: float = 0.0, **desired: Any) -> int:
    data = p.outputs(DesiredCommand(**desired), now)
    word: int = struct.unpack(">H", data[:2])[0]
    return word


# ----------------------------------------------------------------- manufacturer profile


@pytest.mark.parametrize(
    ("device", "quick"),
    [(Device.CFW11, 0x0056), (Device.CFW700, 0x0056), (Device.CFW320, 0x0016)],
)
def test_manufacturer_quick_stop_clears_run(device: Device, quick: int) -> None:
    # Table 3.3 / 4.3: bit 6 quick stop (reserved on the CFW320) with bit 0 = 0, bit 1
    # general enable, bit 2 forward, bit 4 remote; today's code sent 0x0057 (run still 1)
    p = profile(device, SYNC)
    assert control(p, run=True, speed_rpm=900.0, quick_stop=True) == quick
    assert control(p, jog=True, quick_stop=True) == quick  # JOG cleared as well
    assert control(p, run=True, jog=True, quick_stop=True, coast_stop=True) & (RUN | JOG) == 0


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
def test_manufacturer_coast_stop_clears_run(device: Device) -> None:
    # bit 1 = 0 (general disable: the motor coasts) with bit 0 = 0: 0x0014, not 0x0015
    p = profile(device, SYNC)
    assert control(p, run=True, speed_rpm=900.0, coast_stop=True) == 0x0014
    assert control(p, jog=True, coast_stop=True) == 0x0014


# ----------------------------------------------------------------- PROFIdrive profile


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700])
def test_profidrive_quick_and_coast_stop_clear_on_and_jog(device: Device) -> None:
    # STW1 (Table 3.8 / 4.7) from operation: OFF3 (bit 2 = 0) and OFF2 (bit 1 = 0) go
    # with ON (bit 0) and JOG (bit 8) at 0; enable operation/ramp/setpoint and bit 10 kept
    p = profile(device, PD)
    p.inputs(struct.pack(">2H", ZSW1_OPERATION, 0), 0.0)
    assert control(p, run=True) == 0x045F
    assert control(p, run=True, quick_stop=True) == 0x045A
    assert control(p, run=True, coast_stop=True) == 0x045C
    assert control(p, jog=True, quick_stop=True) & (STW1_ON | STW1_JOG) == 0
    assert control(p, jog=True, coast_stop=True) & (STW1_ON | STW1_JOG) == 0


# ----------------------------------------------------------------- P0202


def test_control_type_table() -> None:
    # V/f (0, 1, 2) and VVW (5) fall back; the vector types keep the quick stop
    assert [c for c in range(8) if CFW11.quick_stop_as_ramp(c)] == [0, 1, 2, 5]
    assert [c for c in range(8) if CFW700.quick_stop_as_ramp(c)] == [0, 1, 2, 5, 6, 7]
    assert CFW700.control_type_text(VVW) == "P0202 = 5 (VVW)"
    assert CFW11.quick_stop_as_ramp(99)  # unknown: the ramp stop every type allows
    assert not CFW320.reads_control_type


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700])
@pytest.mark.parametrize("control_type", [V_F_60HZ, 1, 2, VVW])
async def test_v_f_or_vvw_quick_stop_is_a_ramp_stop(device: Device, control_type: int) -> None:
    loop = Loop(device, SYNC, params={202: control_type})
    changes = await loop.connect()
    assert changes["values"] == {"P0202": control_type, "quick_stop_as_ramp": 1}
    [(text, kind, data)] = loop.events.got
    assert kind == "safety"
    assert text.startswith(f"quick stop falls back to ramp stop: P0202 = {control_type} (V")
    assert data == {"control_type": control_type, "quick_stop_as_ramp": True}
    # run 0, no bit 6: P0684 = 0x0016, the manual's ramp stop
    assert control(loop.profile, run=True, quick_stop=True) == 0x0016
    assert control(loop.profile, run=True, coast_stop=True) == 0x0014
    state = loop.step()
    assert state["values"]["quick_stop_as_ramp"] == 1
    assert state["values"]["P0202"] == control_type


async def test_vector_control_keeps_the_quick_stop_and_says_nothing() -> None:
    loop = Loop(Device.CFW700, SYNC)  # the simulator's P0202 default: sensorless vector
    changes = await loop.connect()
    assert changes["values"] == {"P0202": SENSORLESS, "quick_stop_as_ramp": 0}
    assert loop.events.got == []
    assert control(loop.profile, run=True, quick_stop=True) == 0x0056


async def test_profidrive_v_f_quick_stop_is_off1() -> None:
    # P0967 bit 2 note: not recommended in V/f or VVW; OFF1 (ON = 0, bit 2 = 1) instead
    loop = Loop(Device.CFW11, PD, params={202: VVW})
    await loop.connect()
    loop.profile.inputs(struct.pack(">2H", ZSW1_OPERATION, 0), 0.0)
    word = control(loop.profile, run=True, quick_stop=True)
    assert word == 0x045E
    assert word & STW1_NO_OFF3 and word & STW1_NO_OFF2 and not word & STW1_ON


async def test_a_write_of_p0202_is_followed_and_said_once() -> None:
    loop = Loop(Device.CFW11, SYNC)
    await loop.connect()
    await loop.profile.write_param(loop.channel, 202, 0, V_F_60HZ)
    await loop.profile.write_param(loop.channel, 202, 0, 1)  # still V/f: no second event
    assert [t for t, _, _ in loop.events.got] == [
        "quick stop falls back to ramp stop: P0202 = 0 (V/f 60 Hz)",
    ]
    assert control(loop.profile, run=True, quick_stop=True) == 0x0016
    await loop.profile.write_param(loop.channel, 202, 0, SENSORLESS)
    assert loop.events.got[-1][0].startswith("quick stop is the drive's quick stop again")
    assert control(loop.profile, run=True, quick_stop=True) == 0x0056


async def test_reconnect_does_not_repeat_the_event() -> None:
    loop = Loop(Device.CFW700, SYNC, params={202: V_F_60HZ})
    await loop.connect()
    loop.profile.on_comm_lost()
    await loop.connect()
    assert len(loop.events.got) == 1


# ----------------------------------------------------------------- against the simulators


def run_to(loop: Loop, rpm: float) -> None:
    loop.command(run=True, speed_rpm=rpm)
    loop.until(lambda s: s.get("at_reference") is True, 10.0)


async def test_simulated_cfw700_in_v_f_ignores_bit_6() -> None:
    # CFW700 P0684 bit 6: "not allowed with control types (P0202) V/f or VVW"
    loop = Loop(Device.CFW700, SYNC, params={202: V_F_60HZ})
    await loop.connect()
    run_to(loop, 900.0)
    for i in range(10):  # today's telegram: run and quick stop (0x0057)
        loop.sim.exchange(struct.pack(">2H", 0x0057, 4096), loop.now + 0.05 * (i + 1))
    assert loop.sim.motor.speed == pytest.approx(900.0)  # still turning at the reference
    assert not loop.sim.motor.quick_stopping


async def test_simulated_cfw11_in_v_f_still_executes_bit_6() -> None:
    # CFW-11 P0684 bit 6: only "não se recomenda" (not recommended) in V/f or VVW
    loop = Loop(Device.CFW11, SYNC, params={202: V_F_60HZ})
    await loop.connect()
    run_to(loop, 900.0)
    loop.sim.exchange(struct.pack(">2H", 0x0057, 4096), loop.now + 0.05)
    assert loop.sim.motor.quick_stopping


@pytest.mark.parametrize("control_type", [V_F_60HZ, SENSORLESS])
async def test_cfw700_quick_stop_stops_and_its_release_does_not_restart(
    control_type: int,
) -> None:
    loop = Loop(Device.CFW700, SYNC, params={202: control_type, 101: 20})
    await loop.connect()
    run_to(loop, 900.0)
    loop.command(quick_stop=True)  # the hub's own clearing of run aside: run still asked
    loop.until(lambda s: s.get("running") is False, 10.0)
    assert loop.sim.motor.speed == 0.0
    loop.command(quick_stop=False, run=False)  # released: the hub clears run with the stop
    loop.step(20)
    assert loop.sim.motor.speed == 0.0 and loop.state["running"] is False


async def test_cfw700_vector_quick_stop_is_faster_than_the_ramp() -> None:
    # P0101 = 2.0 s from 1800 rpm: 900 rpm needs 1 s on the ramp; the quick stop less
    times = {}
    for quick in (False, True):
        loop = Loop(Device.CFW700, SYNC, params={101: 20})
        await loop.connect()
        run_to(loop, 900.0)
        start = loop.now
        loop.command(run=False, quick_stop=quick)
        loop.until(lambda s: s.get("running") is False, 10.0)
        times[quick] = loop.now - start
    assert times[True] < times[False]


async def test_cfw700_v_f_quick_stop_takes_the_ramp() -> None:
    loop = Loop(Device.CFW700, SYNC, params={202: V_F_60HZ, 101: 20})
    await loop.connect()
    run_to(loop, 900.0)
    loop.command(quick_stop=True)  # run still asked: the profile sends run 0, no bit 6
    loop.step(2)
    assert loop.sim.net.run is False and loop.sim.net.quick_stop is False
    assert not loop.sim.motor.quick_stopping
    assert 0.0 < loop.sim.motor.speed < 900.0  # on the deceleration ramp


# ----------------------------------------------------------------- release of a stop


@pytest.mark.parametrize("stop", ["quick_stop", "coast_stop"])
@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
def test_release_with_run_still_desired_does_not_restart(device: Device, stop: str) -> None:
    # rule 1: run only on a run command given after the release; here the desired command
    # still says run (a hub that kept it): the profile keeps bit 0 at 0 until run is seen off
    p = profile(device, SYNC)
    assert control(p, run=True) == 0x0017
    assert control(p, run=True, **{stop: True}) & RUN == 0
    assert control(p, run=True) == 0x0016  # released, run held: ramp-stop word
    assert control(p, jog=True) == 0x0016  # nor JOG
    assert control(p, run=False) == 0x0016
    assert control(p, run=True) == 0x0017  # a new run command after the release
    assert control(p, jog=True) == 0x001E


@pytest.mark.parametrize("stop", ["quick_stop", "coast_stop"])
def test_profidrive_release_with_run_still_desired_does_not_switch_on(stop: str) -> None:
    p = profile(Device.CFW700, PD)
    p.inputs(struct.pack(">2H", ZSW1_OPERATION, 0), 0.0)
    assert control(p, run=True, **{stop: True}) & STW1_ON == 0
    assert control(p, run=True) == 0x045E  # ON = 0 (OFF1) while run was not seen off
    assert control(p, run=False) == 0x045E
    assert control(p, run=True) == 0x045F


@pytest.mark.parametrize("stop", ["quick_stop", "coast_stop"])
def test_a_run_given_with_the_release_runs(stop: str) -> None:
    # the hub clears run with the stop (and refuses run while it is latched): a run given
    # after, even in the command that releases the stop, is a new run command
    p = profile(Device.CFW700, SYNC)
    assert control(p, run=True) == 0x0017
    assert control(p, **{stop: True}) & RUN == 0
    assert control(p, run=True) == 0x0017
