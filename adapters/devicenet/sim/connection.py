"""A Connection object instance of the simulated CFW-08 (fact sheet 2.9; seed tables 12-14)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from adapters.devicenet.cfw08.objects import Value
from adapters.devicenet.codec.objects import (
    INACTIVITY_EPR_FACTOR,
    ConnectionInstance,
    ConnectionState,
    ConnectionType,
    WatchdogAction,
)

EXPLICIT_EPR_MS = 2500  # fact sheet 2.9: the explicit connection starts with EPR 2500 ms
EXPLICIT_SIZE = 0xFFFF  # decision: no fixed size for the explicit connection


class IoTrigger(Enum):
    POLL = "poll"
    COS = "cos"
    CYCLIC = "cyclic"


@dataclass(slots=True)
class SimConnection:
    instance: int
    clock: Callable[[], float]
    produced_id: int = 0
    consumed_id: int = 0
    produced_size: int = 0
    consumed_size: int = 0
    produced_path: bytes = b""
    consumed_path: bytes = b""
    state: ConnectionState = ConnectionState.NON_EXISTENT
    epr_ms: int = 0
    inhibit_ms: int = 0
    epr_tick_ms: int = 10
    last_consumed: float = 0.0
    trigger: IoTrigger = IoTrigger.POLL
    acknowledged: bool = True

    @property
    def is_explicit(self) -> bool:
        return self.instance == ConnectionInstance.EXPLICIT

    @property
    def established(self) -> bool:
        return self.state is ConnectionState.ESTABLISHED

    def open(self, now: float, trigger: IoTrigger = IoTrigger.POLL, ack: bool = True) -> None:
        """Allocated: explicit is established at once, I/O waits for its EPR (fact sheet 2.9)."""
        self.trigger, self.acknowledged = trigger, ack
        self.last_consumed = now
        if self.is_explicit:
            self.state, self.epr_ms = ConnectionState.ESTABLISHED, EXPLICIT_EPR_MS
        else:
            self.state, self.epr_ms = ConnectionState.CONFIGURING, 0

    def close(self) -> None:
        self.state, self.epr_ms = ConnectionState.NON_EXISTENT, 0

    def consumed(self, now: float) -> None:
        """Each message the connection consumes restarts its inactivity timer (2.9)."""
        self.last_consumed = now

    def inactivity_deadline(self) -> float | None:
        if not self.established or self.epr_ms <= 0:
            return None
        return self.last_consumed + INACTIVITY_EPR_FACTOR * self.epr_ms / 1000.0

    def time_out(self) -> None:
        """Explicit: auto delete; I/O: timed out (fact sheet 2.9 watchdog actions)."""
        if self.is_explicit:
            self.close()
        else:
            self.state = ConnectionState.TIMED_OUT

    # ------------------------------------------------------------ the server's view

    def set_epr(self, ms: int) -> int | None:
        """Set attribute 9: rounded up to the node's tick and returned (fact sheet 2.9 [JB])."""
        if self.state is ConnectionState.NON_EXISTENT:
            return None
        tick = max(self.epr_tick_ms, 1)
        used = min(math.ceil(ms / tick) * tick, 0xFFFF)
        self.epr_ms = used
        self.last_consumed = self.clock()
        if self.state in (ConnectionState.CONFIGURING, ConnectionState.TIMED_OUT):
            self.state = ConnectionState.ESTABLISHED
        return used

    def set_inhibit(self, ms: int) -> bool:
        if self.state is ConnectionState.NON_EXISTENT:
            return False
        self.inhibit_ms = ms
        return True

    def attribute(self, attribute: int) -> Value:
        watchdog = WatchdogAction.AUTO_DELETE if self.is_explicit else WatchdogAction.TIME_OUT
        values: dict[int, Value] = {
            1: int(self.state),
            2: int(ConnectionType.EXPLICIT if self.is_explicit else ConnectionType.IO),
            3: _TRIGGER[(self.is_explicit, self.trigger)],
            4: self.produced_id,
            5: self.consumed_id,
            6: 0x21 if self.is_explicit else 0x01,  # simulator constants
            7: self.produced_size,
            8: self.consumed_size,
            9: self.epr_ms,
            12: int(watchdog),
            13: len(self.produced_path),
            14: self.produced_path,
            15: len(self.consumed_path),
            16: self.consumed_path,
            17: self.inhibit_ms,
        }
        return values[attribute]


# Transport class / trigger (attribute 3): explicit 0x83 and poll 0x82 as fact sheet 2.9;
# COS 0x12 and cyclic 0x02 are simulator constants (the scanner does not read them).
_TRIGGER: dict[tuple[bool, IoTrigger], int] = {
    (True, IoTrigger.POLL): 0x83,
    (True, IoTrigger.COS): 0x83,
    (True, IoTrigger.CYCLIC): 0x83,
    (False, IoTrigger.POLL): 0x82,
    (False, IoTrigger.COS): 0x12,
    (False, IoTrigger.CYCLIC): 0x02,
}
