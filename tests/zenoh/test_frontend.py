"""The front end in-process on a hub the test drives, with a real client session."""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import pytest_asyncio
import zenoh

from gateway.adapter import Capabilities, EventKind, ParamValue
from gateway.config import Config, ZenohSection
from gateway.errors import ConfigError
from gateway.hub import DrivePolicy, Hub
from gateway.model import CommState, Device, DriveState, Source, SpeedScale
from gateway.runtime.daemon import Runtime
from gateway.zenoh import params as frontend_module
from gateway.zenoh.frontend import ZenohFrontEnd
from tests.support.net import zenoh_endpoint
from tests.zenoh.client import Client

P = "t"
HEARTBEAT = 0.2
N = 5000  # state changes the slow subscriber is sent


class StubParams:
    """A parameter service whose reads never answer."""

    def __init__(self) -> None:
        self.asked = asyncio.Event()

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        self.asked.set()
        await asyncio.Event().wait()
        return 0

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        return None


@dataclass
class Served:
    hub: Hub
    frontend: ZenohFrontEnd
    task: asyncio.Task[None]
    client: Client
    params: StubParams

    async def stop(self) -> None:
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self.task


def make_runtime(endpoint: str, **zenoh: object) -> Runtime:
    hub = Hub()
    hub.add_drive(
        DriveState(id="d1", device=Device.TEST, bus="line1", address=1),
        DrivePolicy(writable_params=frozenset({100})),
    )
    hub.set_capabilities("d1", Capabilities(speed_scale=SpeedScale(1800.0)))
    hub.update("d1", comm=CommState.ONLINE)
    section = ZenohSection(prefix=P, listen=(endpoint,), heartbeat=HEARTBEAT, **zenoh)  # type: ignore[arg-type]
    return Runtime(config=Config(file="test.toml", zenoh=section), hub=hub)


@pytest_asyncio.fixture
async def served() -> AsyncIterator[Served]:
    endpoint = zenoh_endpoint()
    runtime = make_runtime(endpoint)
    params = StubParams()
    runtime.hub.attach_params(["d1"], params)
    fe = ZenohFrontEnd(runtime)
    task = asyncio.create_task(fe.run())
    await asyncio.wait_for(fe.ready.wait(), 10)
    client = Client(endpoint, asyncio.get_running_loop())
    s = Served(runtime.hub, fe, task, client, params)
    try:
        with client.liveliness(f"{P}/gateway") as live:
            await live.auntil(lambda g: g.put, 10)
        yield s
    finally:
        await s.stop()
        client.close()


def small_buffers_config(tmp: Path, endpoint: str) -> Path:
    """A Zenoh config file for the gateway: its endpoint, no scouting, a tiny TCP send buffer."""
    file = tmp / "zenoh.json5"
    doc = {
        "mode": "peer",
        "listen": {"endpoints": [endpoint]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"tcp": {"so_sndbuf": 4096, "so_rcvbuf": 4096}}},
    }
    file.write_text("// the gateway's own Zenoh config (JSON5)\n" + json.dumps(doc))
    return file


async def test_a_slow_subscriber_gets_the_newest_state_and_the_loop_never_waits(
    tmp_path: Path,
) -> None:
    endpoint = zenoh_endpoint()
    runtime = make_runtime(endpoint, config_file=small_buffers_config(tmp_path, endpoint))
    hub = runtime.hub
    fe = ZenohFrontEnd(runtime)
    task = asyncio.create_task(fe.run())
    await asyncio.wait_for(fe.ready.wait(), 10)
    client = Client(endpoint, asyncio.get_running_loop(), rcvbuf=4096)
    gate = threading.Event()
    gave_up: list[bool] = []
    got: list[tuple[float, str]] = []
    newest = asyncio.Event()
    loop = asyncio.get_running_loop()

    def on_state(sample: zenoh.Sample) -> None:  # a subscriber stuck in its callback
        if not gate.wait(30):  # a put that waited on the network held the loop this long
            gave_up.append(True)
            gate.set()
        state = json.loads(sample.payload.to_bytes())
        got.append((state["speed_rpm"], str(sample.congestion_control)))
        if state["speed_rpm"] == N:
            loop.call_soon_threadsafe(newest.set)

    sub = client.session.declare_subscriber(f"{P}/drives/d1/state", on_state)
    try:
        await client.settled(P)
        for i in range(1, N + 1):
            hub.update("d1", speed_rpm=float(i))
            await asyncio.sleep(0)  # the front end puts every change at once
        # the subscriber is still stuck in its first sample: had a put waited for the
        # link to drain, the loop would have been held until the stuck callback gave up
        stuck = list(got)
        gate.set()
        await asyncio.wait_for(newest.wait(), 10)
    finally:
        gate.set()
        sub.undeclare()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        client.close()
    assert stuck == [] and not gave_up
    speeds = [speed for speed, _ in got]
    assert len(speeds) < N / 2  # the link was full: older states were dropped, not queued
    assert speeds == sorted(speeds)  # in order, and the newest ...
    assert got[-1] == (N, "CongestionControl.BLOCK")  # ... came as the last word, with BLOCK


