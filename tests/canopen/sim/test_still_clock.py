"""The simulated drives' clock leaves out the time their process stood still."""

from __future__ import annotations

import pytest

from adapters.canopen.sim.clock import STILL_GAP, StillClock


class Base:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_it_runs_with_its_base_while_read_often() -> None:
    base = Base()
    clock = StillClock(base)
    start = clock()
    for _ in range(100):
        base.t += 0.01
        clock()
    assert clock() - start == pytest.approx(base.t - 100.0)
    assert clock.stood_still == 0.0


def test_a_gap_longer_than_the_still_gap_counts_as_that_gap_only() -> None:
    base = Base()
    clock = StillClock(base)
    start = clock()
    base.t += 5.0  # the process stood still for 5 s
    assert clock() - start == pytest.approx(STILL_GAP)
    assert clock.stood_still == pytest.approx(5.0 - STILL_GAP)
    base.t += 0.01
    assert clock() - start == pytest.approx(
        STILL_GAP + 0.01
    )  # and runs on from there, never backwards
