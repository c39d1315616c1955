"""The simulated MCD 600 on its own: the rules of its guide, driven by raw telegrams."""

from __future__ import annotations

from dataclasses import replace

import pytest

from adapters.mcd600.layout import LAYOUTS, InputTelegram, Mode, OutputTelegram
from adapters.mcd600.monitoring import DataRequest, StarterState
from adapters.mcd600.options import Mcd600Options
from adapters.mcd600.paramtable import (
    AUTO_RESET_ACTION,
    AUTO_RESET_DELAY,
    AUTO_RESET_MAX,
    COMMAND_SOURCE,
    CURRENT_LIMIT,
    EXCESS_START_TIME,
    MOTOR_FLC,
    PROFIBUS_ADDRESS,
    START_RAMP_TIME,
    STOP_TIME,
    AutoResetAction,
    CommandSource,
)
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.mcd600.trips import EXCESS_START_TIME as EXCESS_START_TRIP
from adapters.mcd600.words import ControlWord, MotorSet, StatusWord
from adapters.profibus.contract import RecordAccessError
from gateway.errors import FrameDecodeError
from tests.mcd600.loop import drive_config

START = ControlWord(start=True).encode()
STOP = ControlWord().encode()


def status(sim: Mcd600Sim, outputs: bytes, now: float) -> StatusWord:
    return InputTelegram.decode(sim.layout, sim.exchange(outputs, now)).status


def test_setup_answers() -> None:
    sim = Mcd600Sim(Mode.PARAMETER)
    assert sim.expected_cfg() == LAYOUTS[Mode.PARAMETER].cfg
    assert sim.set_prm(b"\x0a") and sim.comm_timeout == 10
    assert not sim.set_prm(b"\x65")  # 101 s is out of 0-100 (guide 3.3): Prm_Fault
    assert not sim.set_prm(b"")
    with pytest.raises(RecordAccessError) as info:
        sim.read_record(0, 47, 240, 0.0)
    assert info.value.code_1 == 0xA9
    with pytest.raises(RecordAccessError):
        sim.write_record(0, 47, b"\x00", 0.0)
    with pytest.raises(FrameDecodeError):
        sim.exchange(b"\x00\x01", 0.0)  # parameter mode outputs are 7 bytes


def test_start_needs_network_as_command_source() -> None:
    sim = Mcd600Sim(params={COMMAND_SOURCE: CommandSource.DIGITAL_INPUT})
    word = status(sim, START, 0.1)
    assert not word.network_control and word.ready and not word.active
    assert sim.starts == 0
    sim.params.set(COMMAND_SOURCE, CommandSource.NETWORK)
    status(sim, STOP, 0.2)
    word = status(sim, START, 0.3)
    assert word.network_control and word.active and word.ramping


def test_start_needs_the_reset_input_closed() -> None:
    sim = Mcd600Sim()
    sim.reset_input_closed = False
    word = status(sim, START, 0.1)
    word = status(sim, START, 0.2)
    assert not word.ready and not word.active and not word.tripped  # not ready
    assert sim.starter.state is StarterState.NOT_READY
    sim.reset_input_closed = True
    assert status(sim, STOP, 0.3).ready
    assert status(sim, START, 0.4).active


def test_start_needs_bit_4_of_byte_0_clear() -> None:
    sim = Mcd600Sim()
    word = status(sim, ControlWord(start=True, quick_stop=True).encode(), 0.1)
    assert not word.active and sim.starts == 0  # guide 4.2 note


def test_motor_set_selection() -> None:
    sim = Mcd600Sim()
    status(sim, ControlWord(start=True, motor_set=MotorSet.SECONDARY).encode(), 0.1)
    assert sim.motor_set_used is MotorSet.SECONDARY
    sim = Mcd600Sim()
    sim.input_a = True
    status(sim, START, 0.1)
    assert sim.motor_set_used is MotorSet.SECONDARY  # from the remote input
    sim = Mcd600Sim()
    status(sim, ControlWord(start=True, motor_set=MotorSet.RESERVED).encode(), 0.1)
    assert sim.starts == 0


