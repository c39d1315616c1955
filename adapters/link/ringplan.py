"""What a steady ring is given and what it gives back (docs/decisions/0103): data only,
no I/O, so an engine can plan a ring and enter its result; :mod:`adapters.link.ring` runs
it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

REPLY_MAX: Final = 512  # bytes of a reply at most (an FDL telegram: 255)


class RingStop(IntEnum):
    """Why a ring stopped (the same numbers as ``_ring.c``'s)."""

    END = 0  # every planned exchange done: the last reply taken, the line idle
    DIFFER = 1  # a reply other than expected: ``rest`` holds it, not taken
    TIMEOUT = 2  # no whole reply by the deadline: ``rest`` holds what came
    WAKE = 3  # something else wants the line's loop (a command): nothing read or written
    HORIZON = 4  # the next request would go after the plan's horizon: not written
    BYTES = 5  # bytes in an idle time: left unread for the loop's reader
    PORT = 6  # the port reports an error or a hang-up: left to the loop's reader
    WRITE = 7  # the last request went out short (``partial`` bytes of it) or not at all


@dataclass(frozen=True, slots=True)
class RingPlan:
    """The exchanges of a ring: the first request is on the line, awaited until
    ``deadline``; ``requests[i]`` goes out after ``expected[i]`` was taken."""

    deadline: float  # the reply deadline of the request on the line
    expected: tuple[bytes, ...]  # each exchange's reply, taken only whole and equal (b"":
    # a broadcast, nobody answers: the line is free TSYN after its end; never the first;
    # written only when due, see gc_due)
    requests: tuple[bytes, ...]  # the request after each reply but the last (n - 1)
    tsyn: float  # s the line is idle before a request (from the reply or the request's end)
    reply_wait: float  # s a reply is awaited after a request's own line time
    t_char: float  # s per byte on the line (a request's line time: its length times this)
    idle_since: float  # the line idle since (its last byte, as the engine counts it)
    busy_until: float  # no request before this
    horizon: float  # no request goes out for a time after this
    # a broadcast goes out only when, the line free for it, this time has come, and then
    # is due ``gc_period`` after it went; one not due is left out (its two times NaN)
    gc_due: float = -math.inf
    gc_period: float = 0.0


@dataclass(frozen=True, slots=True)
class RingResult:
    """What a ring did: ``times`` are each taken reply's and each written request's, in
    turn (reply 0, request 1, reply 1, request 2, ...); a broadcast left out (not due) has
    NaN for both of its times."""

    stop: RingStop
    times: tuple[float, ...]
    rest: bytes  # bytes read and not taken (DIFFER, TIMEOUT): for the stream codec
    rest_at: float  # when the last of them was read
    idle_since: float  # the line idle since, as the ring counted it
    partial: int  # WRITE: bytes of the last request written; -1 otherwise
    bytes_in: int
    bytes_out: int
    realtime: int = 0  # 1: run under SCHED_FIFO; 0: not asked; -errno: refused

    @property
    def taken(self) -> int:
        """Exchanges gone through: replies taken, a broadcast counted as one (one left out
        too: the entries of ``times`` go by the plan's exchanges)."""
        return (len(self.times) + 1) // 2

    @property
    def left_out(self) -> int:
        """Broadcasts of the plan not due where the ring came to them, so not sent."""
        return sum(1 for t in self.times if math.isnan(t)) // 2

    @property
    def written(self) -> int:
        """Requests written (the last one short when ``stop`` is WRITE)."""
        return len(self.times) // 2
