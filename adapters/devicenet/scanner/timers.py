"""Which nodes a timer step has to look at, without a pass over every node.

A steady node (:meth:`NodeMachine.steady`: online, polled, nothing under way but its
polls) has two timers, its inactivity (4 x EPR after its last frame, fact sheet 2.9) and
its explicit keep-alive (half the explicit EPR after its last explicit message); its tick
does nothing before the earlier of the two, its *idle time* (:meth:`NodeMachine.idle_until`).
Both only ever move later while it stays steady: they follow its last frame and its last
explicit message.

So :class:`SteadyTimers` keeps, for the steady nodes, a heap of lower bounds of their
idle times, pushed when a node becomes steady and corrected when it comes to the top
(a lazy timer heap), and the set of the other nodes, which every timer step ticks as
before. On a line of 63 polled nodes a timer step then looks at the one or two nodes due
or busy instead of all 63 twice (their ticks, then their deadlines).

It holds only what the engine tells it: after every tick or frame of a node and every
request submitted to it (:meth:`track`), and a full rebuild after every full pass
(:meth:`rebuild`). What frees a node to go on without touching it (the explicit or
bring-up window freed, a change-of-state output) only asks for a timer step
(:meth:`LineContext.wake`): every node such a change concerns is not steady, and so
ticked. The line's own events (bus errors, send failures, link down), a send hold and
the leave take the full pass, as before (docs/architecture.md, "DeviceNet scanner").
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable

from adapters.devicenet.scanner.node import Node

# stale entries (nodes that left the steady state, or were pushed again) are dropped as
# they come to the top; past this many per node the heap is rebuilt from the live ones
_STALE_FACTOR = 4


class SteadyTimers:
    """The steady nodes' idle times (a lazy heap) and the set of the other nodes."""

    def __init__(
        self,
        nodes: dict[int, Node],
        steady: Callable[[Node], bool],
        idle_time: Callable[[Node], float],
    ) -> None:
        self._nodes = nodes
        self._steady = steady
        self._idle_time = idle_time
        self._order = {mac: i for i, mac in enumerate(nodes)}  # the full pass's order
        self._heap: list[tuple[float, int]] = []
        self._entry: dict[int, float] = {}  # mac -> its live heap entry
        self.unsteady: set[int] = set(nodes)

    def rebuild(self) -> None:
        """From every node (after a full pass)."""
        steady, idle_time = self._steady, self._idle_time
        entry: dict[int, float] = {}
        unsteady: set[int] = set()
        for mac, node in self._nodes.items():
            if steady(node):
                entry[mac] = idle_time(node)
            else:
                unsteady.add(mac)
        self._entry, self.unsteady = entry, unsteady
        self._heap = [(t, mac) for mac, t in entry.items()]
        heapq.heapify(self._heap)

    def track(self, node: Node) -> None:
        """After a node's tick or frame: its place, steady (with its idle time) or not."""
        mac = node.mac
        if self._steady(node):
            self.unsteady.discard(mac)
            t = self._idle_time(node)
            old = self._entry.get(mac)
            if old is None or t < old:  # a later time: the old entry stays a lower bound
                self._entry[mac] = t
                self._push(t, mac)
        else:
            self._entry.pop(mac, None)  # its heap entry is stale from now on
            self.unsteady.add(mac)

    def track_steady(self, node: Node, idle: float) -> None:
        """:meth:`track` for a node known steady, with its idle time (the steady lane)."""
        mac = node.mac
        self.unsteady.discard(mac)
        old = self._entry.get(mac)
        if old is None or idle < old:
            self._entry[mac] = idle
            self._push(idle, mac)

    def due(self, now: float) -> list[Node]:
        """The nodes a timer step at ``now`` ticks, in the full pass's order: every node
        not steady, and the steady ones whose idle time has come (taken off the heap; the
        engine tracks each again after its tick)."""
        macs = set(self.unsteady)
        heap, entry, nodes = self._heap, self._entry, self._nodes
        while heap and heap[0][0] <= now:
            t, mac = heapq.heappop(heap)
            if entry.get(mac) != t:
                continue  # stale
            true = self._idle_time(nodes[mac])
            if true > now:  # moved on since it was pushed
                entry[mac] = true
                heapq.heappush(heap, (true, mac))
                continue
            del entry[mac]
            macs.add(mac)
        order = self._order
        return [nodes[mac] for mac in sorted(macs, key=order.__getitem__)]

    def soonest(self) -> float | None:
        """The earliest idle time of the steady nodes (exact: the top is corrected)."""
        heap, entry, nodes = self._heap, self._entry, self._nodes
        while heap:
            t, mac = heap[0]
            if entry.get(mac) != t:
                heapq.heappop(heap)
                continue
            true = self._idle_time(nodes[mac])
            if true == t:
                return t
            entry[mac] = true
            heapq.heapreplace(heap, (true, mac))
        return None

    def unsteady_nodes(self) -> Iterable[Node]:
        nodes = self._nodes
        return (nodes[mac] for mac in self.unsteady)

    def _push(self, t: float, mac: int) -> None:
        heap = self._heap
        heapq.heappush(heap, (t, mac))
        if len(heap) > _STALE_FACTOR * len(self._nodes) + 16:
            self._heap = [(t, m) for m, t in self._entry.items()]
            heapq.heapify(self._heap)
