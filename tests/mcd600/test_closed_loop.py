"""Profile and simulator together, without a bus, on a fake clock."""

from __future__ import annotations

from typing import Any

import pytest

from adapters.mcd600.layout import Mode
from adapters.mcd600.monitoring import REQUESTS
from adapters.mcd600.paramtable import (
    CURRENT_LIMIT,
    INITIAL_CURRENT,
    NETWORK_COMMS,
    START_RAMP_TIME,
    STOP_TIME,
    NetworkCommsAction,
)
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.mcd600.trips import MOTOR_OVERLOAD, NETWORK_FORCED_TRIP
from adapters.profibus.codec.dp import GlobalControl
from gateway.model import DriveStatus
from tests.mcd600.loop import Loop

FAST: dict[int, int] = {START_RAMP_TIME: 2, STOP_TIME: 2, INITIAL_CURRENT: 100, CURRENT_LIMIT: 180}


def fast_sim(mode: Mode = Mode.BASIC) -> Mcd600Sim:
    return Mcd600Sim(mode, required_start_pct=150.0, params=dict(FAST))


def pct(loop: Loop) -> float:
    value = loop.state.current_pct_flc
    assert value is not None
    return value


def running_loop(mode: Mode = Mode.BASIC, **options: Any) -> Loop:
    loop = Loop(mode, sim=fast_sim(mode), flc_a=100.0, **options)
    loop.step(2)
    loop.command(run=True)
    loop.run_until(lambda s: s.status is DriveStatus.RUNNING, limit=5.0)
    return loop


def test_start_run_soft_stop_with_current_following() -> None:
    loop = Loop(sim=fast_sim(), flc_a=100.0)
    assert loop.step(2).status is DriveStatus.READY
    assert loop.state.remote and not loop.state.running
    loop.command(run=True)
    t0 = loop.now
    currents = []
    while loop.step().status is not DriveStatus.RUNNING:
        assert loop.now < 5.0
        currents.append(pct(loop))
    # the current ramps from the initial current to the current limit while starting
    assert currents[0] == pytest.approx(100.0, abs=4.0)
    assert currents == sorted(currents)
    assert max(currents) == pytest.approx(180.0, abs=4.0)
    assert loop.now - t0 == pytest.approx(2.05, abs=0.1)  # start ramp time + a cycle
    running = loop.step(4)
    assert running.running and running.at_reference
    assert 55.0 < pct(loop) < 75.0  # the motor's running current
    assert running.current_a == pytest.approx(running.current_pct_flc, abs=0.01)  # FLC 100 A
    loop.command(run=False)
    t0 = loop.now
    stopping = []
    while loop.step().status is not DriveStatus.READY:
        assert loop.state.status is DriveStatus.STOPPING
        stopping.append(pct(loop))
    assert stopping == sorted(stopping, reverse=True)
    assert loop.now - t0 == pytest.approx(2.05, abs=0.1)  # 2 s soft stop + a cycle
    assert loop.state.current_pct_flc == 0.0 and not loop.state.running
    assert loop.statuses == [
        DriveStatus.READY,
        DriveStatus.STARTING,
        DriveStatus.RUNNING,
        DriveStatus.STOPPING,
        DriveStatus.READY,
    ]
    assert loop.state.speed_rpm is None and loop.state.speed_pct is None


def test_coast_stop_turns_the_output_off_at_once() -> None:
    loop = running_loop()
    loop.command(run=False, coast_stop=True)
    state = loop.step()
    assert state.status is DriveStatus.READY
    assert state.current_pct_flc == 0.0
    assert loop.controls[-1].quick_stop


def test_trip_needs_a_reset_and_a_new_run() -> None:
    loop = running_loop()
    loop.sim.trip(MOTOR_OVERLOAD)  # run stays requested
    assert loop.step().status is DriveStatus.TRIPPED
    [event] = loop.diag()
    assert (event.kind, event.text) == ("trip", "trip 2: Motor overload")
    state = loop.step()
    assert (state.fault_code, state.fault_text) == (2, "Motor overload")
    assert state.current_pct_flc == 0.0 and not state.running
    assert loop.step(10).status is DriveStatus.TRIPPED  # stays tripped until reset
    loop.fault_reset()
    assert loop.step(10).status is DriveStatus.READY
    assert loop.state.fault_code is None and loop.state.fault_text is None
    assert loop.sim.reset_edges == 1 and loop.reset_edges() == 1
    loop.step(40)  # run is still requested: no restart
    assert loop.state.status is DriveStatus.READY and loop.sim.starts == 1
    assert loop.reset_edges() == 1  # and the reset is never repeated
    assert loop.sim.ext_diag() == b""  # 5.1.1: the reset cleared the trip code
    loop.command(run=False)
    loop.step()
    loop.command(run=True)
    loop.run_until(lambda s: s.status is DriveStatus.RUNNING, limit=5.0)
    assert loop.sim.starts == 2


