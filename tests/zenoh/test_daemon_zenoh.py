"""The whole daemon in-process with fake drives, and a client session: faults, offline, stop."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path

import pytest_asyncio

from gateway.config import load
from gateway.runtime.daemon import READY_BOUND, Daemon
from gateway.runtime.systemd import Notifier
from tests.support.fake_adapter import FakeAdapter
from tests.support.net import zenoh_endpoint
from tests.zenoh.client import Client
from tests.zenoh.conftest import PREFIX, gateway_config


@dataclass
class Running:
    daemon: Daemon
    task: asyncio.Task[int]
    client: Client
    adapter: FakeAdapter

    async def on_line(self, fn: Callable[[], None]) -> None:
        """``fn()`` run on the fake bus's line (the adapter's own thread and loop)."""
        await self.daemon.runtime.adapters["line1"].call(fn)

    async def stop(self) -> int:
        self.daemon.request_stop()
        return await asyncio.wait_for(self.task, 10)


@pytest_asyncio.fixture
async def running(tmp_path: Path) -> AsyncIterator[Running]:
    """The client listens on 127.0.0.1 and the daemon connects to it as it starts."""
    client_endpoint = zenoh_endpoint()
    client = Client(client_endpoint, asyncio.get_running_loop(), listen=True)
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(gateway_config(connect=client_endpoint))
    daemon = Daemon(
        load(cfg).with_overrides(zenoh_endpoint=zenoh_endpoint()), notifier=Notifier({})
    )
    task = asyncio.create_task(daemon.run())
    try:
        with client.liveliness(f"{PREFIX}/gateway") as live:
            await live.auntil(lambda g: g.put, 10)
        # the buses start once the front ends serve (a start-up failure touches no bus)
        await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + 10)
        await asyncio.wait_for(daemon.hub.wait_for("d1", lambda s: s.online), 10)
        adapter = daemon.runtime.adapters["line1"].adapter
        assert isinstance(adapter, FakeAdapter) and adapter.bus.drives[0].id == "d1"
        yield Running(daemon, task, client, adapter)
    finally:
        if not task.done():
            daemon.request_stop()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(task, 10)
        client.close()


def events_of(drive: str) -> str:
    return f"{PREFIX}/drives/{drive}/events"


async def test_a_fault_arrives_on_events_with_its_text_and_a_reset_clears_it(
    running: Running,
) -> None:
    client = running.client
    with (
        client.subscribe(events_of("d1")) as events,
        client.subscribe(f"{PREFIX}/drives/d1/state") as states,
    ):
        await client.settled(PREFIX)
        adapter = running.adapter
        await running.on_line(lambda: adapter.inject_fault("d1", 42))
        fault = (await events.auntil(lambda e: e.json()["kind"] == "fault")).json()
        assert fault["text"] == "fault 42: test fault 42"
        assert fault["code"] == 42
        state = (await states.auntil(lambda s: s.json()["status"] == "faulted")).json()
        assert (state["fault_code"], state["fault_text"]) == (42, "test fault 42")
        reply = await client.aone(f"{PREFIX}/drives/d1/command", {"fault_reset": True})
        assert reply.json() == {"accepted": True}
        await events.auntil(lambda e: e.json()["text"] == "fault reset sent")
        await events.auntil(lambda e: e.json()["text"] == "fault cleared")
        state = (await states.auntil(lambda s: s.json()["status"] == "ready")).json()
        assert not state["running"]  # a reset never restarts the drive


async def test_a_refused_put_is_an_event(running: Running) -> None:
    client = running.client
    with client.subscribe(events_of("d1")) as events:
        await client.settled(PREFIX)
        client.put(f"{PREFIX}/drives/d1/command", {"run": True, "speed_rpm": 1e6})
        refused = (await events.auntil(lambda e: e.json()["kind"] == "command_refused")).json()
        assert "speed_rpm 1e+06 is beyond the drive's scale" in refused["text"]
        assert refused["source"] == "zenoh"


async def test_drive_tokens_follow_the_bus_and_go_when_the_gateway_stops(running: Running) -> None:
    client = running.client
    with client.liveliness(f"{PREFIX}/**") as live:
        present: set[str] = set()
        while len(present) < 4:
            sample = await live.aget()
            assert sample.put
            present.add(sample.key)
        adapter = running.adapter

        def bus(online: bool) -> None:
            adapter.online = online

        await running.on_line(lambda: bus(False))  # the bus goes quiet: every drive offline
        gone: set[str] = set()
        while len(gone) < 3:
            sample = await live.aget()
            assert not sample.put
            gone.add(sample.key)
        assert gone == {f"{PREFIX}/drives/{d}" for d in ("d1", "d2", "soft")}
        await running.on_line(lambda: bus(True))
        back: set[str] = set()
        while len(back) < 3:
            sample = await live.aget()
            assert sample.put
            back.add(sample.key)
        assert back == gone
        assert await running.stop() == 0
        while present:
            sample = await live.aget()
            assert not sample.put
            present.discard(sample.key)
