"""The push feed: what every open page receives, and how a slow page is kept from
holding anything up.

Every :data:`PUSH_PERIOD` the front end calls :meth:`Feed.step`: it takes what changed
since the last step from the hub's own conflating state subscription (the newest state of
each drive that changed) and from its event subscription, adds a trend sample every
:data:`SAMPLE_EVERY` steps and the bus figures every :data:`DIAG_EVERY` steps, and encodes
one message, once, for every client. So a drive's row reaches a page at most
``1 / PUSH_PERIOD`` times a second whatever its bus does, and the cost of a client is a
queue append and a socket write.

Each client has a :class:`ClientQueue` of at most :data:`CLIENT_QUEUE` messages. A client
that falls that far behind loses what waits (counted) and gets one fresh snapshot when it
next reads: the latest state wins, nothing piles up. A snapshot is built once per step,
when the first client asks for it, and shared by every client that asks before the next
step (each one gets what changed after it in the next step's message), so many pages
connecting at once cost one snapshot. Its writer gives a message at most
:data:`SEND_TIMEOUT` seconds; a client still stuck then is disconnected. Nothing here ever
waits for a client: the hub's subscriptions are drained by the step, on the loop, at the
step's own pace.
"""

from __future__ import annotations

import asyncio
import collections
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import orjson

from gateway.adapter import Event
from gateway.frontend import RuntimeView
from gateway.hub import EventSubscription, StateSubscription
from gateway.web.history import TrendHistory
from gateway.web.views import bus_diagnostics, buses_json, drive_row, health_json

PUSH_PERIOD = 0.25  # s between pushes: at most 4 updates per second per drive
SAMPLE_EVERY = 2  # pushes per trend sample (SAMPLE_PERIOD = 0.5 s, 2 Hz)
DIAG_EVERY = 4  # pushes per bus figures and health (1 Hz)
CLIENT_QUEUE = 8  # messages waiting for one client (2 s of pushes); one more: resync
SEND_TIMEOUT = 10.0  # s one message may take to reach a client before it is disconnected
EVENTS_KEPT = 100  # the last events a new page is shown


@dataclass
class FeedCounters:
    messages: int = 0  # update messages made (each one sent to every client)
    dropped: int = 0  # messages a slow client lost (replaced by a snapshot)
    snapshots: int = 0  # snapshots sent: one per new client, one per resync
    clients_connected: int = 0
    clients_stuck: int = 0  # disconnected: a message took longer than SEND_TIMEOUT


class ClientQueue:
    """The messages waiting for one client, bounded (see the module docstring)."""

    def __init__(self, counters: FeedCounters, limit: int = CLIENT_QUEUE) -> None:
        self._counters = counters
        self._limit = limit
        self._queue: collections.deque[str] = collections.deque()
        self._ready = asyncio.Event()
        self.resync = True  # a new client starts with a snapshot

    def offer(self, message: str) -> None:
        if self.resync:  # the snapshot it will get covers this message
            self._counters.dropped += 1
            return
        if len(self._queue) >= self._limit:
            self._counters.dropped += len(self._queue) + 1
            self._queue.clear()
            self.resync = True
        else:
            self._queue.append(message)
        self._ready.set()

    def __len__(self) -> int:
        return len(self._queue)

    async def next(self, snapshot: Callable[[], str]) -> str:
        """The next message to send: a snapshot made now if it fell behind."""
        while not self._queue and not self.resync:
            self._ready.clear()
            await self._ready.wait()
        if self.resync:
            self.resync = False
            self._queue.clear()
            return snapshot()
        return self._queue.popleft()


def _dumps(message: dict[str, Any]) -> str:
    return orjson.dumps(message).decode()


class Feed:
    """The trend history and the push messages of one web front end."""

    def __init__(
        self,
        runtime: RuntimeView,
        history: TrendHistory | None = None,
        clock: Callable[[], float] = time.time,
        commands: bool = False,
    ) -> None:
        self.runtime = runtime
        self.hub = runtime.hub
        self.history = history or TrendHistory()
        self.clock = clock
        self.commands = commands
        self.counters = FeedCounters()
        self.events: collections.deque[dict[str, Any]] = collections.deque(maxlen=EVENTS_KEPT)
        self.clients: set[ClientQueue] = set()
        self._steps = 0
        self._states: StateSubscription | None = None
        self._events: EventSubscription | None = None
        self._buses: list[dict[str, Any]] = []
        self._health: dict[str, Any] = {}
        self._snapshot: str | None = None  # built since the last step

    # ------------------------------------------------------------ life cycle

    def open(self) -> None:
        self._states = self.hub.subscribe_states()
        self._events = self.hub.subscribe_events()

    def close(self) -> None:
        for sub in (self._states, self._events):
            if sub is not None:
                sub.close()
        self._states = self._events = None

    def add(self) -> ClientQueue:
        client = ClientQueue(self.counters)
        self.clients.add(client)
        self.counters.clients_connected += 1
        return client

    def remove(self, client: ClientQueue) -> None:
        self.clients.discard(client)

    # ------------------------------------------------------------ the step

    def _refresh_diag(self) -> None:
        self._buses = buses_json(self.runtime, bus_diagnostics(self.runtime))
        self._health = health_json(self.runtime)

    def _take_events(self) -> list[dict[str, Any]]:
        taken: list[Event] = self._events.drain() if self._events is not None else []
        out = [e.to_json() for e in taken]
        self.events.extend(out)
        return out

    def step(self) -> str | None:
        """One push: the message made for every client (None when there is none to send)."""
        self._steps += 1
        self._snapshot = None
        now = self.clock()
        changed = self._states.drain() if self._states is not None else []
        events = self._take_events()
        message: dict[str, Any] = {"type": "update", "now": round(now, 3)}
        if self._steps % SAMPLE_EVERY == 0:
            message["points"] = self.history.sample(now, self.hub.states())
        if not self.clients:
            return None
        if self._steps % DIAG_EVERY == 0:
            self._refresh_diag()
            message["buses"] = self._buses
            message["health"] = self._health
        if changed:
            message["drives"] = [drive_row(self.runtime, s) for s in changed]
        if events:
            message["events"] = events
        if len(message) == 2:
            return None
        text = _dumps(message)
        self.counters.messages += 1
        for client in self.clients:
            client.offer(text)
        return text

    def snapshot(self) -> str:
        """Everything a page shows, as of the last step or later (its trend comes from
        ``/api/history``): built once per step, shared until the next."""
        if self._snapshot is None:
            self._snapshot = self._build_snapshot()
        self.counters.snapshots += 1
        return self._snapshot

    def _build_snapshot(self) -> str:
        runtime = self.runtime
        self._refresh_diag()
        message = {
            "type": "snapshot",
            "now": round(self.clock(), 3),
            "gateway": {
                "name": runtime.config.gateway.name,
                "version": runtime.version,
                "commands": self.commands,
            },
            "trend": {"period": self.history.period, "span": self.history.span},
            "drives": [drive_row(runtime, s) for s in self.hub.states()],
            "events": list(self.events),
            "buses": self._buses,
            "health": self._health,
        }
        return _dumps(message)
