"""The EMCY budget of a node: how many EMCY frames a second the engine takes from it.

A node sends an EMCY when an error occurs or ends (CiA 301 §7.2.7), its inhibit time
(0x1015) spacing them: a handful at a fault, none in steady operation. CAN carries no
authentication, so any station can send frames with a node's EMCY identifier as fast as the
line allows (2,000 a second took the daemon's loop away for up to 1.9 s, each frame a
``fault`` event and a log line). Each node gets a token bucket (:data:`EMCY_RATE` a second,
:data:`EMCY_BURST` at once); a frame over it is counted (``emcy_dropped``) and not decoded:
its whole cost is a comparison and two counters. The frames dropped are reported at most
once per :data:`EMCY_REPORT_EVERY` per node, with their count.

An EMCY is advisory: the drive's fault state is its statusword (TPDO1), and on entering
fault the engine reads 0x603F and 0x1001 by SDO, so a genuine EMCY dropped in a flood
costs the fault's code only until that read answers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

EMCY_RATE = 5.0  # EMCY frames a second a node may send on and on
EMCY_BURST = 10  # ... and at once (a fault, the errors that follow it, their resets)
EMCY_REPORT_EVERY = 10.0  # s: at most one report per node this often of the frames dropped


@dataclass(slots=True)
class EmcyBudget:
    """One node's token bucket, kept as the time the next frame is due at the steady rate
    (the generic cell rate algorithm: the same frames taken as a bucket of ``burst`` tokens
    refilled at ``rate``, one number to keep)."""

    rate: float = EMCY_RATE
    burst: int = EMCY_BURST
    due: float = -math.inf
    dropped: int = 0  # frames over the budget, in all
    unsaid: int = 0  # of those, the ones no report has counted yet
    said_at: float = -math.inf  # when the last report went out
    _spacing: float = field(init=False, repr=False, default=0.0)  # s between frames, steadily
    _slack: float = field(init=False, repr=False, default=0.0)  # how far ``due`` may run ahead

    def __post_init__(self) -> None:
        if self.rate <= 0 or self.burst < 1:
            raise ValueError(f"EMCY budget {self.rate}/s, burst {self.burst}: both above 0")
        self._spacing = 1.0 / self.rate
        self._slack = (self.burst - 1) * self._spacing

    def take(self, now: float) -> bool:
        """Whether a frame that came at ``now`` is within the budget (then it is taken from
        it); a frame over it is counted."""
        due = self.due
        if due - now > self._slack:
            self.dropped += 1
            self.unsaid += 1
            return False
        self.due = (due if due > now else now) + self._spacing
        return True

    def report_due(self, now: float) -> bool:
        """Frames dropped that no report counted yet, and the last report long enough ago."""
        return self.unsaid > 0 and now - self.said_at >= EMCY_REPORT_EVERY

    def report(self, node_id: int, now: float) -> str:
        """The text of a report of the frames dropped since the last one (counted now)."""
        count, self.unsaid, self.said_at = self.unsaid, 0, now
        return (
            f"node {node_id}: {count} EMCY frame(s) over its budget ({self.rate:g} a second, "
            f"{self.burst} at once) dropped unread; {self.dropped} in all"
        )
