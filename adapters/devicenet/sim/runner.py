"""The thin async runner: simulated CFW-08 nodes on one python-can bus.

All nodes share one bus (one Notifier, one reader) and frames are routed by the MAC in
their identifier, so 63 nodes cost one bus, not 63. Nodes are stepped at their own
deadlines from a heap. Runs until cancelled; the link is always closed.
"""

from __future__ import annotations

import asyncio
import heapq
import logging
import time
from collections.abc import Callable, Iterable
from typing import Any

from adapters.can.simulated import until_watched
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import match_predefined
from adapters.devicenet.errors import InvalidCanId
from adapters.devicenet.link import CanLink, LinkConfig, RxFrame
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig

log = logging.getLogger(__name__)

IDLE_WAIT = 1.0  # s: longest wait when no node has a deadline


class SimRunner:
    """Simulated nodes on a python-can bus; control them from the same event loop (another
    loop or thread reads them, waits with :meth:`until`, and pokes them on this one)."""

    def __init__(
        self,
        link: LinkConfig,
        nodes: Iterable[SimNodeConfig],
        *,
        clock: Callable[[], float] = time.monotonic,
        powered: bool = True,
    ) -> None:
        self.link_config = link
        self.nodes: dict[int, Cfw08Node] = {}
        for cfg in nodes:
            if cfg.mac in self.nodes:
                raise ValueError(f"two simulated nodes with MAC ID {cfg.mac} on one runner")
            self.nodes[cfg.mac] = Cfw08Node(cfg)
        self.clock = clock
        self.powered = powered
        self.started = asyncio.Event()
        self.stepped = asyncio.Event()  # set after each pass of the loop (tests wait on it)
        self.watchers: list[Callable[[], None]] = []
        """Called after each pass of the loop, on its loop (:meth:`until` from another)."""
        self._home: asyncio.AbstractEventLoop | None = None  # the loop it runs on
        self.send_failures = 0
        self._link: CanLink | None = None
        self._heap: list[tuple[float, int]] = []
        self._due: dict[int, float] = {}
        self._macs: dict[int, int | None] = {}
        self._stranded: set[int] = set()  # nodes whose new MAC another node here holds

    def node(self, mac: int) -> Cfw08Node:
        return self.nodes[mac]

    def link_figures(self) -> dict[str, Any]:
        """The simulator's own link counters (frames sent and received), while it runs."""
        return {} if self._link is None else self._link.diagnostics()

    async def run(self) -> None:
        self._home = asyncio.get_running_loop()
        async with CanLink(self.link_config) as link:
            self._link = link
            try:
                if self.powered:
                    for mac in self.nodes:
                        self.power_on(mac)
                self.started.set()
                await self._loop(link)
            finally:
                self._link = None

    # ------------------------------------------------------------ control

    def power_on(self, mac: int) -> None:
        node = self.nodes[mac]
        self._send(node.power_on(self.clock()))
        self._schedule(node)

    def power_off(self, mac: int) -> None:
        self.nodes[mac].power_off()
        self._due.pop(mac, None)

    def call(self, mac: int, action: Callable[[Cfw08Node, float], list[CanFrame] | None]) -> None:
        """Do something to a node now (inject a fault, bus-off...) and send what it says."""
        node = self.nodes[mac]
        self._send(action(node, self.clock()) or [])
        self._schedule(node)

    # ------------------------------------------------------------ loop

    async def _loop(self, link: CanLink) -> None:
        while True:
            timeout = self._heap[0][0] - self.clock() if self._heap else IDLE_WAIT
            events = await link.receive(max(0.0, min(timeout, IDLE_WAIT)))
            now = self.clock()
            for event in events:
                if isinstance(event, RxFrame):
                    self._route(now, event.frame)
            self._run_due(now)
            self.stepped.set()
            for watcher in tuple(self.watchers):
                watcher()

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

    def _route(self, now: float, frame: CanFrame) -> None:
        mac = self._macs.get(frame.arbitration_id, -1)
        if mac == -1:
            mac = self._macs[frame.arbitration_id] = _mac_of(frame.arbitration_id)
        node = self.nodes.get(mac) if mac is not None else None
        if node is None:
            return
        self._send(node.step(now, frame))
        self._schedule(node)

    def _run_due(self, now: float) -> None:
        while self._heap and self._heap[0][0] <= now:
            when, mac = heapq.heappop(self._heap)
            if self._due.get(mac) != when:
                continue
            del self._due[mac]
            node = self.nodes[mac]
            self._send(node.step(now))
            self._schedule(node)

    def _rekey(self, node: Cfw08Node) -> None:
        """A node that came back from a reset with another MAC ID (P701) is found by it."""
        if self.nodes.get(node.mac) is node:
            return
        old = next(mac for mac, n in self.nodes.items() if n is node)
        if node.mac in self.nodes:  # a duplicate needs a second runner (its own bus)
            if old not in self._stranded:
                self._stranded.add(old)
                log.warning("simulated MAC %d moved to %d, taken in this runner", old, node.mac)
            return
        del self.nodes[old]
        self._due.pop(old, None)
        self.nodes[node.mac] = node

    def _schedule(self, node: Cfw08Node) -> None:
        self._rekey(node)
        deadline = node.next_deadline()
        if deadline is None:
            self._due.pop(node.mac, None)
            return
        if self._due.get(node.mac) == deadline:
            return
        self._due[node.mac] = deadline
        heapq.heappush(self._heap, (deadline, node.mac))
        if self._link is not None and self._heap[0] == (deadline, node.mac):
            self._link.wake()

    def _send(self, frames: list[CanFrame]) -> None:
        if not frames or self._link is None:
            return
        result = self._link.send(frames)
        if result.error is not None:
            self.send_failures += 1
            log.debug("simulator send failed: %s", result.error)


def _mac_of(arbitration_id: int) -> int | None:
    """The MAC a predefined-set identifier carries, None for any other identifier."""
    try:
        found = match_predefined(arbitration_id)
    except InvalidCanId:
        return None
    return None if found is None else found.mac
