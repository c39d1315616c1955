"""The line as the master holds it: one request outstanding, its timing and its repetition.

Fact sheet 1.1: a request goes out only after the line was idle TSYN, counted from the last
byte written or received; a reply is awaited for the reply wait after the request's own
line time. Every time counts from when a telegram actually went out: the driver confirms
each :class:`Transmit` with :class:`Written` (the planned time is never used), and until it
did nothing else is sent and nothing times out. Which telegram goes next is the
scheduler's business (:mod:`.scheduler`); what a reply means is the station's
(:mod:`.station`) or the job queue's (:mod:`.acyclic`).
"""

from __future__ import annotations

import math
from collections import deque

from adapters.profibus.codec.dp import GlobalControl, global_control_request
from adapters.profibus.errors import DecodeFailure, FdlDecodeError
from adapters.profibus.master.common import Job, Pending
from adapters.profibus.master.events import Action, Purpose, Transmit
from adapters.profibus.master.figures import LineFigures, SlaveFigures
from adapters.profibus.master.timing import BITS_PER_CHAR, MAX_TELEGRAM, BusParams


class Line:
    """The request on the line, the idle time before the next, and what is unconfirmed."""

    def __init__(self, bus: BusParams, figures: LineFigures, out: list[Action], now: float) -> None:
        self.bus = bus
        self.address = bus.master_address
        self.figures = figures
        self.out = out
        self.tsyn = bus.tsyn  # BusParams computes these on every call; each message needs them
        self.reply_wait = bus.reply_wait
        self._t_bit = bus.t_bit  # tx_time's factor (a property computed on every call)
        self.pending: Pending | None = None
        self.retry: Pending | None = None  # timed out, repeated once the line is idle
        self.unwritten: deque[tuple[int, Pending | None]] = deque()  # bytes, request
        self.idle_since = now - bus.tsyn
        self.busy_until = now

    # ------------------------------------------------------------------ when

    def heard(self, now: float) -> None:
        """Bytes on the line (or a request's end) at ``now``: the idle time starts again."""
        self.idle_since = max(self.idle_since, now)

    def awaiting_reply(self) -> bool:
        return self.pending is not None and self.pending.written

    def data_exchange_on_line(self) -> Pending | None:
        """The request on the line when it is a Data_Exchange confirmed written and nothing
        else waits on the line (no write unconfirmed, no repetition): where a steady reply
        may be taken by its bytes (the lane, a steady ring)."""
        p = self.pending
        if (
            p is None
            or not p.written
            or p.purpose is not Purpose.DATA
            or self.unwritten
            or self.retry is not None
        ):
            return None
        return p

    def busy_with(self) -> list[int]:
        """The stations a request is on the line or waiting to be repeated for."""
        return [p.address for p in (self.pending, self.retry) if p is not None]

    # ------------------------------------------------------------------ sending

    def transmit(self, pending: Pending, now: float, fresh: bool = False) -> None:
        not_before = max(now, self.idle_since + self.tsyn)
        if not fresh:
            pending.tries += 1
        pending.sent_at = not_before
        # the reply wait starts when the driver confirms the write (Written), not now
        pending.deadline = math.inf
        pending.written = False
        self.unwritten.append((len(pending.data), pending))
        self.pending = pending
        self.figures.telegrams += 1
        self.out.append(Transmit(pending.data, not_before, True))

    def broadcast(self, control: GlobalControl, now: float) -> None:
        data = global_control_request(control, sa=self.address).encode()
        not_before = max(now, self.idle_since + self.tsyn)
        self.unwritten.append((len(data), None))  # busy until Written + line time + TSYN
        self.figures.telegrams += 1
        self.out.append(Transmit(data, not_before, False))

    def leave(self, now: float) -> list[Transmit]:
        """Global_Control Clear to everyone, twice (SDN is unacknowledged)."""
        self.pending = None
        data = global_control_request(GlobalControl.clear(), sa=self.address).encode()
        busy = self.idle_since  # a telegram not confirmed yet: assume it went out now
        for n, _ in self.unwritten:
            busy = max(busy, now + self.bus.tx_time(n))
        self.unwritten.clear()
        first = max(now, busy + self.tsyn)
        second = first + self.bus.tx_time(len(data)) + self.tsyn
        return [Transmit(data, first, False), Transmit(data, second, False)]

    def reset(self, now: float) -> None:
        """Nothing is outstanding any more (the port was reopened)."""
        self.pending = self.retry = None
        self.unwritten.clear()
        self.idle_since = now - self.tsyn

    def forget_job(self, job: Job) -> None:
        """A reply to a request of ``job`` no longer concerns it (it ended meanwhile)."""
        for p in (self.pending, self.retry):
            if p is not None and p.job is job:
                p.job = None

    # ------------------------------------------------------------------ events

    def on_written(self, at: float) -> None:
        """The oldest unconfirmed telegram was written at ``at``: on the line until its
        line time after that (1.1); a request's reply wait starts there."""
        if not self.unwritten:
            return  # written before a reset: nothing waits for it any more
        n, pending = self.unwritten.popleft()
        end = at + n * BITS_PER_CHAR * self._t_bit  # bus.tx_time(n), as it computes it
        self.idle_since = max(self.idle_since, end)
        if pending is None:  # a broadcast: nobody answers, the line is free TSYN later
            self.busy_until = max(self.busy_until, end + self.tsyn)
        elif pending is self.pending:
            pending.sent_at = at
            pending.deadline = end + self.reply_wait
            pending.written = True

    def receiving(self, now: float) -> None:
        """A telegram is still arriving: its reply wait lasts until it can be complete."""
        if self.pending is not None and self.pending.written:
            bound = now + self.bus.tx_time(MAX_TELEGRAM) + self.bus.latency
            self.pending.deadline = max(self.pending.deadline, bound)

    def garbled(self, now: float) -> None:
        """Noise while a reply is awaited: wait until the line is quiet again, then repeat."""
        pending = self.pending
        if pending is not None and pending.written:
            pending.garbled = True
            pending.deadline = max(pending.deadline, now + self.bus.reply_wait)

    def count_noise(self, error: FdlDecodeError, slave: SlaveFigures | None) -> None:
        """Count undecodable bytes (line level, and for a slave if given)."""
        self.figures.discarded_bytes += len(error.raw)
        counters: list[LineFigures | SlaveFigures] = [self.figures]
        if slave is not None:
            counters.append(slave)
        for c in counters:
            if error.reason is DecodeFailure.BAD_CHECKSUM:
                c.fcs_errors += 1
            else:
                c.framing_errors += 1

    def end_request(self, now: float) -> Pending | None:
        """The request on the line is over at ``now`` (answered, or its wait ran out)."""
        pending, self.pending = self.pending, None
        # never before the end of our own request: a stray reply seen while it was still
        # going out (a late answer, noise) must not shorten the idle time before the next
        self.idle_since = max(self.idle_since, now)
        return pending
