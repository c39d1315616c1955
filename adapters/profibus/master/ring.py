"""The master's steady ring: the next steady exchanges planned as bytes, and the master
brought up to date once they ran (adapters/link/ring.py runs them; docs/decisions/
0103-steady-ring.md).

A ring starts where the steady lane leaves the line (:meth:`Master.lane`): a slave's
Data_Exchange on the line, its caller quiet. It goes on through the slaves that follow
while each is in data exchange, its caller quiet, no diagnosis waiting and its last plain
reply known, and stops before the first that is not, at :data:`RING_MAX` exchanges, and
where no more could go before its horizon at the line's pace. At the cycle's end it goes
on into the next cycle where nothing but the periodic Global_Control can be sent at the
cycle's end (:class:`_Wraps`); the ring writes that one there only if it is due when the
line is free for it, as the scheduler would (docs/decisions/0110), else the next cycle's
first request follows at once. Where it cannot go on (a cycle time not over),
it ends with the cycle's Global_Control when that is due already. Nothing else may wait:
no DP-V1 job, no slave in start-up, no repetition.

Afterwards each exchange the ring did is entered as the general path enters a steady
reply, with the times it really happened: the reply's turn ends (response time, FCB,
exchanges; its unchanged inputs reported if their refresh was due by then: a steady
reply's inputs are the last ones reported), the broadcast where it went (none where it
was not due) and the cycle's end and begin as the scheduler makes them, the next slave's
turn begins with its Data_Exchange (the scheduler's own ``send_for``) and each write is
confirmed (the line's ``on_written``).
The counters and telegrams are those of the lane and of the general path: a property test
runs all three on the same lines.
"""

from __future__ import annotations

import math
from typing import Final

from adapters.link.ringplan import REPLY_MAX, RingPlan, RingResult
from adapters.profibus.codec.fdl import RequestFunction
from adapters.profibus.errors import SteadyRingError
from adapters.profibus.master.events import Action, LineMode, Purpose, SlaveState, Transmit
from adapters.profibus.master.line import Line
from adapters.profibus.master.scheduler import Scheduler
from adapters.profibus.master.station import Station
from adapters.profibus.master.timing import BITS_PER_CHAR

RING_MAX: Final = 128  # exchanges in one ring at most (a cycle of 125 slaves in one)
RING_PACE: Final = 0.8  # of the measured line time per Data_Exchange: a ring's plan length


def steady(sl: Station) -> bool:
    """Whether ``sl``'s plain reply can be taken by its bytes (the lane's test, less the
    reply itself and the time, which the ring checks)."""
    return (
        sl.quiet
        and not sl.diag_pending
        and 0 < len(sl.steady_reply) <= REPLY_MAX
        and sl.last_inputs is not None
        and sl.state is SlaveState.DATA_EXCHANGE
    )


