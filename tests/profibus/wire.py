"""The master engine wired to the simulated line in fake time (no I/O, no sleeping).

Each Transmit is confirmed to the master (``Written``, ``write_lag`` after it was due, as a
driver's late callback would) and reaches the simulated slaves when its last byte is on the
line; their replies
come back after ``turnaround`` plus their own transmission time, through the streaming
decoder, as the link would deliver them.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from adapters.link.ringplan import RingResult, RingStop
from adapters.link.stream import SLEEP_LIMIT
from adapters.profibus.codec.fdl import (
    DataTelegram,
    Discarded,
    NeedMore,
    ShortAck,
    TelegramDecoder,
    TokenTelegram,
)
from adapters.profibus.master import (
    Action,
    FrameIn,
    LineNoise,
    Master,
    SlaveParams,
    Transmit,
    Written,
)
from adapters.profibus.master.timing import BusParams
from adapters.profibus.sim.echo import ECHO_IDENT, EchoSim, echo_cfg
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.slave import DpSlave

FAST_BUS = BusParams.for_baudrate(500000, latency=0.001, absent_retry=0.2, fault_retry=0.2)


def echo_params(address: int, size: int = 4, **changes: Any) -> SlaveParams:
    values: dict[str, Any] = {
        "address": address,
        "ident_number": ECHO_IDENT,
        "cfg": echo_cfg(size),
        "input_len": size,
        "output_len": size,
        "watchdog": 0.1,
    }
    values.update(changes)
    return SlaveParams(**values)


def echo_line(addresses: Iterable[int], size: int = 4) -> SimLine:
    return SimLine(DpSlave(a, EchoSim(size)) for a in addresses)


class Wire:
    def __init__(
        self, master: Master, line: SimLine, now: float = 0.0, turnaround: float = 50e-6
    ) -> None:
        self.master = master
        self.line = line
        self.bus = master.bus
        self.now = now
        self.until = now  # where the last run(duration) ended
        self.turnaround = turnaround
        self.decoder = TelegramDecoder()
        self.actions: list[Action] = []
        self.sent: list[tuple[float, bytes]] = []
        self.received: list[tuple[float, bytes]] = []
        self._arrivals: list[tuple[float, int, bytes]] = []
        self._seq = 0
        self._queue: deque[Action] = deque()
        self.drop_replies = 0  # lose the next n replies
        self.late_by = 0.0  # extra delay of every reply
        self.write_lag = 0.0  # how late every write is (the driver's callback run late)
        self.on_action: Callable[[Action], None] | None = None  # the caller, as a driver's
        # a reply read whole (one read, nothing held) is decoded as the driver's FdlStream
        # does, raw bytes kept; with ``lane`` it is offered to Master.lane first
        self.whole = False
        self.lane = False
        self.lane_taken = 0
        # with ``ring`` (and ``lane``), a request of the lane's on the line starts a steady
        # ring (Master.ring_plan), run here in fake time as adapters/link/ring.py runs it
        self.ring = False
        self.ring_taken = 0
        self.ring_closed = 0  # rings that ended with the cycle's Global_Control, written
        self.rings = 0
        self.ring_left_out = 0  # Global_Controls in rings' plans, not due there: not sent

    # ------------------------------------------------------------------ driving

    def settle(self) -> None:
        """Step the deadlines due within the driver's SLEEP_LIMIT, as the driver does inside
        one step (nothing else, a command included, runs between)."""
        while not self._arrivals or self._arrivals[0][0] > self.now + SLEEP_LIMIT:
            deadline = self.master.next_deadline()
            if deadline is None or deadline - self.now > SLEEP_LIMIT:
                return
            if self.master.awaiting_reply():
                return
            self.now = max(self.now, deadline)
            self.line.tick(self.now)
            self._queue.extend(self.master.step(self.now))
            self._drain()

    def poke(self) -> None:
        """Step the master now (after a command)."""
        self._queue.extend(self.master.step(self.now))
        self._drain()

    def run(self, duration: float) -> None:
        """Run ``duration`` s on from where the last run ended when ``now`` is just past it
        (a lane writes its request ahead of the step that would, past a run's end; the
        steps write it when the driver settles): both end their runs at the same times."""
        base = self.until if self.until <= self.now <= self.until + 2 * SLEEP_LIMIT else self.now
        self.until = base + duration
        self.run_until(lambda: False, self.until - self.now)

    def run_until(self, cond: Callable[[], bool], timeout: float = 5.0) -> bool:
        end = self.now + timeout
        self._queue.extend(self.master.step(self.now))
        while True:
            self._drain()
            if self.ring and self.master.awaiting_reply() and not self.decoder.buffered:
                self._ring(end)
            if cond():
                return True
            deadline = self.master.next_deadline()
            times = [t for t in (deadline,) if t is not None]
            if self._arrivals:
                times.append(self._arrivals[0][0])
            if not times or min(times) > end:
                self.now = max(self.now, end)
                self.line.tick(self.now)
                return cond()
            self.now = max(self.now, min(times))
            if self._arrivals and self._arrivals[0][0] <= self.now:
                _, _, data = heapq.heappop(self._arrivals)
                self.received.append((self.now, data))
                if self.whole and not self.decoder.buffered and self._take_whole(data):
                    continue
                self.decoder.feed(data)
                for event in self._events():
                    self._queue.extend(self.master.step(self.now, event))
            else:
                self.line.tick(self.now)
                self._queue.extend(self.master.step(self.now))

    def _take_whole(self, data: bytes) -> bool:
        """A reply read whole, as the driver takes it: the lane first (with ``lane``), else
        decoded whole with its bytes; False: not one whole telegram (fed instead)."""
        if self.lane:
            actions = self.master.lane(data, self.now, SLEEP_LIMIT)
            if actions is not None:
                self.lane_taken += 1
                self._queue.extend(actions)
                return True
        telegram = self.decoder.whole(data)
        if telegram is None:
            return False
        self._queue.extend(self.master.step(self.now, FrameIn(telegram, data)))
        return True

    def _events(self) -> list[FrameIn | LineNoise]:
        out: list[FrameIn | LineNoise] = []
        while True:
            ev = self.decoder.next_frame()
            if isinstance(ev, NeedMore):
                break
            if isinstance(ev, Discarded):
                out.append(LineNoise(ev.error))
            elif isinstance(ev, DataTelegram | ShortAck | TokenTelegram):
                out.append(FrameIn(ev))
        self.decoder.mark_idle()  # a reply arrives whole, as on a quiet line
        tail = self.decoder.next_frame()
        if isinstance(tail, Discarded):
            out.append(LineNoise(tail.error))
        return out

    def _drain(self) -> None:
        while self._queue:
            action = self._queue.popleft()
            if not isinstance(action, Transmit):
                self.actions.append(action)
                if self.on_action is not None:
                    self.on_action(action)
                continue
            self.now = max(self.now, action.not_before) + self.write_lag
            self.sent.append((self.now, action.data))
            self._queue.extend(self.master.step(self.now, Written(self.now)))
            self._to_slaves(action.data)

    def _to_slaves(self, data: bytes) -> None:
        """A request written now reaches the slaves; their replies are on their way."""
        end = self.now + self.bus.tx_time(len(data))
        for out in self.line.receive(data, end):
            if self.drop_replies:
                self.drop_replies -= 1
                continue
            arrive = out.at + self.turnaround + self.late_by + self.bus.tx_time(len(out.data))
            self._seq += 1
            heapq.heappush(self._arrivals, (arrive, self._seq, out.data))

    def _ring(self, end: float) -> None:
        """A steady ring in fake time: each reply taken when it is the one expected and
        came by its deadline, each next request written once the
        line is free; stopped at anything else, which is left as it is (an arrival not
        taken stays for the steps), and at ``end`` (the run's: a command comes after)."""
        plan = self.master.ring_plan(self.now, end)
        if plan is None:
            return
        self.rings += 1
        times: list[float] = []
        idle, deadline, busy = plan.idle_since, plan.deadline, plan.busy_until
        sent_end = idle
        stop = RingStop.END
        gc_due, skipped = plan.gc_due, False
        for i, expected in enumerate(plan.expected):
            if not expected and skipped:  # a broadcast left out (not due): nothing sent
                times.append(math.nan)
                skipped = False
            elif not expected:  # a broadcast: nobody answers, the line free TSYN after it
                busy = max(busy, sent_end + plan.tsyn)
                times.append(sent_end)
            else:
                arrival = self._arrivals[0] if self._arrivals else None
                if arrival is None or arrival[0] > min(deadline, end):
                    stop = RingStop.TIMEOUT
                    break
                at, _, data = arrival
                if data != expected:
                    stop = RingStop.DIFFER
                    break
                heapq.heappop(self._arrivals)
                self.now = at
                self.received.append((at, data))
                times.append(at)
                idle = max(idle, at)
            if i + 1 == len(plan.expected):
                break
            free = max(busy, idle + plan.tsyn)
            if free > plan.horizon:
                stop = RingStop.HORIZON
                break
            self.now = max(self.now, free)
            if not plan.expected[i + 1] and self.now < gc_due:  # not due: the next follows
                times.append(math.nan)
                skipped = True
                self.ring_left_out += 1
                continue
            self.now += self.write_lag
            self.line.tick(self.now)
            request = plan.requests[i]
            if not plan.expected[i + 1]:
                gc_due = self.now + plan.gc_period
            self.sent.append((self.now, request))
            times.append(self.now)
            self._to_slaves(request)
            sent_end = self.now + self.bus.tx_time(len(request))
            idle = max(idle, sent_end)
            deadline = sent_end + self.bus.reply_wait
        result = RingResult(stop, tuple(times), b"", 0.0, idle, -1, 0, 0)
        self.ring_taken += result.taken - result.left_out
        closed = len(times) == 2 * len(plan.expected) - 1 and not plan.expected[-1]
        self.ring_closed += closed
        self._queue.extend(self.master.ring_done(result))

    # ------------------------------------------------------------------ looking

    def of(self, kind: type) -> list[Any]:
        return [a for a in self.actions if isinstance(a, kind)]

    def clear(self) -> None:
        self.actions.clear()
        self.sent.clear()
        self.received.clear()
