"""The pyprofibus comparison's own machinery, without pyprofibus (never a dependency)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench import bench_pyprofibus as bench


def test_a_failed_install_is_one_json_line_saying_why(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def fail(where: Path) -> Path:
        raise bench.Skipped("pip install failed (1): no network")

    monkeypatch.setattr(bench, "install_pyprofibus", fail)
    assert bench.run() == []
    line = json.loads(capsys.readouterr().out)
    assert line == {
        "name": "pyprofibus_comparison",
        "skipped": True,
        "why": "pip install failed (1): no network",
    }


async def test_our_master_exchanges_with_the_simulator_process(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bench, "MEASURE", 0.1)
    monkeypatch.setattr(bench, "SETTLE", 0.01)
    with bench.simulator(2, None) as port:
        for timed in (False, True):
            result = await bench.our_round(port, 2, timed)
            assert result.exchanges > 0 and result.cpu > 0


def test_the_figures_compare_with_pyprofibus() -> None:
    rounds = {
        "ours_untimed": [bench.Round(2000, 1.0, 0.06)],
        "ours_timed": [bench.Round(1000, 1.0, 0.05)],
        "pyprofibus": [bench.Round(1500, 1.0, 0.15, requests=1500, overlapped=750)],
    }
    figures = {f.name: f for f in bench._figures(8, rounds)}
    assert figures["pyprofibus_cmp_ours_untimed_exchanges_per_s_8_slaves"].ratio == pytest.approx(
        4 / 3
    )
    assert figures["pyprofibus_cmp_ours_timed_cpu_per_exchange_8_slaves"].ratio == pytest.approx(
        0.5
    )
    assert figures["pyprofibus_cmp_pyprofibus_overlapped_requests_8_slaves"].value == 0.5
