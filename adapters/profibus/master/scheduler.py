"""Which station is served when: the cycle, each station's turn, and the line tasks.

One request is outstanding on the line at a time. A cycle visits every slave once, in
address order; a slave's turn is a short burst: in data exchange its Data_Exchange, then a
Slave_Diag if one is waiting (DH/RDH, Stat_Diag), then at most two DP-V1 telegrams of its
head job (request and a first poll, :mod:`.acyclic`); during start-up up to four start-up
telegrams. After the slaves come the line tasks: queued Sync/Freeze, the periodic
Operate/Clear broadcast and one live-list probe when due. An absent slave is probed once
per ``absent_retry`` with a single try, so it costs one slot time per period, never a
whole retry series every cycle. A cycle starts no sooner than ``cycle_time`` after the
last one started.

Data exchange first, the rest in the time left (the target rotation time's rule of IEC
61158-4-3: high-priority cyclic traffic first, low-priority only while the cycle has time
for it). High priority: each Data_Exchange, the Slave_Diag a slave in data exchange asks
for, Global_Control. Low priority: starting a bring-up (the first Slave_Diag of a slave in
WAIT_DIAG), probing an absent or faulty slave, DP-V1, the live-list probe; they go out only
while the cycle's low-priority time is within its budget, ``LOW_SHARE`` of the shortest
watchdog among the slaves in data exchange less the cycle's data exchange time (the line
time per Data_Exchange measured, times the slaves in data exchange), but at least
``LOW_FLOOR`` of that data exchange time and at least one telegram per cycle, so that
bring-up always progresses. A bring-up under way (Set_Prm, Chk_Cfg, Get_Cfg, the ready
polls) is low priority and counts in the budget, but is not deferred: its start was, and
deferring it would run into its state timeouts and the slave's own watchdog (running since
Set_Prm); so are the polls for a DP-V1 answer once its request went out (the job's deadline
runs), and a DP-V1 request whose job could expire before the slave's next turn (two of the
last cycle's length). With no slave in data exchange, or none with a watchdog, there is no
budget. The line time of a telegram is counted from its transmission to the next one (its
reply, retries, slot times and TSYN included).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Final

from adapters.profibus.codec.dp import GlobalControl, global_control_request
from adapters.profibus.codec.fdl import (
    MAX_STATION,
    DataTelegram,
    RequestFunction,
    ResponseFc,
    StationType,
)
from adapters.profibus.errors import SteadyRingError
from adapters.profibus.master.acyclic import JobQueue
from adapters.profibus.master.common import DPV1_PURPOSES, MAX_TURN, Job, Pending, Reply, Turn
from adapters.profibus.master.events import LineMode, Purpose, SlaveState
from adapters.profibus.master.line import Line
from adapters.profibus.master.scan import status_request
from adapters.profibus.master.station import Station, StationContext
from adapters.profibus.master.timing import BusParams

IDLE_GUARD: Final = 0.001  # s: an empty cycle never restarts sooner than this
# The share of the shortest watchdog in data exchange that one cycle may take (data exchange
# plus low-priority work): every slave in data exchange is served well within its watchdog.
LOW_SHARE: Final = 0.25
# ... and however long the data exchange alone takes, low-priority work may have this share
# of it in every cycle, so that bring-up keeps a part of the line (a third of it) when the
# data exchange alone fills LOW_SHARE of the watchdog (a slow host: each turnaround late).
LOW_FLOOR: Final = 0.5


class Scheduler:
    """The cycle of one line (see the module docstring)."""

    def __init__(
        self,
        bus: BusParams,
        stations: dict[int, Station],
        line: Line,
        jobs: JobQueue,
        now: float,
        *,
        context: StationContext,
    ) -> None:
        self.bus = bus
        self.stations = stations
        self.line = line
        self.jobs = jobs
        self.context = context
        self.mode = LineMode.OPERATE
        self.cycle_started: float | None = None
        self._cycle_sent = 0
        self.next_cycle = now
        self.queue: deque[int] = deque()
        self._current: int | None = None
        self.line_done = False
        self._one_shot: deque[GlobalControl] = deque()
        self._gc_due = now
        self._probe_due = now + bus.live_list_period if bus.live_list_period > 0 else math.inf
        self._probe_next = 0
        self.probed: dict[int, StationType] = {}  # stations that answered a live-list probe
        # the budget of low-priority work (module docstring): line time per class this cycle
        self._last_at: float | None = None  # the last transmission of this cycle
        self._last_low = False  # ... and whether it was low priority
        self._low_used = 0.0  # line time of this cycle's low-priority telegrams so far
        self._high_used = 0.0  # ... of its high-priority ones
        self._low_sent = 0  # low-priority telegrams begun in this cycle
        self._dx_sent = 0  # Data_Exchange telegrams in this cycle (retries not counted)
        self._dx_each = 0.0  # line time per Data_Exchange, as the last cycle measured it
        self._low_budget = math.inf  # the budget (s), for the slaves in data exchange ...
        self._budget_for = -1  # ... when context.exchange_changes was this
        # the budget goes round: a cycle's grants start at the slave the last one refused
        self._low_from = 0
        self._refused_at: int | None = None
        self.last_cycle = 0.0  # how long the last cycle took (s)

    # ------------------------------------------------------------------ commands

    def set_mode(self, mode: LineMode, now: float) -> None:
        if mode is not self.mode:
            self.mode = mode
            self._gc_due = now

    def global_control(self, control: GlobalControl) -> None:
        control.encode()  # FrameEncodeError now rather than on the line
        self._one_shot.append(control)

    def reset(self, now: float) -> None:
        """A new cycle from ``now`` (the port was reopened)."""
        self.cycle_started = None
        self.queue.clear()
        self._current = None
        self.next_cycle = now

    # ------------------------------------------------------------------ the cycle

    def send_next(self, now: float) -> None:
        """Transmit what comes next, if the line is free for it (1.1)."""
        # 1.1: a request only after the line was idle TSYN (counted from the last byte
        # written or received), and only once the previous telegram was confirmed written
        line = self.line
        if line.unwritten or now < line.busy_until or now < line.idle_since + line.tsyn:
            return
        if line.retry is not None:
            retry, line.retry = line.retry, None
            self._mark(now, self._last_low)  # a repetition is of its first try's class
            self._transmit(retry, now)
            return
        for _ in range(len(self.stations) + 8):  # bounded: each pass ends or starts a cycle
            if self.cycle_started is None:
                if now < self.next_cycle:
                    return
                self.begin_cycle(now)
            if self._next_in_cycle(now):
                return
            self.end_cycle(now)

    def begin_cycle(self, now: float) -> None:
        self.cycle_started = now
        self._cycle_sent = 0
        self.queue = deque(self.stations)
        self._current = None
        self.line_done = False
        self._last_at = None
        self._low_used = self._high_used = 0.0
        self._low_sent = self._dx_sent = 0
        self._refused_at = None

    def _budget(self) -> float:
        """The cycle's low-priority budget: ``LOW_SHARE`` of the shortest watchdog in data
        exchange less their Data_Exchange time, at least ``LOW_FLOOR`` of that time (inf:
        no slave in data exchange has a watchdog).
        Computed again whenever a slave entered or left data exchange (mid-cycle too: a
        slave that came up in this cycle is protected from its next Data_Exchange on)."""
        changes = self.context.exchange_changes
        if changes == self._budget_for:
            return self._low_budget
        self._budget_for = changes
        shortest = math.inf
        exchanging = 0
        for sl in self.stations.values():
            if sl.state is SlaveState.DATA_EXCHANGE:
                exchanging += 1
                watchdog = sl.params.watchdog
                if watchdog is not None and 0 < watchdog < shortest:
                    shortest = watchdog
        exchange = self._dx_each * exchanging
        self._low_budget = max(LOW_SHARE * shortest - exchange, LOW_FLOOR * exchange)
        return self._low_budget

    def low_allowed(self, now: float, address: int) -> bool:
        """Whether a low-priority telegram for ``address`` that can wait may go out now.

        At least one a cycle, then while the cycle's low-priority line time is within its
        budget. The grants go round the line: when the budget refused a slave, the next
        cycle's grants begin with it (the slaves before it wait for the round to wrap, a
        cycle later at most), so that absent slaves at low addresses cannot starve the
        bring-up of those above them. A DP-V1 request asks as ``MAX_STATION + 1``, never
        held by the round: its job's deadline runs from when it was queued; one whose
        deadline could pass before the slave's next turn (two of the last cycle's length)
        goes without asking."""
        if address < self._low_from:
            return False
        if not self._low_sent:
            return True
        used = self._low_used
        if self._last_low and self._last_at is not None:
            used += now - self._last_at
        if used < self._budget():
            return True
        if self._refused_at is None:
            self._refused_at = address
        self.line.figures.low_deferred += 1
        return False

    def _mark(self, now: float, low: bool) -> None:
        """A telegram of class ``low`` goes out: the line time since the last one was the
        last one's."""
        last = self._last_at
        if last is not None:
            if self._last_low:
                self._low_used += now - last
            else:
                self._high_used += now - last
        self._last_at = now
        self._last_low = low

    def end_cycle(self, now: float) -> None:
        started = self.cycle_started if self.cycle_started is not None else now
        self.cycle_started = None
        if self._last_at is not None:
            self._mark(now, False)
            self._last_at = None
            if self._dx_sent:
                self._dx_each = self._high_used / self._dx_sent
                self._budget_for = -1  # computed again with this figure
        self._low_from = self._refused_at if self._refused_at is not None else 0
        self.last_cycle = now - started
        if self._cycle_sent:
            figures = self.line.figures
            figures.cycles += 1
            figures.cycle.add(now - started)
            self.next_cycle = max(now, started + self.bus.cycle_time)
        else:
            self.next_cycle = max(now + IDLE_GUARD, started + self.bus.cycle_time, self._due())

    def _due(self) -> float:
        """The earliest time something wants the line when nobody is exchanging."""
        times = [self._gc_due, self._probe_due]
        for sl in self.stations.values():
            if sl.state in (SlaveState.ABSENT, SlaveState.FAULT):
                times.append(sl.retry_at)
            else:
                times.append(-math.inf)
        return min(times) if times else math.inf

    def _next_in_cycle(self, now: float) -> bool:
        """Transmit the next telegram of this cycle; False when the cycle is over."""
        while True:
            if self._current is not None:
                sl = self.stations[self._current]
                purpose = _WANTS[sl.state](self, sl, now) if sl.turn.count < MAX_TURN else None
                if purpose is not None:
                    self.send_for(sl, purpose, now)
                    return True
                self._current = None
            if not self.queue:
                break
            self.start_turn()
        if not self.line_done:
            if self._line_task(now):
                return True
            self.line_done = True
        return False

    def start_turn(self) -> Station:
        """The next slave of the cycle; its turn begins."""
        self._current = self.queue.popleft()
        sl = self.stations[self._current]
        sl.turn = Turn()
        return sl

    def steady_next(self, now: float) -> bool:
        """After a turn that ended with its Data_Exchange: the next slave's, if it is in
        data exchange; at the end of the cycle, with no line task due, the cycle ends and
        the next begins the same way. False: :meth:`send_next` decides, nothing changed
        but what it would change first itself (an ended and a begun cycle)."""
        line = self.line
        if self.cycle_started is None or now < line.busy_until or now < line.idle_since + line.tsyn:
            return False
        if not self.queue:
            if self.line_done or self._line_due(now):
                return False
            self.end_cycle(now)
            if now < self.next_cycle:
                return True  # the cycle time is not over: the timer starts the next
            self.begin_cycle(now)
        # a turn in data exchange starts with its Data_Exchange
        if self.stations[self.queue[0]].state is not SlaveState.DATA_EXCHANGE:
            return False
        self.send_for(self.start_turn(), Purpose.DATA, now)
        return True

    @property
    def dx_each(self) -> float:
        """The line time per Data_Exchange as the last cycle measured it (0: not yet)."""
        return self._dx_each

    def line_tasks_due(self) -> tuple[bool, float, float]:
        """(a Sync/Freeze is queued, when the periodic Global_Control is due, when the
        live-list probe is): what a steady ring's plan needs to know of this cycle's end."""
        return bool(self._one_shot), self._gc_due, self._probe_due

    def broadcast_frame(self) -> bytes:
        """The periodic Global_Control as :meth:`_line_task` sends it now."""
        control = GlobalControl(clear_data=self.mode is LineMode.CLEAR)
        return global_control_request(control, sa=self.bus.master_address).encode()

    def ended_with_broadcast(self, now: float) -> None:
        """The cycle's periodic Global_Control went out at ``now`` (a steady ring sent it,
        as :meth:`_line_task` would have)."""
        if not self._line_task(now):
            raise SteadyRingError("a ring sent the cycle's Global_Control before it was due")

    def next_cycle_now(self, now: float) -> None:
        """The cycle's end with nothing more to send, and the next cycle begun, at
        ``now`` (a steady ring went on into it, as :meth:`steady_next` would have)."""
        self.line_done = True
        self.end_cycle(now)
        self.begin_cycle(now)

    # ------------------------------------------------------------------ a station's turn

    def _want_start_up(self, sl: Station, now: float) -> Purpose | None:
        return _START_UP[sl.state]

    def _want_bring_up(self, sl: Station, now: float) -> Purpose | None:
        """WAIT_DIAG: the Slave_Diag that starts a bring-up, if the cycle has time for it;
        later in the same turn (after a reply) the bring-up goes on without asking."""
        if sl.turn.count or self.low_allowed(now, sl.address):
            return Purpose.DIAG
        return None

    def _want_ready(self, sl: Station, now: float) -> Purpose | None:
        return None if sl.turn.ready_polls else Purpose.DIAG

    def _want_exchange(self, sl: Station, now: float) -> Purpose | None:
        turn = sl.turn
        if not turn.data:
            return Purpose.DATA
        if sl.diag_pending and not turn.diag:
            return Purpose.DIAG
        if not self.jobs.jobs:
            return None
        # DP-V1: low priority; a job's request waits for the budget, the polls for its
        # answer go on (as a bring-up under way does: the job's deadline runs)
        purpose = self.jobs.want(sl, now)
        if (
            purpose is Purpose.RECORD
            and now + 2 * self.last_cycle < self.jobs.head(sl.address).deadline
            and not self.low_allowed(now, MAX_STATION + 1)
        ):
            return None  # (a job that could expire before the next turn goes now: two of
            # the last cycle's length, since the cycle that carries it grows by it)
        return purpose

    def _want_probe(self, sl: Station, now: float) -> Purpose | None:
        if sl.turn.count or now < sl.retry_at or not self.low_allowed(now, sl.address):
            return None
        if sl.state is SlaveState.FAULT:
            sl.enter(SlaveState.WAIT_DIAG, now, "retrying after a fault")
        return Purpose.DIAG

    def send_for(self, sl: Station, purpose: Purpose, now: float) -> None:
        sl.turn.count += 1
        fc = sl.fcb.fc(RequestFunction.SRD_HIGH)
        job: Job | None = None
        if purpose is Purpose.DATA:  # the message of every cycle: nothing else to decide
            self._mark(now, False)
            self._dx_sent += 1
            sl.turn.data = True
            data = sl.data_frame(fc, self.mode is LineMode.OPERATE)
            dsap, tries = None, 1 + self.bus.retries
        else:
            low = not (purpose is Purpose.DIAG and sl.state is SlaveState.DATA_EXCHANGE)
            self._mark(now, low)
            self._low_sent += low
            job = self._count_in_turn(sl, purpose)
            telegram: DataTelegram
            if purpose in DPV1_PURPOSES:
                telegram = self.jobs.request(purpose, sl, fc, job)
            else:
                telegram = sl.request(purpose, fc)
            data, dsap = telegram.encode(), telegram.dsap
            tries = 1 if sl.state is SlaveState.ABSENT else 1 + self.bus.retries
        sl.figures.requests += 1
        pending = Pending(sl.address, purpose, data, now, now, tries, True, job=job, dsap=dsap)
        self._cycle_sent += 1
        self.line.transmit(pending, now, fresh=True)

    def _count_in_turn(self, sl: Station, purpose: Purpose) -> Job | None:
        """Note a telegram other than Data_Exchange in the slave's turn; a DP-V1 one's job."""
        turn = sl.turn
        if purpose is Purpose.DIAG and sl.state is SlaveState.DATA_EXCHANGE:
            turn.diag = True
        elif purpose is Purpose.DIAG and sl.state is SlaveState.WAIT_READY:
            turn.ready_polls += 1
        elif purpose in DPV1_PURPOSES:
            turn.acyclic += 1
            return self.jobs.head(sl.address)
        elif purpose is Purpose.SET_PRM:
            sl.prm_attempts += 1
        return None

    def _transmit(self, pending: Pending, now: float, fresh: bool = False) -> None:
        self._cycle_sent += 1
        self.line.transmit(pending, now, fresh)

    # ------------------------------------------------------------------ line tasks

    def _line_due(self, now: float) -> bool:
        """A line task waits (each is looked at by :meth:`_line_task`, in this order)."""
        return bool(self._one_shot) or now >= self._gc_due or now >= self._probe_due

    def _line_task(self, now: float) -> bool:
        """After the slaves: Sync/Freeze, the Operate/Clear broadcast, a live-list probe."""
        if self._one_shot:
            self._broadcast(self._one_shot.popleft(), now)
            return True
        if now >= self._gc_due:
            self._gc_due = now + self.bus.global_control_period
            clear = self.mode is LineMode.CLEAR
            self._broadcast(GlobalControl(clear_data=clear), now)
            return True
        if now >= self._probe_due and self.low_allowed(now, MAX_STATION + 1):
            self._probe_due = now + self.bus.live_list_period
            address = self._next_probe()
            if address is not None:
                data = status_request(address, self.bus.master_address)
                pending = Pending(address, Purpose.STATUS, data, now, now, 1, False)
                self._mark(now, True)
                self._low_sent += 1
                self._transmit(pending, now, fresh=True)
                return True
        return False

    def _broadcast(self, control: GlobalControl, now: float) -> None:
        self._mark(now, False)
        self._cycle_sent += 1
        self.line.broadcast(control, now)

    def _next_probe(self) -> int | None:
        for _ in range(MAX_STATION + 1):
            address = self._probe_next
            self._probe_next = (self._probe_next + 1) % (MAX_STATION + 1)
            if address != self.bus.master_address and address not in self.stations:
                return address
        return None

    def on_status_reply(self, p: Pending, t: Reply) -> None:
        """A live-list probe was answered: the station is there, as what it says it is."""
        if isinstance(t, DataTelegram) and isinstance(t.fc, ResponseFc):
            self.probed[p.address] = t.fc.station_type
        else:
            self.probed[p.address] = StationType.SLAVE


# ---------------------------------------------------------------------------------------
# Tables

_START_UP: Final[dict[SlaveState, Purpose]] = {
    SlaveState.WAIT_DIAG: Purpose.DIAG,
    SlaveState.SET_PRM: Purpose.SET_PRM,
    SlaveState.CHK_CFG: Purpose.CHK_CFG,
    SlaveState.GET_CFG: Purpose.GET_CFG,
}

_WANTS: Final[dict[SlaveState, Callable[[Scheduler, Station, float], Purpose | None]]] = {
    SlaveState.WAIT_DIAG: Scheduler._want_bring_up,
    SlaveState.SET_PRM: Scheduler._want_start_up,
    SlaveState.CHK_CFG: Scheduler._want_start_up,
    SlaveState.WAIT_READY: Scheduler._want_ready,
    SlaveState.GET_CFG: Scheduler._want_start_up,
    SlaveState.DATA_EXCHANGE: Scheduler._want_exchange,
    SlaveState.ABSENT: Scheduler._want_probe,
    SlaveState.FAULT: Scheduler._want_probe,
}
