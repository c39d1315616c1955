"""Closed loop without a bus: profile.outputs() -> sim.exchange() -> profile.inputs()."""

from __future__ import annotations

import pytest

from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.sim.dataprofile import PdState
from adapters.profibus.weg.spec import DataProfile
from gateway.model import Device, Direction, DriveStatus
from tests.profibus.weg.helpers import Loop

FAULTS = {
    Device.CFW11: (71, "motor overload"),  # CFW-11 Table 3.7 (F0071)
    Device.CFW700: (71, "F071"),  # not in the CFW700 manual: its code, not a text
    Device.CFW320: (32, "Comm. plug-in module communication lost"),  # CFW320 section 7
}


def sim_state(loop: Loop) -> PdState:
    return loop.sim.pd_state


def reset_pulses(outputs: list[int], bit: int = 0x80) -> int:
    """How many separate pulses of ``bit`` a series of control words holds."""
    pulses, level = 0, False
    for word in outputs:
        high = bool(word & bit)
        pulses += high and not level
        level = high
    return pulses


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
async def test_run_reverse_stop_fault_reset(device: Device) -> None:
    loop = Loop(device, WegOptions(words=4, words_in=(3, 49)))
    assert (await loop.connect())["speed_base"].startswith("8192 = ")
    assert loop.step()["status"] is DriveStatus.READY

    # run 900 rpm: ramp, then at reference
    loop.command(run=True, speed_rpm=900.0)
    assert loop.step(2)["status"] is DriveStatus.STARTING
    s = loop.until(lambda s: s["at_reference"], 3.0)
    assert (s["status"], s["speed_rpm"], s["running"]) == (DriveStatus.RUNNING, 900.0, True)
    assert s["direction"] is Direction.FORWARD
    assert s["current_a"] > 0

    # reverse through zero
    loop.command(direction=Direction.REVERSE)
    seen: list[float] = []

    def reversed_at_reference(s: dict[str, object]) -> bool:
        seen.append(float(s["speed_rpm"]))  # type: ignore[arg-type]
        return bool(s["at_reference"])

    s = loop.until(reversed_at_reference, 5.0)
    assert min(seen) == -900.0 and max(seen) == 900.0
    assert any(-100 < v < 100 for v in seen)  # it passed through zero
    assert s["direction"] is Direction.REVERSE

    # stop
    loop.command(run=False)
    assert loop.step()["status"] is DriveStatus.STOPPING
    s = loop.until(lambda s: s["status"] is DriveStatus.READY, 3.0)
    assert (s["speed_rpm"], s["running"]) == (0.0, False)

    # run again, then a fault: faulted with its code and text
    loop.command(run=True, direction=Direction.FORWARD)
    loop.until(lambda s: s["at_reference"], 3.0)
    code, text = FAULTS[device]
    loop.sim.inject_fault(code, loop.now)
    s = loop.step()
    assert (s["status"], s["fault_code"], s["fault_text"]) == (DriveStatus.FAULTED, code, text)
    loop.command(run=False)  # the hub clears run on a fault (safety rule 1)
    loop.step(60)
    assert loop.state["status"] is DriveStatus.FAULTED  # until reset

    # reset: one edge, never repeated; ready and not running afterwards
    loop.reset()
    sent = []
    for _ in range(40):
        loop.step()
        sent.append(int.from_bytes(loop.last_out[:2], "big"))
    assert reset_pulses(sent) == 1
    s = loop.state
    assert (s["status"], s["running"], s["fault_code"], s["speed_rpm"]) == (
        DriveStatus.READY,
        False,
        None,
        0.0,
    )


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700])
async def test_profidrive_switching_on_walk(device: Device) -> None:
    loop = Loop(device, WegOptions(data_profile=DataProfile.PROFIDRIVE))
    assert (await loop.connect())["speed_base"] == "4000h = P0134 1800 rpm"
    assert loop.sim.pd_state is PdState.S1  # switching on inhibited after power-up
    s = loop.step()
    assert loop.last_out[:2] == b"\x04\x5e"  # ON = 0 leaves S1
    assert sim_state(loop) is PdState.S2
    assert s["status"] is DriveStatus.READY

    loop.command(run=True, speed_rpm=900.0)
    s = loop.step()
    assert loop.last_out == b"\x04\x5f\x20\x00"  # ON; 900 rpm = 2000h of 4000h = P0134
    assert sim_state(loop) is PdState.S4
    assert s["status"] is DriveStatus.STARTING
    s = loop.until(lambda s: s["status"] is DriveStatus.RUNNING, 3.0)
    assert (s["speed_rpm"], s["at_reference"]) == (900.0, True)

    loop.command(direction=Direction.REVERSE)  # a negative reference (P0967 note)
    s = loop.until(lambda s: s["status"] is DriveStatus.RUNNING, 5.0)
    assert (s["speed_rpm"], s["direction"]) == (-900.0, Direction.REVERSE)

    loop.command(run=False)  # OFF1: ramp down, then ready to switch on
    assert loop.step()["status"] is DriveStatus.STOPPING
    loop.until(lambda s: s["status"] is DriveStatus.READY, 3.0)
    loop.step()
    assert sim_state(loop) is PdState.S2

    loop.command(run=True, coast_stop=True)  # OFF2: switching on inhibited
    assert loop.step()["status"] is DriveStatus.NOT_READY
    loop.command(coast_stop=False)
    loop.step()  # ON = 0 first, S1 -> S2
    assert loop.step(5)["status"] is DriveStatus.READY  # released: no restart (rule 1)
    loop.command(run=False)
    loop.step()
    loop.command(run=True)  # a new run command after the release
    assert loop.until(lambda s: s["status"] is DriveStatus.RUNNING, 3.0)["speed_rpm"] == -900

    loop.command(quick_stop=True)  # OFF3: quick stop, then switching on inhibited
    s = loop.until(lambda s: s["status"] is not DriveStatus.RUNNING, 1.0)
    assert s["status"] is DriveStatus.STOPPING
    loop.until(lambda s: s["status"] is DriveStatus.NOT_READY, 2.0)
    loop.command(quick_stop=False, run=False)
    assert loop.step()["status"] is DriveStatus.READY

    loop.sim.inject_fault(80, loop.now)
    assert loop.step()["status"] is DriveStatus.FAULTED
    loop.reset()
    sent = []
    for _ in range(10):
        loop.step()
        sent.append(int.from_bytes(loop.last_out[:2], "big"))
    assert reset_pulses(sent) == 1  # fault acknowledge, bit 7
    assert loop.state["status"] is DriveStatus.READY