def test_trip_while_stopped_and_the_diagnosis_telegram() -> None:
    loop = Loop(sim=fast_sim())
    loop.step()
    loop.sim.trip(90)
    assert loop.sim.diag_alert
    assert loop.sim.ext_diag() == bytes.fromhex("03 5A 00")
    [event] = loop.diag()
    assert event.text.startswith("trip 90: Internal fault 90")
    assert loop.step().fault_code == 90
    loop.fault_reset()
    loop.step(6)
    assert loop.sim.ext_diag() == b""  # 5.1.1: reset clears the trip code
    assert loop.state.fault_code is None
    # the profile saw the reset in the status word: a cleared telegram is no news
    assert loop.profile.on_ext_diag(bytes.fromhex("03 00 00")) == []
    loop.sim.trip(90)  # the same trip again: the same bytes, a new trip
    loop.step()
    [again] = loop.diag()
    assert again.text.startswith("trip 90: Internal fault 90")


def test_extended_mode_round_robin_fills_fields_and_leaves_unread_ones_none() -> None:
    period, dt = 0.25, 0.0625  # binary fractions: exact on the fake clock
    loop = Loop(Mode.EXTENDED, sim=fast_sim(Mode.EXTENDED), request_period=period)
    other = Loop(Mode.EXTENDED, sim=fast_sim(Mode.EXTENDED), request_period=period, drive_id="x")
    loop.step(dt=dt)  # request 1 sent and answered
    assert loop.state.values == {"product_type": 15}
    assert loop.state.motor_temp_pct is None
    assert loop.state.power_kw is None and loop.state.voltage_v is None
    loop.step(16, dt=dt)  # one more request every 0.25 s: requests 1-5 asked by now
    assert [c.start for c in loop.controls] == [False] * 17
    assert loop.state.motor_temp_pct == 0.0  # request 4
    assert loop.state.power_kw is None and loop.state.voltage_v is None  # 6 and 8 not yet
    assert loop.state.values["starter_state"] == 1  # request 2: ready
    assert loop.state.values["power_factor"] == 0.0  # request 5
    assert "current_l1_a" not in loop.state.values
    loop.step(48, dt=dt)  # past a whole round
    state = loop.state
    assert state.voltage_v == 400.0 and state.power_kw == 0.0
    assert state.values["voltage_l1_v"] == 400.0
    assert state.values["software_version_major"] == 1
    assert state.values["input_reset"] == 1
    assert loop.profile._poller.invalid == set()
    # another drive's profile has read nothing: no shared state
    assert other.state.values == {} and other.state.voltage_v is None
    other.step()
    assert other.state.values == {"product_type": 15}


def test_extended_mode_readings_while_running() -> None:
    loop = running_loop(Mode.EXTENDED, request_period=0.0)  # a new request every cycle
    loop.step(len(REQUESTS))
    state = loop.state
    assert state.values["starter_state"] == 3  # running
    assert state.values["current_avg_a"] == pytest.approx(state.current_a, abs=2.0)
    assert state.power_kw is not None and 30.0 < state.power_kw < 45.0  # sqrt3 400 V 65 A 0.85
    assert state.values["apparent_power_kva"] > state.power_kw
    assert state.values["power_factor"] == 0.85
    assert state.motor_temp_pct is not None and state.motor_temp_pct >= 0.0


def test_extended_mode_gives_the_trip_code_without_the_diagnosis() -> None:
    loop = Loop(Mode.EXTENDED, sim=fast_sim(Mode.EXTENDED), request_period=0.0)
    loop.step()
    loop.sim.trip(MOTOR_OVERLOAD)
    loop.step(len(REQUESTS))
    assert loop.state.status is DriveStatus.TRIPPED
    assert (loop.state.fault_code, loop.state.fault_text) == (2, "Motor overload")


def test_comm_loss_trips_after_the_timeout() -> None:
    loop = running_loop(comm_timeout=10)
    loop.sim.params.set(NETWORK_COMMS, NetworkCommsAction.TRIP_STARTER)
    lost = loop.now
    loop.sim.comm_lost(lost)
    loop.profile.on_comm_lost()
    loop.sim.tick(lost + 9.9)
    assert loop.sim.starter.active  # 3.3: the state holds until the timeout
    loop.sim.tick(lost + 10.05)
    assert loop.sim.trip_code == NETWORK_FORCED_TRIP
    # the master comes back: Set_Prm again, data exchange, diagnosis
    loop.now = lost + 11.0
    assert loop.sim.set_prm(loop.profile.setup().user_prm)
    assert loop.step().status is DriveStatus.TRIPPED
    [event] = loop.diag()
    assert event.text == "trip 16: Network forced trip"
    assert loop.step().fault_code == NETWORK_FORCED_TRIP
    assert loop.sim.starts == 1


