"""``/api/drives/<id>/history``: any range from the history store, bad parameters refused
by name, the trend's ring without ``[history]``."""

from __future__ import annotations

import time
from pathlib import Path

from gateway.history.store import READINGS, HistoryDb, HistoryStore, Sample, WriterCounters
from tests.web.harness import small_gateway, web_section

NOW = time.time()


def make_store(tmp_path: Path) -> HistoryStore:
    path = tmp_path / "h.sqlite"
    db = HistoryDb.open_checked(path)
    rest = (None,) * (len(READINGS) - 1)
    start = 3600 * (NOW // 3600) - 2 * 86400  # two days ago, on the hour
    db.write([Sample("d1", start + i, (float(i % 60), *rest)) for i in range(0, 7200)], [])
    db.close()
    return HistoryStore(path)


async def test_any_range_from_the_store(tmp_path: Path) -> None:
    async with small_gateway(web_section()) as gw:
        gw.runtime.history = make_store(tmp_path)
        url = f"{gw.url}api/drives/d1/history?start=now-3d&step=1h"
        async with gw.http.get(url) as r:
            assert r.status == 200
            body = await r.json()
        assert len(body["t"]) == 2
        assert body["values"]["speed_rpm"] == [29.5, 29.5]
        assert body["step"] == 3600


async def test_bad_parameters_are_a_400_naming_them(tmp_path: Path) -> None:
    async with small_gateway(web_section()) as gw:
        gw.runtime.history = make_store(tmp_path)
        async with gw.http.get(f"{gw.url}api/drives/d1/history?start=soon") as r:
            assert r.status == 400
            assert "start='soon' is not a time" in (await r.json())["error"]
        async with gw.http.get(f"{gw.url}api/drives/nope/history") as r:
            assert r.status == 404
        async with gw.http.get(f"{gw.url}api/drives/d1/history?events&step=1") as r:
            assert r.status == 400


async def test_without_history_the_ring_answers() -> None:
    async with small_gateway(web_section(), speed_rpm=120.0) as gw:
        gw.web.feed.history.sample(time.time(), gw.hub.states())
        async with gw.http.get(f"{gw.url}api/drives/d1/history?start=now-10m") as r:
            assert r.status == 200
            body = await r.json()
        assert body["values"]["speed_rpm"] == [120.0]


async def test_the_writers_counters_in_metrics(tmp_path: Path) -> None:
    async with small_gateway(web_section()) as gw:
        counters = WriterCounters(samples=7, samples_dropped=2, events=3, moved_aside=1)
        gw.runtime.history = HistoryStore(tmp_path / "h.sqlite", counters=counters)
        async with gw.http.get(f"{gw.url}metrics") as r:
            text = await r.text()
    assert 'drive_gateway_history_samples_total{result="written"} 7.0' in text
    assert 'drive_gateway_history_samples_total{result="dropped"} 2.0' in text
    assert 'drive_gateway_history_events_total{result="written"} 3.0' in text
    assert "drive_gateway_history_moved_aside_total 1.0" in text