class SteadyRing:
    """Plans a ring from the line's state and enters what it did (see the module doc)."""

    def __init__(
        self, line: Line, stations: dict[int, Station], scheduler: Scheduler, out: list[Action]
    ) -> None:
        self.line = line
        self.stations = stations
        self.scheduler = scheduler
        self.out = out
        self.chain: list[Station | None] = []  # the last plan's, in order (None: broadcast)
        self.wraps = 0  # plans that went on into the next cycle
        self.crossed = 0  # cycles begun within a ring

    def plan(self, now: float, horizon: float) -> RingPlan | None:
        """The ring from the Data_Exchange on the line, or None (nothing to gain: fewer
        than two exchanges, or the line is not in the steady case)."""
        line = self.line
        p = line.data_exchange_on_line()
        if p is None:
            return None
        first = self.stations[p.address]
        if not steady(first):
            return None
        chain: list[Station | None] = [first]
        expected = [first.steady_reply]
        requests: list[bytes] = []
        fcb = {first.address: first.fcb.acknowledged()}  # each slave's next FCB in the ring
        operate = self.scheduler.mode is LineMode.OPERATE
        queue = list(self.scheduler.queue)
        wraps = _Wraps(self.scheduler, now, horizon)
        # when each next telegram may go, no later than the line's own figures say (its line
        # time, the reply's, TSYN; RING_PACE of a Data_Exchange's measured line time): none
        # is planned that could not go before the horizon
        t_char, tsyn = BITS_PER_CHAR * line.bus.t_bit, line.tsyn
        pace = RING_PACE * self.scheduler.dx_each
        earliest = now + len(first.steady_reply) * t_char + tsyn
        while len(chain) < RING_MAX and earliest <= wraps.horizon:
            if not queue:  # the cycle's end: the ring goes on into the next cycle
                end = wraps.next()
                if end is None:  # it stops there, with the Global_Control if it is due
                    closing = wraps.closing()
                    if closing is not None:
                        chain.append(None)
                        expected.append(b"")
                        requests.append(closing)
                    break
                for broadcast in end:  # its Global_Control: no reply
                    chain.append(None)
                    expected.append(b"")
                    requests.append(broadcast)
                    earliest += len(broadcast) * t_char + tsyn
                queue = list(self.stations)
                continue
            sl = self.stations[queue.pop(0)]
            if not steady(sl):
                break
            state = fcb.get(sl.address, sl.fcb)
            fcb[sl.address] = state.acknowledged()
            request = sl.frame_for(state.fc(RequestFunction.SRD_HIGH), operate)
            chain.append(sl)
            expected.append(sl.steady_reply)
            requests.append(request)
            earliest += max((len(request) + len(sl.steady_reply)) * t_char + tsyn, pace)
        while chain[-1] is None and not wraps.closed:  # a broadcast ends only a cycle
            chain.pop()
            expected.pop()
            requests.pop()
        if len(chain) < 2:
            return None
        self.chain = chain
        self.wraps += wraps.count
        return RingPlan(
            deadline=p.deadline,
            expected=tuple(expected),
            requests=tuple(requests),
            tsyn=line.tsyn,
            reply_wait=line.reply_wait,
            t_char=t_char,
            idle_since=line.idle_since,
            busy_until=line.busy_until,
            horizon=wraps.horizon,
            gc_due=wraps.gc_due,
            gc_period=self.scheduler.bus.global_control_period,
        )

    def enter(self, result: RingResult) -> bool:
        """Enter what the ring of the last plan did; True when the line is free after its
        last reply (the next turn is the steady one, as after the lane's)."""
        line, chain = self.line, self.chain
        times = result.times
        marked = len(self.out)
        for j in range(result.taken):
            sl = chain[j]
            if sl is not None:  # (None: the broadcast, answered by nobody)
                now = times[2 * j]
                p = line.pending
                if p is None or p.address != sl.address:
                    raise SteadyRingError(f"a ring's reply {j} is not slave {sl.address}'s")
                line.pending = None
                line.idle_since = max(line.idle_since, now)
                sl.answered(p, now)
                sl.took_same_inputs(now)
            if 2 * j + 1 < len(times) and not math.isnan(times[2 * j + 1]):
                self._sent(chain[j + 1], times[2 * j + 1])  # the next request went out
                # (NaN: a Global_Control not due there, left out: the next cycle's first
                # request follows, and begins that cycle as the scheduler does)
        # send_for's Transmit actions: the ring wrote them (the inputs reported stay)
        self.out[marked:] = [a for a in self.out[marked:] if type(a) is not Transmit]
        self.chain = []
        return result.taken > 0 and line.pending is None

    def _sent(self, sl: Station | None, at: float) -> None:
        """The ring wrote the next telegram at ``at``: entered as the scheduler sends it."""
        scheduler = self.scheduler
        if sl is None:
            scheduler.ended_with_broadcast(at)
        else:
            if not scheduler.queue:  # the next cycle's first
                scheduler.next_cycle_now(at)
                self.crossed += 1
            scheduler.send_for(scheduler.start_turn(), Purpose.DATA, at)
        self.line.on_written(at)


class _Wraps:
    """Whether a ring can go on into the next cycle, and what the cycle's end sends there.
    Each end has the periodic Global_Control in the plan, and the ring writes it there only
    when it is due once the line is free for it, as the scheduler decides at that time
    (:class:`RingPlan` ``gc_due``, docs/decisions/0110); the ring's horizon ends before a
    live-list probe is due. A Sync or Freeze queued, or a cycle time not over, ends the
    ring at the cycle's end (with a cycle time, a second end is never certain); the ring
    then ends with the end's Global_Control when that is certain (:meth:`closing`)."""

    def __init__(self, scheduler: Scheduler, now: float, horizon: float) -> None:
        self.scheduler = scheduler
        self.now = now
        self.horizon = horizon
        self.count = 0
        self.closed = False  # the ring ends with the cycle's Global_Control (closing)
        self.queued, self.gc_due, self.probe_due = scheduler.line_tasks_due()

    def closing(self) -> bytes | None:
        """Where the ring stops at the cycle's end: the Global_Control the end sends first
        when it is certain, i.e. due already and no Sync or Freeze queued before it (the
        ring's last telegram: the line is the engine's again after it, for a live-list
        probe or the next cycle's start, as :meth:`Scheduler.send_next` makes them)."""
        if self.queued or self.scheduler.cycle_started is None or self.gc_due > self.now:
            return None
        self.closed = True
        return self.scheduler.broadcast_frame()

    def next(self) -> tuple[bytes, ...] | None:
        """The cycle's end: (the Global_Control,), written there only if it is due then
        (the ring decides, as the scheduler would: :class:`RingPlan` ``gc_due``), or None
        (the ring stops there)."""
        scheduler = self.scheduler
        started = scheduler.cycle_started
        cycle_time = scheduler.bus.cycle_time
        if self.queued or started is None or (self.count and cycle_time > 0):
            return None
        if not self.count and started + cycle_time > self.now:
            return None
        self.count += 1
        self.horizon = min(self.horizon, self.probe_due - _BEFORE)
        return (scheduler.broadcast_frame(),)


_BEFORE: Final = 1e-9  # s: a horizon before a due time is strictly before it
