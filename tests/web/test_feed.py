"""The push feed and the trend history: bounded, conflating, and never waiting for a page."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from gateway.model import CommState, DriveStatus
from gateway.web import feed as feed_module
from gateway.web.feed import CLIENT_QUEUE, DIAG_EVERY, SAMPLE_EVERY, ClientQueue, FeedCounters
from gateway.web.history import TrendHistory
from tests.web.harness import small_gateway, web_section


def test_the_history_keeps_ten_minutes_and_no_more() -> None:
    history = TrendHistory(period=0.5, span=600.0)
    assert history.capacity == 1200
    from gateway.model import Device, DriveState

    state = DriveState(id="d", device=Device.TEST, bus="b", address=1, speed_rpm=10.0)
    for i in range(1500):
        history.sample(1000.0 + i * 0.5, [state])
    points = history.points("d")
    assert len(points) == 1200
    assert points[0][0] == 1000.0 + 300 * 0.5 and points[-1][0] == 1000.0 + 1499 * 0.5
    as_json = history.to_json("d")
    assert len(as_json["t"]) == len(as_json["speed"]) == 1200 and as_json["ref"][0] is None


async def test_a_client_that_falls_behind_gets_one_fresh_snapshot_not_a_backlog() -> None:
    counters = FeedCounters()
    queue = ClientQueue(counters)
    made: list[str] = []

    def snapshot() -> str:
        made.append(f"snapshot {len(made)}")
        return made[-1]

    assert await queue.next(snapshot) == "snapshot 0"  # a new client starts with one
    for i in range(CLIENT_QUEUE):
        queue.offer(f"m{i}")
    assert len(queue) == CLIENT_QUEUE and counters.dropped == 0
    queue.offer("one too many")
    assert len(queue) == 0 and counters.dropped == CLIENT_QUEUE + 1
    queue.offer("covered by the snapshot")
    assert counters.dropped == CLIENT_QUEUE + 2
    assert await queue.next(snapshot) == "snapshot 1"  # made when read: the latest state
    queue.offer("next")
    assert await queue.next(snapshot) == "next"


async def test_a_step_sends_the_newest_state_of_each_changed_drive_once() -> None:
    async with small_gateway(web_section()) as gw:
        feed = gw.web.feed
        client = feed.add()
        await client.next(feed.snapshot)
        for speed in (1.0, 2.0, 3.0):
            gw.hub.update("d1", speed_rpm=speed)
        gw.hub.update("d2", status=DriveStatus.RUNNING)
        text = feed.step()
        assert text is not None
        message = json.loads(text)
        rows = {row["id"]: row for row in message["drives"]}
        assert rows["d1"]["speed_rpm"] == 3.0 and rows["d2"]["status"] == "running"
        assert len(message["drives"]) == 2
        assert await client.next(feed.snapshot) == text
        feed.remove(client)


async def test_samples_and_figures_come_at_their_own_pace() -> None:
    async with small_gateway(web_section()) as gw:
        feed = gw.web.feed
        client = feed.add()
        await client.next(feed.snapshot)
        kinds: list[set[str]] = []
        for _ in range(DIAG_EVERY * 2):
            gw.hub.update("d1", speed_rpm=float(len(kinds)))
            text = feed.step()
            kinds.append(set(json.loads(text)) if text else set())
        sampled = [i for i, k in enumerate(kinds) if "points" in k]
        with_figures = [i for i, k in enumerate(kinds) if "health" in k]
        assert len(sampled) == len(kinds) // SAMPLE_EVERY
        assert len(with_figures) == len(kinds) // DIAG_EVERY
        feed.remove(client)


class _StuckSocket:
    closed = False

    async def send_str(self, message: str) -> None:
        await asyncio.Event().wait()  # a page that reads nothing: the write never ends


class _Transport:
    aborted = False

    def abort(self) -> None:
        self.aborted = True


class _Request:
    remote = "127.0.0.1"

    def __init__(self) -> None:
        self.transport = _Transport()


async def test_a_stuck_page_is_disconnected_and_the_hub_never_waits(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(feed_module, "SEND_TIMEOUT", 0.2)
    from gateway.web import frontend

    monkeypatch.setattr(frontend, "SEND_TIMEOUT", 0.2)
    async with small_gateway(web_section()) as gw:
        feed = gw.web.feed
        client = feed.add()
        request: Any = _Request()
        writer = asyncio.create_task(gw.web._write(_StuckSocket(), client, request))  # type: ignore[arg-type]
        for i in range(CLIENT_QUEUE * 4):  # the hub goes on, the feed goes on
            gw.hub.update("d1", speed_rpm=float(i), comm=CommState.ONLINE)
            feed.step()
        assert len(client) <= CLIENT_QUEUE
        await asyncio.wait_for(writer, 5.0)
        assert request.transport.aborted and feed.counters.clients_stuck == 1
        feed.remove(client)


def test_a_canopen_line_counts_its_syncs_as_cycles() -> None:
    from gateway.web.views import BUS_FIGURES, figures

    diag = {"sync_period": 0.05, "syncs_tx": 42, "bad_frames": 0, "drives": {}}
    assert figures(diag, BUS_FIGURES)["cycles"] == 42
