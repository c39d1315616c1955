"""What one Modbus TCP client may hold: connection count and time to finish a frame.

Plain data and a sans-IO rate limit for warnings (the caller passes the clock),
used by :mod:`gateway.modbus.server`.
"""

from __future__ import annotations

from dataclasses import dataclass

EVICT_MIN_IDLE = 5.0  # s: a connection idle this long may make room for a new client
OVER_LIMIT_LOG_INTERVAL = 60.0  # s: at most one WARNING per interval for refusals over the limit


@dataclass(frozen=True, slots=True)
class ConnectionLimits:
    """``modbus.frame_timeout``, ``modbus.max_connections`` and ``modbus.idle_timeout``."""

    frame_timeout: float  # s from the first byte of a frame to its last
    max_connections: int  # connections open at once (see evictable)
    idle_timeout: float = 0.0  # s with no complete request before closing; 0: never

    @property
    def evict_after(self) -> float:
        """How long a connection must have been idle to make room for a new client
        at the limit: a client polling more often than this is never evicted."""
        if self.idle_timeout:
            return min(EVICT_MIN_IDLE, self.idle_timeout)
        return EVICT_MIN_IDLE


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