def test_comm_loss_with_soft_trip_stops_softly_then_trips() -> None:
    loop = running_loop(comm_timeout=5)  # 6-13 default: soft trip and log
    lost = loop.now
    loop.sim.comm_lost(lost)
    loop.sim.tick(lost + 5.1)
    assert loop.sim.starter.active and loop.sim.trip_code == 0  # soft stopping (2 s)
    loop.sim.tick(lost + 7.5)
    assert loop.sim.trip_code == NETWORK_FORCED_TRIP


def test_comm_timeout_zero_keeps_the_state() -> None:
    loop = running_loop(comm_timeout=0)
    loop.sim.comm_lost(loop.now)
    loop.sim.tick(loop.now + 300.0)
    assert loop.sim.starter.active and loop.sim.trip_code == 0


def test_comm_back_before_the_timeout_cancels_it() -> None:
    loop = running_loop(comm_timeout=10)
    loop.sim.comm_lost(loop.now)
    loop.now += 5.0
    loop.step()
    loop.sim.tick(loop.now + 20.0)
    assert loop.sim.trip_code == 0


def test_global_control_clear_is_a_quick_stop() -> None:
    loop = running_loop()
    loop.sim.global_control(GlobalControl.clear(), loop.now)
    assert loop.sim.starter.current_a == 0.0
    loop.command(run=False)
    assert loop.step().status is DriveStatus.READY


def test_sync_holds_commands_until_the_next_sync() -> None:
    loop = Loop(sim=fast_sim())
    loop.step()
    loop.sim.global_control(GlobalControl(sync=True), loop.now)
    loop.command(run=True)
    loop.step(5)
    assert loop.sim.starts == 0  # 6.2: not processed until another Sync
    loop.sim.global_control(GlobalControl(sync=True), loop.now)
    assert loop.sim.starts == 1
    loop.command(run=False)
    loop.step(2)
    assert loop.sim.starter.state.name == "STARTING"
    loop.sim.global_control(GlobalControl(unsync=True), loop.now)
    assert loop.sim.starter.state.name == "STOPPING"


def test_freeze_holds_inputs_until_the_next_freeze() -> None:
    loop = Loop(sim=fast_sim())
    loop.step()
    loop.sim.global_control(GlobalControl(freeze=True), loop.now)
    loop.command(run=True)
    loop.step(10)
    assert loop.sim.starter.active
    assert loop.state.status is DriveStatus.READY  # 6.1: inputs frozen
    loop.sim.global_control(GlobalControl(freeze=True), loop.now)
    assert loop.step().status is DriveStatus.STARTING
    loop.sim.global_control(GlobalControl(unfreeze=True), loop.now)
    loop.run_until(lambda s: s.status is DriveStatus.RUNNING, limit=5.0)


def test_keypad_change_is_reported_in_the_diagnosis() -> None:
    loop = Loop(sim=fast_sim())
    loop.step()
    loop.sim.keypad_change(STOP_TIME, 7)
    assert not loop.sim.diag_alert  # 5.1.2: no diagnosis alarm for a changed parameter
    assert loop.sim.ext_diag() == bytes.fromhex("03 00 09")
    [event] = loop.diag()
    assert (event.kind, event.data) == ("parameter", {"number": STOP_TIME})
    assert loop.diag() == []


@pytest.mark.parametrize("stop", ["quick_stop", "coast_stop"])
def test_release_of_a_stop_does_not_restart(stop: str) -> None:
    # issue 17 item 4 / rule 1: the quick stop action (4.2 table 2, byte 0 bit 4) with start
    # 0; released while the desired command still says run, the starter stays stopped
    loop = running_loop()
    loop.command(**{stop: True})
    loop.run_until(lambda s: not s.running, limit=5.0)
    assert loop.controls[-1].quick_stop and not loop.controls[-1].start
    loop.command(**{stop: False})
    loop.step(40)  # 2 s, the start ramp time
    assert not any(c.start for c in loop.controls[-40:])
    assert loop.state.status is DriveStatus.READY and not loop.state.running
    loop.command(run=False)
    loop.step()
    loop.command(run=True)  # a new run command after the release starts it
    loop.run_until(lambda s: s.status is DriveStatus.RUNNING, limit=5.0)
