"""The adapter refreshes the outputs once per poll interval, but never twice in one poll cycle."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from adapters.devicenet.adapter import DeviceNetAdapter
from gateway.config import load

CONFIG = """
[buses.dn]
adapter = 'devicenet'
poll_interval = 0.001
[[buses.dn.drives]]
id = 'd'
device = 'CFW-08'
address = 5
max_rpm = 1800
"""


def test_outputs_are_refreshed_once_per_cycle_when_a_cycle_outlasts_the_interval(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "site.toml"
    path.write_text(CONFIG)
    adapter = DeviceNetAdapter(load(path).buses[0])
    refreshed: list[float] = []
    monkeypatch.setattr(adapter, "_refresh_outputs", refreshed.append)
    schedule = SimpleNamespace(cycle_started=None)
    line = SimpleNamespace(cycles=0)
    adapter.engine = SimpleNamespace(schedule=schedule, line=line)  # type: ignore[assignment]

    # no cycle under way (nothing polled yet, or COS/cyclic nodes only): every interval
    for now in (1.0, 1.0005, 1.001, 1.002):
        adapter.before_step(now)
    assert refreshed == [1.0, 1.001, 1.002]

    # a cycle of 63 nodes takes ~25 ms at 500 kbit/s: one refresh until it ends
    schedule.cycle_started = 1.0025
    refreshed.clear()
    for i in range(1, 25):
        adapter.before_step(1.0025 + i * 0.001)
    assert refreshed == []
    assert adapter.wake_at() is None  # the cycle's end (an event) steps the driver
    line.cycles = 1  # it ended, the next one began in the same step
    adapter.before_step(1.03)
    assert refreshed == [1.03]
    adapter.before_step(1.04)
    assert refreshed == [1.03]
    assert adapter.wake_at() is None
