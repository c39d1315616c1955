"""The pty floor benchmark's machinery, run tiny (no timing is asserted): the echo process
answers every telegram whole, the figures carry Felser's exchange time as their reference,
and the echo process ends."""

from __future__ import annotations

import pytest

from bench import bench_pty


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
    }
    assert figures["pty_round_trip_p50_us"].value > 0
    assert figures["pty_round_trip_p50_us"].reference == pytest.approx(352 / 1.5)
    assert figures["pty_round_trip_vs_budget"].reference == pytest.approx(0.05 * 352 / 1.5)