def test_current_limit_too_low_trips_on_excess_start_time() -> None:
    sim = Mcd600Sim(params={CURRENT_LIMIT: 150, START_RAMP_TIME: 2, EXCESS_START_TIME: 5})
    t = 0.0
    while t < 4.9:
        t += 0.1
        word = status(sim, START, t)
        assert word.active and word.ramping  # stalled below line speed
    assert word.current_pct_flc == pytest.approx(150.0, abs=3.2)  # held at the limit
    t += 0.3
    word = status(sim, START, t)
    assert word.tripped and sim.trip_code == EXCESS_START_TRIP
    assert sim.ext_diag() == bytes.fromhex("03 01 00")


def test_thermal_model_trips_on_overload() -> None:
    sim = Mcd600Sim(params={CURRENT_LIMIT: 600}, required_start_pct=1000.0)  # never reaches speed
    sim.params.set(EXCESS_START_TIME, 0)  # no excess start time check
    t = 0.0
    while not sim.starter.tripped and t < 60.0:
        t += 0.5
        status(sim, START, t)
    assert sim.trip_code == 2  # motor overload
    assert 9.0 < t < 20.0  # locked rotor time 10 s at 600 %
    assert not sim.starter.reset()  # still too hot to reset


def test_data_requests_out_of_range_are_flagged_invalid() -> None:
    sim = Mcd600Sim(Mode.EXTENDED)
    for number in (0, 17, 255):
        out = OutputTelegram(ControlWord(), number).encode(sim.layout)
        reply = InputTelegram.decode(sim.layout, sim.exchange(out, 0.1)).monitor
        assert reply is not None and reply.echo == number and reply.invalid


def test_small_models_report_currents_times_ten() -> None:
    sim = Mcd600Sim(Mode.EXTENDED, current_x10=True)
    status(sim, START + b"\x00", 0.1)
    out = OutputTelegram(ControlWord(start=True), DataRequest.MOTOR_CURRENT).encode(sim.layout)
    reply = InputTelegram.decode(sim.layout, sim.exchange(out, 0.2)).monitor
    assert reply is not None
    assert reply.value == round(sim.starter.current_a * 10)


def test_power_cycle_keeps_parameters_and_loses_the_rest() -> None:
    sim = Mcd600Sim()
    sim.set_prm(b"\x05")
    sim.params.set(START_RAMP_TIME, 3)
    status(sim, START, 0.1)
    sim.trip(40)
    sim.power_cycle(1.0)
    assert not sim.prm_ok and not sim.exchanging
    assert sim.comm_timeout == 10
    assert sim.params[START_RAMP_TIME] == 3
    assert not sim.starter.active and sim.trip_code == 0
    assert sim.ext_diag() == b""
    sim.tick(100.0)  # no comm timeout after a power cycle
    assert sim.trip_code == 0


def test_injected_trip_needs_a_reset_edge() -> None:
    sim = Mcd600Sim()
    sim.trip(7)
    assert status(sim, START, 0.1).tripped
    reset = ControlWord(reset=True).encode()
    assert not status(sim, reset, 0.2).tripped
    assert status(sim, reset, 0.3).ready  # held reset: one edge, one reset
    assert sim.reset_edges == 1
    with pytest.raises(ValueError):
        sim.trip(0)
    with pytest.raises(ValueError):
        sim.keypad_change(250, 1)


def run_until(sim: Mcd600Sim, word: bytes, start: float, end: float, dt: float = 0.05) -> float:
    t = start
    while t < end - 1e-9:
        t = min(end, t + dt)
        sim.exchange(word, t)
    return t


def test_keypad_reset_with_start_held_starts_again() -> None:
    """The LCP's reset clears the trip behind the master's back; start is a level (guide
    4.2), so a start the master still sends starts the motor again (why the gateway clears
    it)."""
    sim = Mcd600Sim(params={START_RAMP_TIME: 1})
    t = run_until(sim, START, 0.0, 2.0)
    assert sim.starter.state is StarterState.RUNNING and sim.starts == 1
    sim.trip(7, t)
    t = run_until(sim, START, t, t + 1.0)
    assert sim.starter.tripped and sim.starts == 1
    assert sim.keypad_reset(t) and not sim.starter.tripped and sim.faults.fault_code is None
    run_until(sim, START, t, t + 0.1)
    assert sim.starts == 2 and sim.starter.active and sim.reset_edges == 0
    stopped = Mcd600Sim()
    stopped.trip(7, 0.5)
    assert stopped.keypad_reset(1.0)
    run_until(stopped, STOP, 1.0, 3.0)  # the master sends stop: it stays ready
    assert stopped.starts == 0 and stopped.starter.state is StarterState.READY
    assert not stopped.keypad_reset(3.0)  # nothing to reset


