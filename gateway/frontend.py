"""What a front end sees of the running gateway, and what it reports back.

The composition root (gateway/runtime/daemon.py) makes each front end (gateway/zenoh,
gateway/modbus, gateway/web) with a :class:`RuntimeView`: the configuration, the hub, the
adapters' diagnostics and the gateway's health, read-only. The front ends import this
module, never the composition root nor each other. Each is a :class:`FrontEnd`: it serves
until cancelled and reports its :class:`FrontEndCounters`, which ``/metrics`` reads at
scrape time (gateway/web/metrics.py): typed fields, so a counter renamed in a front end is
a type error, never a metric silently at zero.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from gateway.access.audit import AuditTrail
from gateway.config import Config
from gateway.history.store import HistoryStore
from gateway.hub import Hub


@dataclass(frozen=True, slots=True)
class FrontEndCounters:
    """What a front end has counted since it started (0, or empty, for what it does not
    count)."""

    requests: Mapping[str, int] = field(default_factory=dict)
    """Requests taken, by kind (Modbus: ``request``; Zenoh: ``put``, ``query``)."""
    exceptions: int = 0
    """Requests answered with an error (Modbus exception responses)."""
    dropped: int = 0
    """Requests dropped unanswered (Zenoh: the hand-over to the loop was full)."""
    refused: Mapping[str, int] = field(default_factory=dict)
    """Requests refused, by reason (web: allow, origin, token, commands_off)."""
    commands_accepted: int = 0
    commands_refused: int = 0
    connections_accepted: int = 0
    connections_refused: int = 0
    """Connections refused at accept: the peer is not allowed."""
    connections_over_limit: int = 0
    """Connections closed at accept: the front end's limit of open connections was reached."""
    connections_open: int = 0
    """Connected now (Modbus connections, web pages)."""
    accept_failures: int = 0
    """Accepts that failed (no descriptor left): the connection waits in the kernel."""


class FrontEnd(Protocol):
    """A front end, as the composition root runs it and ``/metrics`` reads it."""

    async def run(self) -> None:
        """Serve until cancelled."""
        ...

    def counted(self) -> FrontEndCounters:
        """Its counters as they are now."""
        ...


class BusView(Protocol):
    """What a front end may see of a running line: its name and its figures."""

    name: str

    def diagnostics(self) -> dict[str, Any]:
        """Bus figures: line-level keys, and per drive under ``"drives"``."""
        ...


class RuntimeView(Protocol):
    """What a front end may see of the running gateway."""

    @property
    def config(self) -> Config: ...

    @property
    def hub(self) -> Hub: ...

    @property
    def version(self) -> str: ...

    @property
    def started(self) -> float:
        """``time.monotonic()`` when the gateway started."""
        ...

    @property
    def adapters(self) -> Mapping[str, BusView]:
        """The running line of each bus, by bus name."""
        ...

    @property
    def restarts(self) -> Mapping[str, int]:
        """How often each supervised part was restarted (``"bus <name>"``, ...)."""
        ...

    @property
    def front_ends(self) -> Mapping[str, FrontEnd]:
        """The running instance of each front end, by name (the web's metrics read them)."""
        ...

    @property
    def history(self) -> HistoryStore | None:
        """The history's queries (``[history]`` on), else None (gateway/history/store.py)."""
        ...

    @property
    def audit(self) -> AuditTrail:
        """Where the front end records its access decisions (gateway/access/audit.py)."""
        ...

    def bus_of(self, drive_id: str) -> str: ...

    def drive_diagnostics(self, drive_id: str) -> dict[str, Any]:
        """One drive's figures from its bus's diagnostics."""
        ...

    def health(self) -> dict[str, Any]:
        """The gateway's health: name, version, uptime, drives, buses."""
        ...
