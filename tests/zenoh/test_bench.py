"""The Zenoh benchmark's machinery, run short (the figures are `make bench`'s)."""

from __future__ import annotations

import asyncio

import pytest
import zenoh

from bench import bench_zenoh as bench
from gateway.zenoh import link


def _state(speed: float, *, spaced: bool = False) -> bytes:
    sep = ": " if spaced else ":"
    return f'{{"id"{sep}"d0","speed_rpm"{sep}{speed}}}'.encode()


def test_a_run_is_counted_up_to_its_sentinel_and_no_further() -> None:
    counts = bench.RunCounts()
    counts.add("bench/raw/drives/d0/state", _state(1.0), 10.0)
    counts.add("bench/raw/drives/d1/state", _state(2.0), 11.0)
    counts.add("bench/raw/drives/d0/state", _state(bench.SENTINEL), 12.0)
    counts.add("bench/raw/drives/d0/state", _state(bench.SENTINEL), 12.05)  # a settle put
    counts.add("bench/drives/d3/state", _state(5.0), 20.0)  # the gateway's own key
    counts.add("bench/naive/drives/d0/state", _state(bench.SENTINEL, spaced=True), 30.0)
    report = counts.report()
    assert report["raw"] == {"n": 3, "seconds": pytest.approx(2.0)}
    assert report["gateway"]["n"] == 1
    assert report["naive"]["n"] == 1
    assert report["floor"]["n"] == 0
    assert {name for name, ended in counts.ended.items() if ended.is_set()} == {"raw", "naive"}


def test_the_reference_is_put_with_the_gateways_qos_for_a_change() -> None:
    # docs/decisions/0011-zenoh-bench-references.md: the gateway's QoS for a change, which is zenoh-python's default
    session = bench._session()  # no endpoints: nothing leaves the process
    try:
        plain = session.declare_publisher(f"{bench.PREFIX}/raw/drives/d0/state")
        assert plain.congestion_control == link.DROP == zenoh.CongestionControl.DROP
        assert bench.REFERENCE_QOS == link.DROP
        plain.undeclare()
    finally:
        session.close()


def test_one_short_fanout_measures_every_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench, "FANOUT_SECONDS", 0.2)
    # a loop of its own, as `make bench` runs it: it ends with its executor's thread
    figures = {f.name: f for f in asyncio.run(bench._fanout())}
    assert sorted(figures) == [
        "zenoh state fan-out (vs floor)",
        "zenoh state fan-out (vs hub alone)",
        "zenoh state fan-out (vs naive bridge)",
        "zenoh state fan-out (vs raw BLOCK puts)",
        "zenoh state fan-out (vs raw puts)",
    ]
    assert all(f.value > 0 and (f.reference or 0) > 0 for f in figures.values())
    target = figures["zenoh state fan-out (vs raw puts)"]
    assert target.target == "ratio >= 0.5"
    assert "(CongestionControl.DROP)" in target.note
    assert figures["zenoh state fan-out (vs raw BLOCK puts)"].target is None


def test_the_command_latency_has_its_reference_from_the_same_puts() -> None:
    figures = {f.name: f for f in asyncio.run(bench._commands())}
    p99 = figures["zenoh command latency p99"]
    assert p99.target == "p99 < 5 ms"
    assert p99.reference is not None and p99.reference > 0
    assert figures["zenoh command latency p50"].reference is not None
    assert p99.note.startswith(
        f"{bench.COMMANDS} of {bench.COMMANDS} commands arrived; reference: "
    )
