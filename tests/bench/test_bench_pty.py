"""The pty floor benchmark's machinery, run tiny (no timing is asserted): the echo process
answers every telegram whole, the figures carry Felser's exchange time as their reference,
and the echo process ends."""

from __future__ import annotations

import time

import pytest

from bench import bench_pty
from bench.common import sleep_cpu


def test_felser_exchange_time_at_1_5_mbit() -> None:
    # 11 bits a character x (14 + 14) + min TSDR 11 + TSYN 33 = 352 bit times
    assert bench_pty.line_time() == pytest.approx(352 / 1_500_000)


def test_a_tiny_run_gives_every_figure() -> None:
    figures = {f.name: f for f in bench_pty.run(50)}
    assert set(figures) == {
        "pty_round_trip_p50_us",
        "pty_round_trip_p99_us",
        "pty_round_trip_vs_budget",
        "pty_requester_cpu_us",
        "host_sleep_cpu_us",
    }
    assert figures["pty_round_trip_p50_us"].value > 0
    assert figures["pty_round_trip_p50_us"].reference == pytest.approx(352 / 1.5)
    assert figures["pty_round_trip_vs_budget"].reference == pytest.approx(0.05 * 352 / 1.5)


def test_the_sleep_figure_sleeps_each_time_for_the_wait_given() -> None:
    # a select(2) never returns before its timeout with nothing to read: 20 sleeps of
    # 2 ms take 40 ms at least, and the call without a wait does not sleep at all
    start = time.monotonic()
    sleep, call = sleep_cpu(0.002, 20)
    assert time.monotonic() - start >= 20 * 0.002
    assert sleep >= 0 and call >= 0
