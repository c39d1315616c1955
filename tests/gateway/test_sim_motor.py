from __future__ import annotations

import pytest

from gateway.sim import FaultInjector, Motor, MotorParams


def motor(**kw: float) -> Motor:
    return Motor(MotorParams(rated_rpm=1800, accel_time=2.0, decel_time=4.0, **kw))


def test_ramps_up_at_the_acceleration_time() -> None:
    m = motor()
    m.command(True, 1800)
    m.advance(1.0)
    assert m.speed == pytest.approx(900)
    m.advance(1.5)
    assert m.speed == 1800


def test_ramps_down_at_the_deceleration_time() -> None:
    m = motor()
    m.command(True, 1800)
    m.advance(10)
    m.command(True, 0)
    m.advance(2.0)
    assert m.speed == pytest.approx(900)


def test_reversal_goes_through_zero_with_both_ramps() -> None:
    m = motor()
    m.command(True, 900)
    m.advance(10)
    m.command(True, -900)
    m.advance(2.0)  # 900 -> 0 at decel (1800/4 rpm/s) takes 2 s
    assert m.speed == pytest.approx(0, abs=1e-6)
    m.advance(0.5)  # then accel 900 rpm/s
    assert m.speed == pytest.approx(-450)


def test_coast_down_uses_coast_time_and_no_current() -> None:
    m = motor(coast_time=9.0)
    m.command(True, 1800)
    m.advance(10)
    m.coast()
    assert m.current() == 0.0
    m.advance(4.5)
    assert m.speed == pytest.approx(900)


def test_quick_stop_is_fast() -> None:
    m = motor(quick_stop_time=0.5)
    m.command(True, 1800)
    m.advance(10)
    m.quick_stop()
    m.advance(0.5)
    assert m.speed == 0


def test_current_grows_with_speed_and_magnetising_at_rest() -> None:
    m = motor()
    m.command(True, 0)
    idle = m.current()
    m.command(True, 1800)
    m.advance(10)
    assert idle == pytest.approx(m.params.magnetising_current)
    assert m.current() > idle


def test_deterministic_faults() -> None:
    a, b = FaultInjector(seed=7, bit_error_rate=0.1), FaultInjector(seed=7, bit_error_rate=0.1)
    data = bytes(range(200))
    assert a.corrupt(data) == b.corrupt(data) != data
    assert FaultInjector().corrupt(data) == data
