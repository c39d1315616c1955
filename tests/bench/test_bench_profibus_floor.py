"""The Profibus timing case's floor figures: what a master that sleeps once more per
exchange with timing kept, and costs nothing else for it, would show (arithmetic only)."""

from __future__ import annotations

import pytest

from bench.bench_profibus import MasterRun, TimingCase, _timing_figures


def _run(cpu_per_exchange: float, sleeps: float) -> MasterRun:
    return MasterRun(1000.0, 0.0, 0.0, cpu_per_exchange, sleeps=sleeps)


def _case(*runs: tuple[float, float], sleep: float) -> TimingCase:
    """Timed, untimed, paced timed, paced untimed: (CPU per exchange, sleeps) each."""
    timed, untimed, paced, paced_untimed = (_run(*run) for run in runs)
    return TimingCase(timed, untimed, [], paced, paced_untimed, [], sleep)


def test_the_floor_is_timing_off_plus_the_extra_sleeps() -> None:
    case = _case((120e-6, 2.0), (60e-6, 1.0), (110e-6, 2.0), (80e-6, 1.0), sleep=30e-6)
    figures = {f.name: f for f in _timing_figures(1, case)}
    unpaced = figures["profibus_timed_cpu_against_floor_1_slaves"]
    assert unpaced.value == pytest.approx(120)
    assert unpaced.reference == pytest.approx(90)  # 60 + 30
    assert figures["profibus_timing_ratio_floor_1_slaves"].value == pytest.approx(1.5)
    paced = figures["profibus_paced_timed_cpu_against_floor_1_slaves"]
    assert paced.reference == pytest.approx(110)  # 80 + 30
    assert paced.ratio == pytest.approx(1.0)
    assert figures["profibus_paced_timing_ratio_floor_1_slaves"].value == pytest.approx(1.375)
    assert "30.0 us" in paced.note
    assert "2.00 with timing, 1.00 without" in paced.note


def test_only_the_sleeps_timing_adds_count() -> None:
    # timing off found half its replies already in (0.5 sleeps per exchange): the timed
    # run's 2 sleeps are 1.5 more; fewer sleeps with timing never lower the floor
    case = _case((120e-6, 2.0), (60e-6, 0.5), (110e-6, 0.9), (80e-6, 1.0), sleep=20e-6)
    figures = {f.name: f for f in _timing_figures(8, case)}
    assert figures["profibus_timed_cpu_against_floor_8_slaves"].reference == pytest.approx(90)
    assert figures["profibus_paced_timing_ratio_floor_8_slaves"].value == pytest.approx(1.0)
