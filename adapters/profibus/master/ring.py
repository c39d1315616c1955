"""The master's steady ring: the cycle's next steady exchanges planned as bytes, and the
master brought up to date once they ran (adapters/link/ring.py runs them; docs/decisions/
0103-steady-ring.md).

A ring starts where the steady lane leaves the line (:meth:`Master.lane`): a slave's
Data_Exchange on the line, its caller quiet. It goes on through the slaves that follow in
the cycle while each is in data exchange, its caller quiet, no diagnosis waiting and its
last plain reply known, and stops before the first that is not, at the end of the cycle
(the line tasks and the next cycle are the scheduler's), and at :data:`RING_MAX`
exchanges. Nothing else may wait: no DP-V1 job, no slave in start-up, no repetition.

Afterwards each exchange the ring did is entered as the general path enters a steady
reply, with the times it really happened: the reply's turn ends (response time, FCB,
exchanges; its unchanged inputs reported if their refresh was due by then: a steady
reply's inputs are the last ones reported), the next slave's
turn begins with its Data_Exchange (the scheduler's own ``send_for``) and its write is
confirmed (the line's ``on_written``). The counters and telegrams are those of the lane
and of the general path: a property test runs all three on the same lines.
"""

from __future__ import annotations

from typing import Final

from adapters.link.ringplan import REPLY_MAX, RingPlan, RingResult
from adapters.profibus.codec.fdl import RequestFunction
from adapters.profibus.master.events import Action, LineMode, Purpose, SlaveState, Transmit
from adapters.profibus.master.line import Line
from adapters.profibus.master.scheduler import Scheduler
from adapters.profibus.master.station import Station
from adapters.profibus.master.timing import BITS_PER_CHAR

RING_MAX: Final = 128  # exchanges in one ring at most (a cycle of 125 slaves in one)


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
        self.chain: list[Station] = []  # the slaves of the last plan, in order

    def plan(self, horizon: float) -> RingPlan | None:
        """The ring from the Data_Exchange on the line, or None (nothing to gain: fewer
        than two exchanges, or the line is not in the steady case)."""
        line = self.line
        p = line.pending
        if (
            p is None
            or not p.written
            or p.purpose is not Purpose.DATA
            or line.unwritten
            or line.retry is not None
        ):
            return None
        first = self.stations[p.address]
        if not steady(first):
            return None
        chain = [first]
        requests: list[bytes] = []
        operate = self.scheduler.mode is LineMode.OPERATE
        for address in self.scheduler.queue:
            sl = self.stations[address]
            if len(chain) >= RING_MAX or not steady(sl):
                break
            chain.append(sl)
            requests.append(sl.frame_for(sl.fcb.fc(RequestFunction.SRD_HIGH), operate))
        if len(chain) < 2:
            return None
        self.chain = chain
        return RingPlan(
            deadline=p.deadline,
            expected=tuple(sl.steady_reply for sl in chain),
            requests=tuple(requests),
            tsyn=line.tsyn,
            reply_wait=line.reply_wait,
            t_char=BITS_PER_CHAR * line.bus.t_bit,
            idle_since=line.idle_since,
            busy_until=line.busy_until,
            horizon=horizon,
        )

    def enter(self, result: RingResult) -> bool:
        """Enter what the ring of the last plan did; True when the line is free after its
        last reply (the next turn is the steady one, as after the lane's)."""
        line, scheduler, chain = self.line, self.scheduler, self.chain
        times = result.times
        marked = len(self.out)
        for j in range(result.taken):
            p = line.pending
            assert p is not None and p.address == chain[j].address
            sl = chain[j]
            now = times[2 * j]
            line.pending = None
            line.idle_since = max(line.idle_since, now)
            sl.answered(p, now)
            inputs = sl.last_inputs
            assert inputs is not None  # (steady: its inputs were taken)
            sl.took_inputs(inputs, now)  # the same inputs: reported if due
            if 2 * j + 1 < len(times):  # the next slave's request went out
                at = times[2 * j + 1]
                nxt = scheduler.start_turn()
                scheduler.send_for(nxt, Purpose.DATA, at)
                line.on_written(at)
        # send_for's Transmit actions: the ring wrote them (the inputs reported stay)
        self.out[marked:] = [a for a in self.out[marked:] if type(a) is not Transmit]
        self.chain = []
        return result.taken > 0 and line.pending is None
