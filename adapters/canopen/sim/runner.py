"""The async runner: simulated CiA 402 nodes on one python-can bus through one
canopen ``Network``.

One bus and one notifier thread for all nodes: the network hands every frame to each
node (:meth:`SimNode.on_frame`, under the node's lock); the event loop steps the nodes
at their deadlines and at least every ``tick`` (motor, heartbeat, TPDO timers). Runs
until :meth:`SimRunner.stop` or cancellation; the notifier thread is joined and the
bus shut down on the way out.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable, Iterable
from typing import Any

import can
import canopen

from adapters.can.simulated import until_watched
from adapters.canopen.sim.clock import StillClock
from adapters.canopen.sim.node import SimNode, SimNodeConfig
from adapters.link.can import REFUSED_INTERFACES, CanConfig, open_problem
from gateway.errors import AdapterError

log = logging.getLogger(__name__)

TICK = 0.01  # s: the longest a node goes unstepped (ramps, event-driven TPDOs)
NOTIFIER_TIMEOUT = 0.05  # s: the notifier thread's read timeout (how fast it stops)


class _SimNetwork(canopen.Network):
    """The shared network: a frame goes to the nodes that listen to its COB-ID (a table
    built on demand, dropped whenever a node's PDO configuration changes)."""

    def __init__(self, bus: can.BusABC, runner: SimRunner) -> None:
        super().__init__(bus)
        self.runner = runner
        self._routes: dict[int, list[SimNode]] = {}
        self._routes_lock = threading.Lock()

    def routes_changed(self) -> None:
        with self._routes_lock:
            self._routes = {}

    def _targets(self, can_id: int) -> list[SimNode]:
        with self._routes_lock:
            routes = self._routes
            found = routes.get(can_id)
            if found is None:
                found = [n for n in self.runner.nodes.values() if n.wants(can_id)]
                routes[can_id] = found
            return found

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        for node in self._targets(can_id):
            try:
                node.on_frame(can_id, bytes(data))
            except Exception:  # a broken node must not stop the others
                log.exception("simulated node %d failed on frame 0x%03X", node.node_id, can_id)


class SimRunner:
    """Simulated CiA 402 nodes on ``interface``/``channel``; control them from the loop
    (another loop or thread reads them, waits with :meth:`until`, and pokes them on this one)."""

    def __init__(
        self,
        interface: str,
        channel: str,
        nodes: Iterable[SimNodeConfig],
        *,
        bitrate: int | None = None,
        clock: Callable[[], float] | None = None,
        powered: bool = True,
        tick: float = TICK,
    ) -> None:
        reason = REFUSED_INTERFACES.get(interface)
        if reason is not None:
            raise AdapterError(reason)
        self.interface = interface
        self.channel = channel
        self.bitrate = bitrate
        self.configs: dict[int, SimNodeConfig] = {}
        for cfg in nodes:
            if cfg.node_id in self.configs:
                raise ValueError(f"two simulated CANopen nodes with node id {cfg.node_id}")
            self.configs[cfg.node_id] = cfg
        self.clock: Callable[[], float] = clock or StillClock()
        """The drives' clock (default: one that does not run while the process stands
        still, :mod:`adapters.canopen.sim.clock`)."""
        self.powered = powered
        self.tick = tick
        self.nodes: dict[int, SimNode] = {}
        self.started = asyncio.Event()
        self.stepped = asyncio.Event()  # set after each pass of the loop (tests wait on it)
        self.watchers: list[Callable[[], None]] = []
        """Called after each pass of the loop, on its loop (:meth:`until` from another)."""
        self._home: asyncio.AbstractEventLoop | None = None  # the loop it runs on
        self._stop = asyncio.Event()
        self.network: canopen.Network | None = None

    def node(self, node_id: int) -> SimNode:
        return self.nodes[node_id]

    def stop(self) -> None:
        """End :meth:`run` (it returns after shutting the bus down)."""
        self._stop.set()

    def figures(self) -> dict[int, dict[str, int]]:
        return {
            nid: {"sent": n.sent, "received": n.received, "send_failures": n.send_failures}
            for nid, n in self.nodes.items()
        }

    async def run(self) -> None:
        self._home = asyncio.get_running_loop()
        kwargs: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.bitrate is not None and self.interface not in ("virtual", "socketcan"):
            kwargs["bitrate"] = self.bitrate
        try:
            bus = can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise AdapterError(open_problem(CanConfig(self.interface, self.channel), exc)) from exc
        network = _SimNetwork(bus, self)
        try:
            for cfg in self.configs.values():
                node = SimNode(cfg, network, clock=self.clock)
                node.on_routes_changed = network.routes_changed
                self.nodes[cfg.node_id] = node
            network.notifier = can.Notifier(bus, network.listeners, NOTIFIER_TIMEOUT)
            self.network = network
            if self.powered:
                for node in self.nodes.values():
                    node.power_on()
            self.started.set()
            await self._loop()
        finally:
            self.network = None
            if network.notifier is not None:
                network.notifier.stop(timeout=1.0)
                network.notifier = None
            bus.shutdown()
            network.bus = None

    async def _loop(self) -> None:
        while not self._stop.is_set():
            now = self.clock()
            wake = now + self.tick
            for node in self.nodes.values():
                node.step(now)
                deadline = node.next_deadline()
                if deadline is not None:
                    wake = min(wake, deadline)
            self.stepped.set()
            for watcher in tuple(self.watchers):
                watcher()
            delay = max(0.0, wake - self.clock())
            if delay > 0:
                try:
                    async with asyncio.timeout(delay):
                        await self._stop.wait()
                except TimeoutError:
                    pass
            else:
                await asyncio.sleep(0)

    async def until(self, predicate: Callable[[], bool]) -> None:
        """Wait until ``predicate()`` holds, checking after each pass of the loop; from the
        runner's own loop or from any other (a test beside a daemon's line thread)."""
        loop = asyncio.get_running_loop()
        if self._home is None or self._home is loop:
            while not predicate():
                self.stepped.clear()
                await self.stepped.wait()
            return
        await until_watched(self.watchers, predicate, loop)