async def test_commands_put_reach_the_hub(served: Served) -> None:
    hub, client = served.hub, served.client
    changed = asyncio.Event()
    hub.on_command(lambda drive_id: changed.set())
    client.put(f"{P}/drives/d1/command", {"run": True, "speed_pct": 50})
    await asyncio.wait_for(changed.wait(), 5)
    desired = hub.desired("d1")
    assert desired.run and desired.speed_pct == 50.0 and desired.source is Source.ZENOH
    reply = await client.aone(f"{P}/drives/d1/command", {})  # a keep-alive
    assert reply.json() == {"accepted": True}


async def test_a_drive_token_follows_its_comm_state(served: Served) -> None:
    hub, client = served.hub, served.client
    with client.liveliness(f"{P}/drives/*") as live:
        assert (await live.aget()).put
        hub.update("d1", comm=CommState.OFFLINE)
        gone = await live.aget()
        assert gone.key == f"{P}/drives/d1" and not gone.put
        hub.update("d1", comm=CommState.CONNECTING)
        hub.update("d1", comm=CommState.ONLINE)
        back = await live.aget()
        assert back.key == f"{P}/drives/d1" and back.put


async def test_events_are_published_in_order(served: Served) -> None:
    hub, client = served.hub, served.client
    with client.subscribe(f"{P}/drives/d1/events") as events:
        await client.settled(P)
        for i in range(200):
            hub.event("d1", EventKind.BUS, f"event {i}", n=i)
        got = [(await events.aget()).json() for _ in range(200)]
    assert [e["n"] for e in got] == list(range(200))
    assert got[0] == {"drive": "d1", "kind": "bus", "text": "event 0", "ts": got[0]["ts"], "n": 0}


async def test_a_parameter_request_that_hangs_gets_an_error_reply(
    served: Served, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(frontend_module, "PARAM_TIMEOUT", 0.2)
    reply = await served.client.aone(f"{P}/drives/d1/params/7")
    assert not reply.ok
    assert reply.json() == {"error": "no answer from drive d1 in 0.2 s"}


async def test_stopping_answers_pending_queries_and_withdraws_every_token(served: Served) -> None:
    client = served.client
    with client.liveliness(f"{P}/**") as live:
        present = {(await live.aget()).key, (await live.aget()).key}
        assert present == {f"{P}/gateway", f"{P}/drives/d1"}
        query = asyncio.ensure_future(client.aquery(f"{P}/drives/d1/params/7"))
        await asyncio.wait_for(served.params.asked.wait(), 5)
        await served.stop()
        replies = await query
        assert [(r.ok, r.json()) for r in replies] == [
            (False, {"error": "the gateway is shutting down"})
        ]
        while present:
            sample = await live.aget()
            assert not sample.put
            present.discard(sample.key)
    assert not served.frontend.worker.thread.is_alive()


async def test_an_endpoint_in_use_fails_the_front_end_cleanly(served: Served) -> None:
    endpoint = served.frontend.section.listen[0]
    second = ZenohFrontEnd(make_runtime(endpoint))
    with pytest.raises(Exception, match=r"(?i)address|bind|in use|listen"):
        await asyncio.wait_for(second.run(), 10)
    assert not second.worker.thread.is_alive()


async def test_a_bad_config_file_fails_before_anything_starts(tmp_path: Path) -> None:
    bad = tmp_path / "zenoh.json5"
    bad.write_text("{ nonsense: true }")
    fe = ZenohFrontEnd(make_runtime(zenoh_endpoint(), config_file=bad))
    with pytest.raises(ConfigError, match="not a Zenoh config"):
        await fe.run()
    assert not fe.worker.thread.is_alive()