async def test_frame_20_closed_loop() -> None:
    options = WegOptions(data_profile=DataProfile.PROFIDRIVE, frame=20, words=6)
    options = WegOptions(**{**options.__dict__, "words_in": (760, 761, 762, 763)})
    loop = Loop(Device.CFW11, options)
    await loop.connect()
    assert loop.profile.ratings.rated_current_a == 10.0  # P0401 read at connect
    assert loop.profile.ratings.rated_power_kw == 5.5  # P0404
    loop.command(run=True, speed_rpm=1800.0)
    s = loop.until(lambda s: s["status"] is DriveStatus.RUNNING, 4.0)
    assert s["current_a"] == pytest.approx(loop.sim.motor.current(), abs=0.01)
    assert 0 < s["current_pct_flc"] <= 100
    assert s["power_kw"] > 0
    assert s["values"]["torque_pct"] > 0
    loop.sim.inject_fault(22, loop.now)
    s = loop.step()
    assert (s["fault_code"], s["fault_text"]) == (22, "DC link overvoltage")  # NAMUR bit 2


async def test_cfw320_status_bits_and_hz_scale() -> None:
    loop = Loop(Device.CFW320, WegOptions(words=3, words_in=(3,)))
    assert (await loop.connect())["speed_base"] == "8192 = P403 60 Hz = 1800 rpm"
    loop.command(run=True, speed_pct=50.0)  # 50 % of P403 = 30 Hz = 4096 (P685 example)
    loop.step()
    assert loop.last_out[2:4] == (4096).to_bytes(2, "big")
    assert loop.last_in[1] & 0x02  # P680 bit 1: run command
    s = loop.until(lambda s: s["at_reference"], 3.0)
    assert (s["speed_pct"], s["speed_rpm"]) == (50.0, 900.0)


