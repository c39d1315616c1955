"""What Modbus TCP clients may hold: connections in all and per peer, time to finish a frame.

Plain data, the admission rule and a sans-IO rate limit for warnings (the caller passes
the clock), used by :mod:`gateway.modbus.server` and :mod:`gateway.modbus.listener`.
"""

from __future__ import annotations

import collections
import enum
from dataclasses import dataclass

EVICT_MIN_IDLE = 5.0  # s: a connection idle this long may make room for a new client
OVER_LIMIT_LOG_INTERVAL = 60.0  # s: at most one WARNING per interval for refusals over a limit


@dataclass(frozen=True, slots=True)
class ConnectionLimits:
    """``modbus.frame_timeout``, ``modbus.max_connections``,
    ``modbus.max_connections_per_peer`` and ``modbus.idle_timeout``."""

    frame_timeout: float  # s from the first byte of a frame to its last
    max_connections: int  # connections open at once (see evict_after)
    idle_timeout: float = 0.0  # s with no complete request before closing; 0: never
    max_per_peer: int = 0  # connections open at once from one address; 0: no limit of its own

    @property
    def evict_after(self) -> float:
        """How long a connection must have been idle to make room for a new client
        at the limit: a client polling more often than this is never evicted."""
        if self.idle_timeout:
            return min(EVICT_MIN_IDLE, self.idle_timeout)
        return EVICT_MIN_IDLE


class Admission(enum.Enum):
    """Whether a new connection fits the limits, given what is open now."""

    ADMIT = "admit"
    PEER_FULL = "peer_full"  # its address holds max_connections_per_peer
    FULL = "full"  # max_connections are open


def admission(limits: ConnectionLimits, open_total: int, open_of_peer: int) -> Admission:
    """The limit a new connection meets (the per-peer one first), or ADMIT."""
    if limits.max_per_peer and open_of_peer >= limits.max_per_peer:
        return Admission.PEER_FULL
    if open_total >= limits.max_connections:
        return Admission.FULL
    return Admission.ADMIT


class PeerCounts:
    """Connections open per peer address (only addresses with at least one)."""

    def __init__(self) -> None:
        self._open: collections.Counter[str] = collections.Counter()

    def of(self, host: str) -> int:
        return self._open[host]

    def add(self, host: str) -> None:
        self._open[host] += 1

    def remove(self, host: str) -> None:
        left = self._open[host] - 1
        if left > 0:
            self._open[host] = left
        else:
            del self._open[host]

    def __len__(self) -> int:
        """Addresses with a connection open."""
        return len(self._open)


class WarningRateLimit:
    """At most one warning per ``interval`` seconds; the ones in between are counted."""

    def __init__(self, interval: float) -> None:
        self.interval = interval
        self._last: float | None = None
        self._held = 0

    def admit(self, now: float) -> int | None:
        """None: hold this one back (log it at DEBUG). Else warn, and the number
        held back since the previous warning is returned (to say so in it)."""
        if self._last is not None and now - self._last < self.interval:
            self._held += 1
            return None
        held, self._held, self._last = self._held, 0, now
        return held