def test_auto_reset_after_its_delay_on_the_sim_clock() -> None:
    params = {AUTO_RESET_ACTION: AutoResetAction.RESET_TRIP, AUTO_RESET_DELAY: 2}
    sim = Mcd600Sim(params={**params, AUTO_RESET_MAX: 2})
    sim.exchange(STOP, 1.0)
    sim.trip(7, 1.0)
    assert sim.auto_reset_due() == pytest.approx(3.0)
    run_until(sim, STOP, 1.0, 2.95)
    assert sim.starter.tripped
    run_until(sim, STOP, 2.95, 3.05)
    assert not sim.starter.tripped and sim.auto_resets == 1 and sim.auto_reset_due() is None
    assert sim.starts == 0  # stop held: it stays ready
    sim.trip(7, 4.0)
    sim.tick(10.0)  # one tick past the deadline: reset at 6.0
    assert not sim.starter.tripped and sim.auto_resets == 2
    sim.trip(7, 11.0)  # the maximum is reached: a manual reset is needed
    assert sim.auto_reset_due() is None
    sim.tick(100.0)
    assert sim.starter.tripped
    assert sim.keypad_reset(100.0) and sim.auto_resets == 0
    off = Mcd600Sim()  # the default: no auto-reset
    off.trip(7, 0.0)
    off.tick(1000.0)
    assert off.starter.tripped and off.auto_reset_due() is None


def test_auto_reset_retries_while_the_motor_is_too_hot() -> None:
    params = {AUTO_RESET_ACTION: AutoResetAction.RESET_TRIP, AUTO_RESET_DELAY: 1}
    sim = Mcd600Sim(params={**params, AUTO_RESET_MAX: 3})
    sim.starter.thermal_pct = 150.0
    sim.starter.trip(2)  # motor overload, still too hot to reset
    sim.tick(0.0)
    sim.tick(0.5)
    sim.tick(1.1)
    assert sim.starter.tripped and sim.auto_resets == 1
    assert sim.auto_reset_due() == pytest.approx(2.0)  # tried at 1.0: again a delay later


def test_time_scale_runs_the_power_section_faster() -> None:
    """``sim_time_scale``: the 2 s start ramp takes 0.5 s at 4x; the card's clock is not scaled."""
    sim = Mcd600Sim(params={START_RAMP_TIME: 2}, time_scale=4.0)
    sim.set_prm(b"\x01")  # communication timeout 1 s
    t = 0.0
    status(sim, START, t)
    while status(sim, START, t).ramping:
        t += 0.01
        assert t < 1.0
    assert t == pytest.approx(0.5, abs=0.06)
    assert sim.starter.state is StarterState.RUNNING
    sim.comm_lost(t)
    sim.tick(t + 0.9)  # 0.9 s of the 1 s comm timeout: not scaled, not expired
    states = [sim.starter.state]
    sim.tick(t + 1.05)  # expired: 6-13 soft trip and log, a soft stop first
    states.append(sim.starter.state)
    assert states == [StarterState.RUNNING, StarterState.STOPPING]
    with pytest.raises(ValueError, match="positive"):
        Mcd600Sim(time_scale=0.0)


def test_for_drive_programs_the_simulator_from_the_drive_table() -> None:
    options = Mcd600Options(mode=Mode.PARAMETER, flc_a=52.4, current_x10=True, sim_time_scale=3)
    sim = Mcd600Sim.for_drive(replace(drive_config(), options=options))
    assert (sim.mode, sim.params[MOTOR_FLC], sim.params[PROFIBUS_ADDRESS]) == (
        Mode.PARAMETER,
        52,  # flc_a, rounded: parameter 2 is whole amperes
        5,  # the drive's address (12-7)
    )
    assert sim.current_x10 and sim.time_scale == 3
    assert sim.starter.motor.params.rated_current == 52.0
    options = Mcd600Options(flc_a=52.0, sim_params=((MOTOR_FLC, 80), (STOP_TIME, 2)))
    sim = Mcd600Sim.for_drive(replace(drive_config(), options=options))
    assert (sim.params[MOTOR_FLC], sim.params[STOP_TIME]) == (80, 2)  # sim_params win
    assert sim.starter.motor.params.rated_current == 80.0
    assert Mcd600Sim.for_drive(drive_config(flc_a=5000.0)).params[MOTOR_FLC] == 2000