@pytest.mark.parametrize(
    ("action", "speed_after", "alarm", "fault"),
    [
        (0, 900.0, 139, None),  # inactive: keeps running, A139
        (1, 0.0, 139, None),  # ramp stop
        (2, None, 139, None),  # general disable: coasts (still turning after 2 s)
        (3, 0.0, 139, None),  # go to local: the HMI has no run command
        (4, 900.0, 139, None),  # local keeping commands and reference
        (5, None, None, 239),  # fault F239
    ],
)
@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW320])
async def test_comm_lost_per_p0313(
    device: Device, action: int, speed_after: float | None, alarm: int | None, fault: int | None
) -> None:
    loop = Loop(device, WegOptions(words=5, words_in=(48, 49, 2)), params={313: action})
    await loop.connect()
    loop.command(run=True, speed_rpm=900.0)
    loop.until(lambda s: s["at_reference"], 3.0)

    loop.sim.comm_lost(loop.now)  # watchdog expired: no more telegrams
    loop.profile.on_comm_lost()
    loop.sim.tick(loop.now + 2.5)
    loop.now += 2.5
    if speed_after is not None:
        assert loop.sim.motor.speed == speed_after
    elif fault is None:
        assert 0 < loop.sim.motor.speed < 900 and not loop.sim.motor.enabled  # coasting
    assert loop.sim.param(48) == (alarm or 0)
    assert loop.sim.param(49) == (fault or 0)
    assert loop.sim.param(740) == 2  # offline

    # back online: the hub has cleared run; the alarm goes by itself, a fault stays
    loop.command(run=False)
    s = loop.step()
    assert loop.sim.param(740) == 6
    assert s["alarm_code"] is None
    if fault:
        assert (s["status"], s["fault_code"]) == (DriveStatus.FAULTED, fault)
        loop.reset()
        loop.step(4)
        assert loop.state["status"] is not DriveStatus.FAULTED
    else:
        assert s["status"] is not DriveStatus.FAULTED


@pytest.mark.parametrize(
    ("action", "after"),  # after 5 s: speed, P0680 bit 9 (general enable), alarm, fault
    [
        (0, (900.0, True, 138, 0)),  # inactive: the last command stays in force
        (1, (0.0, True, 138, 0)),  # ramp stop
        (2, (0.0, False, 138, 0)),  # general disable: coasted to a stop (225 rpm/s)
        (3, (0.0, True, 138, 0)),  # go to local: the HMI has no run command
        (4, (900.0, True, 138, 0)),  # local keeping the network's run and reference
        (5, (0.0, False, 0, 238)),  # fault F238: coasted to a stop
    ],
)
@pytest.mark.parametrize("device", [Device.CFW700, Device.CFW320])
async def test_clear_mode_per_p0313(
    device: Device, action: int, after: tuple[float, bool, int, int]
) -> None:
    """P0313 after Global_Control Clear: A138 with the action, or F238 (Table 4.1)."""
    speed_after, enabled, alarm, fault = after
    loop = Loop(device, WegOptions(words=4, words_in=(48, 49)), params={313: action})
    await loop.connect()
    loop.command(run=True, speed_rpm=900.0)
    loop.until(lambda s: s["at_reference"], 3.0)
    loop.sim.clear_mode(loop.now)  # Global_Control Clear
    assert loop.sim.param(740) == 5
    s = loop.step(100)  # 5 s; the outputs are ignored in clear mode
    assert (s["alarm_code"] or 0, s["fault_code"] or 0) == (alarm, fault)
    assert loop.sim.motor.speed == speed_after
    assert bool(loop.sim.status_word() & 0x0200) is enabled
    assert s["speed_rpm"] == speed_after
    loop.sim.clear_mode(loop.now, active=False)  # Operate: the A138 alarm goes
    s = loop.step()
    assert loop.sim.param(740) == 6
    assert s["alarm_code"] is None
    assert s["status"] is (DriveStatus.FAULTED if fault else s["status"])
