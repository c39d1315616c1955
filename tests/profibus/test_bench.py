"""The Profibus benchmark's own machinery, run very short (the figures are `make bench`'s)."""

from __future__ import annotations

import os
import select

import pytest

from adapters.profibus.codec.fdl import SD3, decode_telegram
from bench import bench_profibus as bench


def test_the_reference_has_the_sizes_of_the_masters_telegrams() -> None:
    # 8 bytes without SAPs: LE = 11, so request and reply are SD3 telegrams (1.2)
    frames = bench.exchange_frames(2)
    assert {len(f) for f in frames} == {bench.REQUEST_LEN} == {14}
    assert bench.REPLY_LEN == 14
    assert all(f[0] == SD3 for f in [*frames, bench.reply_frame()])
    assert [decode_telegram(f).fc.encode() for f in frames] == [0x7D, 0x7D, 0x5D, 0x5D]  # type: ignore[union-attr]


def test_felser_estimate() -> None:
    # (380 + 300 + 11 x 16) bit times at 500 kbit/s + 75 us
    assert bench.felser_cycle(1, 500000) == pytest.approx(1.787e-3)
    assert bench.felser_cycle(32, 187500) == pytest.approx((380 + 9600 + 11 * 512) / 187500 + 75e-6)


class _Clock:
    """perf_counter and process_time for the bench, set by the test."""

    def __init__(self) -> None:
        self.wall = self.cpu = 0.0

    def at(self, wall: float, cpu: float) -> None:
        self.wall, self.cpu = wall, cpu


def test_windows_give_the_best_stretch_and_the_least_cpu() -> None:
    clock = _Clock()
    windows = bench.Windows(lambda: clock.wall, lambda: clock.cpu)
    assert windows.best_rate() == 0.0  # no whole window yet
    for wall, cpu, done in [
        (0.00, 0.000, 0),
        (0.05, 0.010, 100),  # 2,000/s, 100 us CPU each
        (0.07, 0.012, 150),  # inside the next window: no mark
        (0.10, 0.016, 400),  # 6,000/s over 0.05 s, 20 us CPU each
        (0.16, 0.028, 500),  # 1,667/s, 120 us each
    ]:
        clock.at(wall, cpu)
        windows.tick(done)
    assert windows.best_rate() == pytest.approx(6000)
    assert windows.least_cpu() == pytest.approx(20e-6)


async def test_the_masters_own_time_without_io() -> None:
    assert await bench.engine_cost(3, messages=200) > 0  # seconds per message, measured


def test_one_short_round_measures_everything(monkeypatch: pytest.MonkeyPatch) -> None:
    """Master and both bare requesters get their replies (a wrong length would hang)."""
    monkeypatch.setattr(bench, "MEASURE", 0.05)
    monkeypatch.setattr(bench, "WINDOW", 0.01)
    monkeypatch.setattr(bench, "SETTLE", 0.01)
    monkeypatch.setattr(bench, "ROUNDS", 1)
    case = bench.measure(2)
    assert case.master.cycles_per_s > 0
    assert case.master.cpu_per_cycle > 0
    assert case.loop_raw.round_trips_per_s > 0
    assert case.blocking_raw > 0
    assert case.peer_check > 0


def _two_cpus() -> bench.Placement:
    where = bench.placement()
    if where is None:
        pytest.skip("one CPU: the bench leaves placement to the scheduler")
    return where


def _say_affinity(fd: int) -> None:
    os.read(fd, 1)  # only once asked: opening the line flushes what came before
    os.write(fd, repr(sorted(os.sched_getaffinity(0))).encode() + b"\n")


def test_a_responder_runs_on_the_responder_cpu() -> None:
    where = _two_cpus()
    assert where.requester.isdisjoint(where.responder)
    with bench._child(_say_affinity, where=where) as path, bench._open_raw(path) as fd:
        os.write(fd, b"?")
        said = b""
        while not said.endswith(b"\n"):
            readable, _, _ = select.select([fd], [], [], 10.0)
            assert readable, "the responder did not say its CPUs within 10 s"
            said += os.read(fd, 64)
    assert said.decode().strip() == repr(sorted(where.responder))


def test_pinned_rounds_give_the_process_its_affinity_back(monkeypatch: pytest.MonkeyPatch) -> None:
    where = _two_cpus()
    monkeypatch.setattr(bench, "MEASURE", 0.05)
    monkeypatch.setattr(bench, "WINDOW", 0.01)
    monkeypatch.setattr(bench, "SETTLE", 0.01)
    monkeypatch.setattr(bench, "ROUNDS", 1)
    before = os.sched_getaffinity(0)
    seen: list[set[int]] = []
    run_master = bench.run_master

    async def spy(path: str, slaves: int, duration: float) -> bench.MasterRun:
        seen.append(os.sched_getaffinity(0))
        return await run_master(path, slaves, duration)

    monkeypatch.setattr(bench, "run_master", spy)
    case = bench.measure(2, where)
    assert seen == [set(where.requester)]
    assert os.sched_getaffinity(0) == before
    assert case.master.cycles_per_s > 0
    assert case.loop_raw.round_trips_per_s > 0


def test_percentile_is_the_nearest_rank() -> None:
    values = [float(v) for v in range(1, 1001)]
    assert bench.percentile(values, 0.5) == 500
    assert bench.percentile(values, 0.99) == 990
    assert bench.percentile(values, 0.999) == 999
    assert bench.percentile([], 0.5) != bench.percentile([], 0.5)  # NaN


def test_one_short_timing_round_keeps_every_not_before(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every setting exchanges, and no request went before its not_before (500 kbit/s)."""
    monkeypatch.setattr(bench, "TIMING_MEASURE", 0.1)
    monkeypatch.setattr(bench, "TIMING_ROUNDS", 1)
    monkeypatch.setattr(bench, "SETTLE", 0.01)
    case = bench.measure_timing(2)
    assert case.timed.cycles_per_s > 0 and case.untimed.cycles_per_s > 0
    assert case.lateness and min(case.lateness) >= 0
    # against slaves paced like the line, TSYN after a reply is slept in the step
    assert case.paced.cycles_per_s > 0 and case.paced_untimed.cycles_per_s > 0
    assert case.paced_lateness and min(case.paced_lateness) >= 0
    figures = {f.name: f for f in bench._timing_figures(2, case)}
    assert figures["profibus_timed_cpu_per_exchange_2_slaves"].ratio is not None
    assert figures["profibus_paced_timed_cpu_per_exchange_2_slaves"].ratio is not None
