"""The CANopen benchmark's machinery, run tiny (the figures are `make bench`'s; no timing is
asserted here): the broker and the simulator process start, the bare library loop and the
gateway both exchange PDOs with the node over the paced bus, and every process ends."""

from __future__ import annotations

import pytest

from bench import bench_canopen


def test_both_cases_exchange_pdos_on_the_paced_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench_canopen, "MEASURE", 0.3)
    # past the master's listening time before it sends (>= 0.3 s: another master on the line?)
    monkeypatch.setattr(bench_canopen, "SETTLE", 0.5)
    [figure] = bench_canopen.run((1,))
    assert figure.name == "canopen_pdo_cycles_1_nodes"
    assert figure.value > 0  # the gateway received TPDO1s in its window
    assert figure.reference is not None and figure.reference > 0  # so did the bare loop
    assert figure.target == "ratio >= 0.5"
    assert "SYNC every 285 us" in figure.note  # the physical minimum for one node at 1 Mbit/s
    assert "plantcan" in figure.note


def test_the_sync_period_is_the_line_minimum_in_whole_us() -> None:
    bus = bench_canopen._bus("unused.sock", 32)
    assert bench_canopen.physical_sync(bus) == pytest.approx(7415e-6)
    assert bench_canopen.physical_sync(bus) >= bench_canopen.line_minimum(bus)
