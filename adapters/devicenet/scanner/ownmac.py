"""The scanner's defence of its own MAC ID once online: the Duplicate MAC ID requests for it
answered at most once per :data:`ANSWER_EVERY`, the rest counted, reported at most once per
:data:`REPORT_EVERY` with their count. Sans-IO: the caller passes the time.

A device claiming a MAC ID sends a request, waits 1 s for a response, sends a second and
waits 1 s again (fact sheet 2.3); one response to either keeps it off the line. Any two
requests 1 s apart meet an answer when answers go out every 0.5 s, even from a claimant
whose timer runs twice as fast. A station that repeats the request as fast as the line
allows (5,000 took the other lines' drives offline: one answer, one event, one log line
each) gets two answers a second; a request not answered costs a comparison and two
counters (its bytes are kept undecoded for the report).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

ANSWER_EVERY = 0.5  # s: at most one response to the requests for the scanner's MAC this often
REPORT_EVERY = 10.0  # s: at most one report of them this often, with the count


@dataclass(frozen=True, slots=True)
class ClaimReport:
    """What the requests since the last report come to: a text and its figures."""

    text: str
    data: dict[str, Any]


@dataclass(slots=True)
class OwnMacDefence:
    """The requests for the scanner's MAC ``mac`` while it is online."""

    mac: int
    claims: int = 0  # in all
    unanswered: int = 0  # in all
    answered_at: float = -math.inf
    said_at: float = -math.inf
    due_at: float | None = None  # when the requests no report counted yet are to be reported
    last: bytes = b""  # the data bytes of the last request (the claimant)
    _answered: int = 0  # since the last report
    _held: int = 0  # unanswered since the last report

    def claim(self, now: float, data: bytes) -> tuple[bool, bool]:
        """A request for the MAC (its data bytes): whether to answer it, and whether to
        report now (:meth:`report`; else it waits for the next, at :attr:`due_at`)."""
        self.claims += 1
        self.last = data
        if now - self.answered_at >= ANSWER_EVERY:
            self.answered_at = now
            self._answered += 1
            answer = True
        else:
            self.unanswered += 1
            self._held += 1
            answer = False
        if now - self.said_at >= REPORT_EVERY:
            return answer, True
        self.due_at = self.said_at + REPORT_EVERY
        return answer, False

    def report(self, now: float, who: str) -> ClaimReport:
        """The report of the requests since the last one (``who``: the last claimant)."""
        answered, held = self._answered, self._held
        count = answered + held
        self._answered = self._held = 0
        self.said_at, self.due_at = now, None
        text = f"a device ({who}) tried to claim the scanner's MAC ID {self.mac}"
        if count > 1 or held:
            text += (
                f" {count} time(s) since the last such report: {answered} answered, {held} "
                f"not (one answer per {ANSWER_EVERY:g} s defends the MAC ID)"
            )
        return ClaimReport(text, {"claims": count, "answered": answered, "unanswered": held})
