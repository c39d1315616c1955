"""The simulator rig: a :class:`SimRunner` on a python-can ``virtual`` channel of its own and
the canopen library's own client (``RemoteNode``) on the same channel. The client's calls
block, so they run on a one-thread pool the rig shuts down."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import uuid
from collections.abc import AsyncIterator, Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

import can
import canopen
import pytest

from adapters.canopen.sim import SimNodeConfig, SimRunner
from tests.support.timing import scaled

ROOT = Path(__file__).resolve().parents[3]
EDS = ROOT / "config" / "eds" / "cia402-drive.eds"
T = TypeVar("T")


class Client:
    """The canopen library as a master on the rig's channel, with a frame recorder."""

    def __init__(
        self, channel: str, runner: SimRunner | None = None, interface: str = "virtual"
    ) -> None:
        self.runner = runner
        self.loop = asyncio.get_running_loop()
        self.changed = asyncio.Event()
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.05
        self.network.NOTIFIER_SHUTDOWN_TIMEOUT = 2.0
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="canopen-client")
        self.frames: list[tuple[int, bytes]] = []
        self._lock = threading.Lock()
        self.network.listeners.append(_Recorder(self))
        self.network.connect(interface=interface, channel=channel)
        self.nodes: dict[int, canopen.RemoteNode] = {}

    def remote(self, node_id: int) -> canopen.RemoteNode:
        if node_id not in self.nodes:
            node = canopen.RemoteNode(node_id, str(EDS))
            node.sdo.RESPONSE_TIMEOUT = scaled(0.3)
            self.network.add_node(node)
            self.nodes[node_id] = node
        return self.nodes[node_id]

    async def call(self, fn: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(self.pool, fn, *args)

    def seen(self, can_id: int) -> list[bytes]:
        with self._lock:
            return [data for cid, data in self.frames if cid == can_id]

    def clear(self) -> None:
        with self._lock:
            self.frames.clear()

    async def until(self, predicate: Callable[[], bool], seconds: float = 2.0) -> None:
        """Wait until ``predicate()`` holds, checked on every frame in and, with a runner
        in this process, after every pass of its loop."""
        async with asyncio.timeout(scaled(seconds)):
            if self.runner is not None:
                await self.runner.until(predicate)
                return
            while not predicate():
                self.changed.clear()
                await self.changed.wait()

    def send(self, can_id: int, data: bytes) -> None:
        self.network.send_message(can_id, data)

    def close(self) -> None:
        self.pool.shutdown(wait=True)
        self.network.disconnect()


class _Recorder(canopen.network.MessageListener):
    def __init__(self, client: Client) -> None:
        super().__init__(client.network)
        self.client = client

    def on_message_received(self, msg: can.Message) -> None:
        with self.client._lock:
            self.client.frames.append((msg.arbitration_id, bytes(msg.data)))
        with contextlib.suppress(RuntimeError):  # the loop may be closing
            self.client.loop.call_soon_threadsafe(self.client.changed.set)


class Rig:
    def __init__(self, runner: SimRunner, client: Client) -> None:
        self.runner = runner
        self.client = client


@pytest.fixture
def sim_nodes() -> list[SimNodeConfig]:
    return [SimNodeConfig(5, heartbeat_ms=50, ramp_time=1.0)]


@pytest.fixture
async def rig(sim_nodes: list[SimNodeConfig]) -> AsyncIterator[Rig]:
    channel = f"canopen-sim-{uuid.uuid4().hex[:8]}"
    runner = SimRunner("virtual", channel, sim_nodes)
    # the client first: it must hear the boot-up
    client = Client(channel, runner)
    task = asyncio.create_task(runner.run(), name="canopen-sim")
    try:
        async with asyncio.timeout(scaled(5.0)):
            await runner.started.wait()
        yield Rig(runner, client)
    finally:
        client.close()
        runner.stop()
        await task
