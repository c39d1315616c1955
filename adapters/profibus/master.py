"""The Profibus DP class-1 master engine: sans-IO, stepped with an injected clock.

Written from the fact sheet (``reference/protocol-facts.md``): 1.1 timing (TSYN before every
request, TSL bounding each wait, retries), 1.3 FCB handling, 1.5 start-up and error handling,
1.6 Set_Prm, 1.7 Chk_Cfg/Get_Cfg, 1.8 Slave_Diag, 1.9 Global_Control, 1.10 DP-V1 MSAC_C1.

``Master.step(now, event) -> actions``: events are what the line delivered (a decoded
telegram, garbage, bytes still arriving); actions are telegrams to transmit (each with the
earliest time it may go out) and what happened to the slaves (reached data exchange, left
it, inputs, diagnosis, faults, DP-V1 results). Between steps, :meth:`Master.next_deadline`
says when to step again if nothing arrives. Commands (outputs, DP-V1 jobs, Global_Control,
line mode) are plain method calls; the caller steps afterwards to get them going.

Scheduling. One request is outstanding on the line at a time. A cycle visits every slave
once, in address order; a slave's turn is a short burst: in data exchange its
Data_Exchange, then a Slave_Diag if one is waiting (DH/RDH, Stat_Diag), then at most two
DP-V1 telegrams of its head job (request and a first poll); during start-up up to four
start-up telegrams. After the slaves come the line tasks: queued Sync/Freeze, the periodic
Operate/Clear broadcast and one live-list probe when due. An absent slave is probed once
per ``absent_retry`` with a single try, so it costs one slot time per period, never a
whole retry series every cycle.

Timing (1.1). Every idle time and reply deadline counts from when a telegram actually went
out: the driver confirms each :class:`Transmit` with a :class:`Written` event carrying the
time it wrote the bytes, and the telegram occupies the line for its line time after that
(an event loop runs callbacks late; the planned time is never used). Until a Transmit is
confirmed nothing else is sent and nothing times out. Any byte received (a reply, a stray
reply to a retried request, an echo, noise) restarts the idle time: the next request is
decided only once the line has been quiet for TSYN, so bytes arriving meanwhile move it.
A short acknowledgement (E5) carries no address: it is taken only as the answer to a request
that may be answered so, never as a Data_Exchange reply of a slave with inputs.

DP-V1 (1.10). A DP-V1 telegram that stays unanswered after every try does not restart the
slave: its job fails, DP-V1 to that slave is held for a back-off (:data:`DPV1_BACKOFF`,
doubling), its Data_Exchange goes on, and a :class:`SlaveFault` reports it once (again only
after a DP-V1 answer came in between).

The steady case (a plain reply to a Data_Exchange, nothing else waiting, the next turn a
Data_Exchange too) takes a short path from reply to request; a property test runs it and
the general path on the same lines and finds every telegram, action and counter equal.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from gateway.errors import FrameEncodeError

from . import dpv1
from .diag import SlaveDiag, describe_blocks
from .dp import (
    DataExchange,
    GetCfgRequest,
    GlobalControl,
    MasterSap,
    SlaveDiagRequest,
    SlaveSap,
    build_request,
    global_control_request,
)
from .errors import DecodeFailure, FdlDecodeError, ProfibusDecodeError
from .events import (
    Action,
    DiagnosisRead,
    Event,
    FaultKind,
    InputsReceived,
    LineMode,
    LineNoise,
    Purpose,
    Received,
    Receiving,
    RecordDone,
    RecordFailure,
    SlaveDown,
    SlaveFault,
    SlaveParams,
    SlaveState,
    SlaveStateChanged,
    SlaveUp,
    Transmit,
    Written,
    check_slave,
    describe_cfg,
)
from .fdl import (
    MAX_STATION,
    DataTelegram,
    FcbState,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    ShortAck,
    StationType,
    TokenTelegram,
)
from .linestats import LineStats, SlaveStats
from .scan import status_request
from .timing import MAX_TELEGRAM, BusParams

MAX_TURN: Final = 4  # telegrams of one slave in one cycle (retries not counted)
MAX_ACYCLIC_PER_TURN: Final = 2  # DP-V1 request + first poll
MAX_PRM_ATTEMPTS: Final = 3  # Set_Prm repeated on Prm_Req before "keeps asking"
IDLE_GUARD: Final = 0.001  # s: an empty cycle never restarts sooner than this
DPV1_BACKOFF: Final = (1.0, 60.0)  # s: DP-V1 held after an unanswered request, doubling
FRAME_MEMO: Final = 4  # Data_Exchange telegrams kept encoded per slave (2 FCBs x outputs)

# 1.5, pyprofibus state timeouts (s): how long a start-up state may last before restarting.
STATE_TIMEOUTS: Final[Mapping[SlaveState, float]] = {
    SlaveState.WAIT_DIAG: 1.0,
    SlaveState.SET_PRM: 0.5,
    SlaveState.CHK_CFG: 0.5,
    SlaveState.WAIT_READY: 1.0,
    SlaveState.GET_CFG: 0.5,
}
# The states whose timeout the engine watches (WAIT_DIAG ends through the retries instead).
_TIMED_STATES: Final = frozenset(STATE_TIMEOUTS) - {SlaveState.WAIT_DIAG}

__all__ = [
    "Action",
    "DiagnosisRead",
    "Event",
    "FaultKind",
    "InputsReceived",
    "LineMode",
    "LineNoise",
    "Master",
    "Purpose",
    "Received",
    "Receiving",
    "RecordDone",
    "RecordFailure",
    "SlaveDown",
    "SlaveFault",
    "SlaveParams",
    "SlaveState",
    "SlaveStateChanged",
    "SlaveUp",
    "Transmit",
    "Written",
    "check_slave",
    "describe_cfg",
]

# ---------------------------------------------------------------------------------------
# Internal records


@dataclass
class _Job:
    id: int
    address: int
    request: dpv1.ReadRequest | dpv1.WriteRequest
    deadline: float
    requested: bool = False  # the request was accepted: poll for the answer


@dataclass(slots=True)
class _Turn:
    count: int = 0
    data: bool = False
    diag: bool = False
    ready_polls: int = 0
    acyclic: int = 0
    acyclic_wait: bool = False  # the slave has nothing for us yet: next turn


@dataclass
class _Slave:
    params: SlaveParams
    set_prm: bytes
    outputs: bytes
    outputs_pending: bool = False  # set_outputs given, no Data_Exchange built from them yet
    state: SlaveState = SlaveState.WAIT_DIAG
    since: float = 0.0
    fcb: FcbState = field(default_factory=FcbState)
    retry_at: float = 0.0
    diag_pending: bool = False
    prm_attempts: int = 0
    fault: str | None = None
    last_diag: SlaveDiag | None = None
    jobs: deque[_Job] = field(default_factory=deque)
    dpv1_hold_until: float = -math.inf  # DP-V1 held after an unanswered request
    dpv1_backoff: float = 0.0  # the last hold, s (0: none since the last answer)
    dpv1_reported: bool = False  # the unanswered DP-V1 fault was reported
    frames: dict[tuple[bool, bool, bytes], bytes] = field(default_factory=dict)
    turn: _Turn = field(default_factory=_Turn)
    stats: SlaveStats = field(default_factory=SlaveStats)

    @property
    def address(self) -> int:
        return self.params.address


@dataclass(slots=True)
class _Pending:
    address: int
    purpose: Purpose
    data: bytes
    sent_at: float
    deadline: float
    max_tries: int
    fcb_function: bool
    tries: int = 1
    garbled: bool = False
    job: _Job | None = None
    dsap: int | None = None  # the request's DSAP: the reply's SSAP must match (1.2)
    written: bool = False  # the driver confirmed the write (Written): the deadline counts


Reply = DataTelegram | ShortAck

# ---------------------------------------------------------------------------------------
# The engine


class Master:
    """A DP class-1 master for the slaves of one line (see the module docstring)."""

    def __init__(self, bus: BusParams, slaves: Iterable[SlaveParams], now: float = 0.0) -> None:
        self.bus = bus
        self.address = bus.master_address
        self._slaves: dict[int, _Slave] = {}
        for params in sorted(slaves, key=lambda s: s.address):
            check_slave(params, self.address)
            if params.address in self._slaves:
                raise FrameEncodeError(f"slave address {params.address} configured twice")
            self._slaves[params.address] = _Slave(
                params=params,
                set_prm=params.set_prm(bus.min_tsdr).encode(),
                outputs=bytes(params.output_len),
                since=now,
            )
        self.stats = LineStats()
        self._tsyn = bus.tsyn  # BusParams computes these on every call; each message needs them
        self._reply_wait = bus.reply_wait
        self.mode = LineMode.OPERATE
        self._pending: _Pending | None = None
        self._retry: _Pending | None = None  # timed out, repeated once the line is idle
        self._unwritten: deque[tuple[int, _Pending | None]] = deque()  # bytes, request
        self._idle_since = now - bus.tsyn
        self._busy_until = now
        self._cycle_started: float | None = None
        self._cycle_sent = 0
        self._next_cycle = now
        self._queue: deque[int] = deque()
        self._current: int | None = None
        self._line_done = False
        self._one_shot: deque[GlobalControl] = deque()
        self._gc_due = now
        self._probe_due = now + bus.live_list_period if bus.live_list_period > 0 else math.inf
        self._probe_next = 0
        self._stations: dict[int, StationType] = {}
        self._jobs: dict[int, _Job] = {}
        self._timed: dict[int, _Slave] = {}  # slaves in a state with a timeout (start-up)
        self._job_ids = 0
        self._stopped = False
        self._out: list[Action] = []

    # ------------------------------------------------------------------ views

    def slave_params(self) -> tuple[SlaveParams, ...]:
        """What each slave is sent at start-up (Set_Prm, Chk_Cfg), by address."""
        return tuple(sl.params for sl in self._slaves.values())

    @property
    def addresses(self) -> tuple[int, ...]:
        return tuple(self._slaves)

    def state_of(self, address: int) -> SlaveState:
        return self._slave(address).state

    def slave_stats(self, address: int) -> SlaveStats:
        return self._slave(address).stats

    def fault_of(self, address: int) -> str | None:
        return self._slave(address).fault

    def live_list(self) -> list[int]:
        """Stations that answered lately: configured slaves not absent, and probed ones."""
        live = {a for a, s in self._slaves.items() if s.state is not SlaveState.ABSENT}
        return sorted(live | set(self._stations))

    def slave_diagnostics(self, address: int) -> dict[str, Any]:
        sl = self._slave(address)
        return {
            "address": address,
            "state": sl.state.value,
            "fault": sl.fault,
            "jobs_queued": len(sl.jobs),
            **sl.stats.to_json(),
        }

    def line_diagnostics(self) -> dict[str, Any]:
        return {
            "mode": self.mode.value,
            "baudrate": self.bus.baudrate,
            "master_address": self.address,
            **self.stats.to_json(),
            "live_list": self.live_list(),
        }

    def _slave(self, address: int) -> _Slave:
        try:
            return self._slaves[address]
        except KeyError:
            raise KeyError(f"no slave {address} on this line") from None

    # ------------------------------------------------------------------ commands

    def set_outputs(self, address: int, data: bytes) -> None:
        """The outputs for the slave's next Data_Exchange (its configured length)."""
        sl = self._slave(address)
        if len(data) != sl.params.output_len:
            raise FrameEncodeError(
                f"slave {address} takes {sl.params.output_len} output bytes, got {len(data)}"
            )
        sl.outputs = bytes(data)
        sl.outputs_pending = True

    def outputs_pending(self, address: int) -> bool:
        """Outputs were given that no Data_Exchange has carried yet.

        A reply's inputs may come before the next telegram to that slave is built (when
        it is built later, at the cycle time); a caller that computes outputs on every
        reply skips one while this is true, so that none it computed (a one-telegram
        pulse, say) is replaced before it went out.
        """
        return self._slave(address).outputs_pending

    def set_mode(self, mode: LineMode, now: float) -> None:
        """Operate or Clear; the new Global_Control goes out at the end of this cycle."""
        if mode is not self.mode:
            self.mode = mode
            self._gc_due = now

    def global_control(self, control: GlobalControl) -> None:
        """A one-shot Global_Control (Sync, Freeze...) at the end of this cycle (1.9)."""
        control.encode()  # FrameEncodeError now rather than on the line
        self._one_shot.append(control)

    def read_record(self, address: int, slot: int, index: int, length: int, now: float) -> int:
        """Queue a DP-V1 read (1.10); the result comes as :class:`RecordDone`."""
        return self._queue_job(address, dpv1.ReadRequest(slot, index, length), now)

    def write_record(self, address: int, slot: int, index: int, data: bytes, now: float) -> int:
        return self._queue_job(address, dpv1.WriteRequest(slot, index, bytes(data)), now)

    def cancel_record(self, job_id: int) -> None:
        """Forget a job (its caller gave up); no RecordDone follows."""
        job = self._jobs.pop(job_id, None)
        if job is None:
            return
        sl = self._slaves[job.address]
        if job in sl.jobs:
            sl.jobs.remove(job)
        for p in (self._pending, self._retry):
            if p is not None and p.job is job:
                p.job = None

    def _queue_job(
        self, address: int, request: dpv1.ReadRequest | dpv1.WriteRequest, now: float
    ) -> int:
        sl = self._slave(address)
        request.encode()  # FrameEncodeError for a bad slot/index/length now
        self._job_ids += 1
        job = _Job(self._job_ids, address, request, now + self.bus.acyclic_timeout)
        self._jobs[job.id] = job
        if sl.state is SlaveState.DATA_EXCHANGE and sl.params.dpv1 and now < sl.dpv1_hold_until:
            self._finish(job, RecordFailure.TIMEOUT, self._held_text(sl, now))
        elif sl.state is SlaveState.DATA_EXCHANGE and sl.params.dpv1:
            sl.jobs.append(job)
        else:
            why = "not in data exchange" if sl.params.dpv1 else "runs without DP-V1"
            self._finish(job, RecordFailure.OFFLINE, f"slave {address} {why}")
        return job.id

    def reset(self, now: float) -> list[Action]:
        """Start every slave up again (the port was reopened): nothing is outstanding."""
        self._pending = self._retry = None
        self._unwritten.clear()
        for sl in self._slaves.values():
            self._enter(sl, SlaveState.WAIT_DIAG, now, "the serial port was reopened")
        self._cycle_started = None
        self._queue.clear()
        self._current = None
        self._next_cycle = now
        self._idle_since = now - self._tsyn
        return self._take()

    def leave(self, now: float) -> list[Transmit]:
        """Leave the line: Global_Control Clear to everyone, twice (SDN is unacknowledged)."""
        self._stopped = True
        self._pending = None
        self.mode = LineMode.CLEAR
        data = global_control_request(GlobalControl.clear(), sa=self.address).encode()
        busy = self._idle_since  # a telegram not confirmed yet: assume it went out now
        for n, _ in self._unwritten:
            busy = max(busy, now + self.bus.tx_time(n))
        self._unwritten.clear()
        first = max(now, busy + self._tsyn)
        second = first + self.bus.tx_time(len(data)) + self._tsyn
        return [Transmit(data, first, False), Transmit(data, second, False)]

    # ------------------------------------------------------------------ stepping

    def step(self, now: float, event: Event | None = None) -> list[Action]:
        if self._stopped:
            return []
        if event is not None:
            if type(event) is Received and self._steady_reply(event.telegram, now):
                return self._take()
            self._on_event(event, now)
        if self._jobs:
            self._check_jobs(now)
        if self._pending is not None and now >= self._pending.deadline:
            self._on_timeout(self._pending, now)
        if self._timed:  # slaves in start-up only: nothing to do per step in data exchange
            for sl in list(self._timed.values()):
                self._check_state_timeout(sl, now)
        if self._pending is None:
            self._send_next(now)
        return self._take()

    def next_deadline(self) -> float | None:
        """When to step again if nothing arrives (None: only after a command)."""
        if self._stopped:
            return None
        if self._unwritten:  # the line is ours until the driver confirms the write
            return min((j.deadline for j in self._jobs.values()), default=None)
        if self._pending is not None:
            return self._pending.deadline
        line_free = max(self._busy_until, self._idle_since + self._tsyn)
        if self._retry is not None:
            return line_free
        # in a cycle (after a broadcast): go on when the line is free; else the next cycle
        base = self._busy_until if self._cycle_started is not None else self._next_cycle
        times = [base, *(j.deadline for j in self._jobs.values())]
        return max(line_free, min(times))

    def awaiting_reply(self) -> bool:
        """A request is on the line (confirmed written) and its reply deadline runs."""
        return self._pending is not None and self._pending.written

    def _take(self) -> list[Action]:
        out, self._out = self._out, []
        return out

    # ------------------------------------------------------------------ events

    def _on_event(self, event: Event, now: float) -> None:
        if isinstance(event, Written):
            self._on_written(event.at)
            return
        # 1.1: any byte on the line restarts the idle time before the next request
        self._idle_since = max(self._idle_since, now)
        if isinstance(event, Received):
            self._on_received(event.telegram, now)
        elif isinstance(event, LineNoise):
            self._on_noise(event.error, now)
        elif self._pending is not None and self._pending.written:  # Receiving: the rest
            bound = now + self.bus.tx_time(MAX_TELEGRAM) + self.bus.latency
            self._pending.deadline = max(self._pending.deadline, bound)

    def _on_written(self, at: float) -> None:
        """The oldest unconfirmed telegram was written at ``at``: on the line until its
        line time after that (1.1); a request's reply wait starts there."""
        if not self._unwritten:
            return  # written before a reset: nothing waits for it any more
        n, pending = self._unwritten.popleft()
        end = at + self.bus.tx_time(n)
        self._idle_since = max(self._idle_since, end)
        if pending is None:  # a broadcast: nobody answers, the line is free TSYN later
            self._busy_until = max(self._busy_until, end + self._tsyn)
        elif pending is self._pending:
            pending.sent_at = at
            pending.deadline = end + self._reply_wait
            pending.written = True

    def count_noise(self, error: FdlDecodeError, address: int | None = None) -> None:
        """Count undecodable bytes (line level, and for ``address`` if given)."""
        self.stats.discarded_bytes += len(error.raw)
        counters: list[Any] = [self.stats]
        if address in self._slaves:
            counters.append(self._slaves[address].stats)
        for c in counters:
            if error.reason is DecodeFailure.BAD_CHECKSUM:
                c.fcs_errors += 1
            else:
                c.framing_errors += 1

    def _on_noise(self, error: FdlDecodeError, now: float) -> None:
        pending = self._pending
        self.count_noise(error, pending.address if pending is not None else None)
        if pending is not None and pending.written:
            pending.garbled = True
            # wait until the line is quiet again before repeating
            pending.deadline = max(pending.deadline, now + self.bus.reply_wait)

    def _on_received(self, telegram: DataTelegram | ShortAck | TokenTelegram, now: float) -> None:
        pending = self._pending
        if isinstance(telegram, DataTelegram) and telegram.is_request:
            return  # our own echo (half-duplex converters) or another station's request
        if pending is None or not pending.written or isinstance(telegram, TokenTelegram):
            self.stats.unexpected += 1
            return
        if isinstance(telegram, DataTelegram) and not _answers_request(
            pending, telegram, self.address
        ):
            self.stats.unexpected += 1  # e.g. a late reply to an earlier request
            return
        if isinstance(telegram, ShortAck) and not self._takes_short_ack(pending):
            self.stats.unexpected += 1  # E5 has no address: a late answer to another request
            return
        self._pending = None
        # never before the end of our own request: a stray reply seen while it was still
        # going out (a late answer, noise) must not shorten the idle time before the next
        self._idle_since = max(self._idle_since, now)
        if pending.purpose is Purpose.STATUS:
            self._on_status_reply(pending, telegram)
            return
        sl = self._slaves[pending.address]
        self._answered(sl, pending, now)
        _REPLY_HANDLERS[pending.purpose](self, sl, pending, telegram, now)

    def _takes_short_ack(self, pending: _Pending) -> bool:
        """Whether E5 may answer ``pending`` (1.2: an acknowledgement without data)."""
        if pending.purpose is Purpose.DATA:
            return self._slaves[pending.address].params.input_len == 0
        return pending.purpose in _SHORT_ACK_PURPOSES

    def _answered(self, sl: _Slave, pending: _Pending, now: float) -> None:
        sl.stats.response.add(now - pending.sent_at)
        if pending.fcb_function:
            sl.fcb = sl.fcb.acknowledged()  # 1.3: toggle after each acknowledged SRD

    def _steady_reply(self, t: object, now: float) -> bool:
        """The steady case of data exchange on a short path; False (nothing changed) else.

        A DL reply without SAPs, with the configured inputs, to a Data_Exchange, while no
        DP-V1 job, diagnosis or start-up is waiting: the slave's turn is over (1.5 step 6)
        and, most often, the next slave's Data_Exchange goes out. The general path
        (``_on_event``, then ``_send_next``) does the same with every case in view; this
        one keeps the turnaround short (a test runs both on the same lines and compares).
        """
        p = self._pending
        sl = self._steady_slave(p, t)
        if p is None or sl is None or not isinstance(t, DataTelegram):
            return False
        self._pending = None
        self._idle_since = max(self._idle_since, now)
        self._answered(sl, p, now)
        self._took_inputs(sl, bytes(t.data))
        if not self._steady_next(now):
            self._send_next(now)
        return True

    def _steady_next(self, now: float) -> bool:
        """After a turn that ended with its Data_Exchange: the next slave's, if it is in
        data exchange; at the end of the cycle, with no line task due, the cycle ends and
        the next begins the same way. False: ``_send_next`` decides, nothing changed but
        what it would change first itself (an ended and a begun cycle)."""
        if (
            self._cycle_started is None
            or now < self._busy_until
            or now < self._idle_since + self._tsyn
        ):
            return False
        if not self._queue:
            if self._line_done or self._line_due(now):
                return False
            self._end_cycle(now)
            if now < self._next_cycle:
                return True  # the cycle time is not over: the timer starts the next
            self._begin_cycle(now)
        # a turn in data exchange starts with its Data_Exchange
        if self._slaves[self._queue[0]].state is not SlaveState.DATA_EXCHANGE:
            return False
        self._send_for(self._start_turn(), Purpose.DATA, now)
        return True

    def _steady_slave(self, p: _Pending | None, t: object) -> _Slave | None:
        """The slave whose plain Data_Exchange reply ``t`` is, if nothing else waits."""
        if (
            p is None
            or not p.written
            or p.purpose is not Purpose.DATA
            or self._jobs
            or self._timed
            or type(t) is not DataTelegram
            or type(t.fc) is not ResponseFc
            or t.fc.status is not ResponseStatus.DL
            or t.sa != p.address
            or t.da != self.address
            or t.dsap is not None
            or t.ssap is not None
        ):
            return None
        sl = self._slaves[p.address]
        if sl.diag_pending or len(t.data) != sl.params.input_len:
            return None
        return sl

    def _on_timeout(self, pending: _Pending, now: float) -> None:
        self._pending = None
        self._idle_since = max(self._idle_since, now)
        if pending.purpose is Purpose.STATUS:  # a live-list probe: silence is an answer
            self._stations.pop(pending.address, None)
            return
        sl = self._slaves[pending.address]
        counters: list[Any] = [self.stats, sl.stats]
        if pending.tries < pending.max_tries:
            for c in counters:
                c.retries += 1
            self._retry = pending  # repeated once the line was idle TSYN (1.1)
            return
        for c in counters:
            c.timeouts += 1
        sl.fcb = FcbState.reset()
        if pending.purpose in _DPV1_PURPOSES and sl.state is SlaveState.DATA_EXCHANGE:
            self._dpv1_unanswered(sl, pending, now)
            return
        self._gave_up(sl, pending, now)

    def _dpv1_unanswered(self, sl: _Slave, pending: _Pending, now: float) -> None:
        """A DP-V1 telegram unanswered after every try (1.10): the slave keeps its data
        exchange (the next Data_Exchange tells whether it is still there); DP-V1 to it is
        held for a back-off; the fault is reported once."""
        low, high = DPV1_BACKOFF
        sl.dpv1_backoff = min(2 * sl.dpv1_backoff, high) if sl.dpv1_backoff else low
        sl.dpv1_hold_until = now + sl.dpv1_backoff
        tries = pending.max_tries
        text = (
            f"slave {sl.address} left a DP-V1 {pending.purpose.value} (MSAC_C1) unanswered "
            f"after {tries} {'try' if tries == 1 else 'tries'}; data exchange goes on, DP-V1 "
            f"held for {sl.dpv1_backoff:g} s"
        )
        for job in list(sl.jobs):
            self._finish(job, RecordFailure.TIMEOUT, text)
        if not sl.dpv1_reported:
            sl.dpv1_reported = True
            self._out.append(SlaveFault(sl.address, FaultKind.DPV1_UNANSWERED, text))

    def _held_text(self, sl: _Slave, now: float) -> str:
        return (
            f"DP-V1 to slave {sl.address} is held for {sl.dpv1_hold_until - now:.1f} s more: "
            "it left a DP-V1 request unanswered"
        )

    def _dpv1_answered(self, sl: _Slave) -> None:
        sl.dpv1_backoff = 0.0
        sl.dpv1_reported = False

    def _gave_up(self, sl: _Slave, pending: _Pending, now: float) -> None:
        """No (valid) reply after every try (1.5 step 7)."""
        what = "no valid reply" if pending.garbled else "no reply"
        if sl.state in (SlaveState.WAIT_DIAG, SlaveState.ABSENT):
            sl.retry_at = now + self.bus.absent_retry
            self._enter(sl, SlaveState.ABSENT, now, what)
            return
        wait = (pending.deadline - pending.sent_at) * 1000
        tries = f"{pending.tries} {'try' if pending.tries == 1 else 'tries'}"
        self._enter(
            sl,
            SlaveState.WAIT_DIAG,
            now,
            f"{what} to {_REQUEST_NAMES[pending.purpose]} after {tries} "
            f"(waited {wait:.1f} ms for each)",
        )

    # ------------------------------------------------------------------ replies

    def _reply_diag(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        if not (isinstance(t, DataTelegram) and t.ssap == SlaveSap.SLAVE_DIAG and len(t.data) >= 6):
            self._invalid(sl, f"Slave_Diag answered with {_show(t)}", now)
            return
        try:
            diag = SlaveDiag.decode(t.data, dpv1=sl.params.dpv1)
        except ProfibusDecodeError as exc:
            self._invalid(sl, f"undecodable diagnosis: {exc.message}", now)
            return
        self._on_diag(sl, diag, bytes(t.data[6:]), now)

    def _reply_ack(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        """Set_Prm and Chk_Cfg expect a short acknowledgement (1.5 steps 3 and 4)."""
        status = _status(t)
        if status not in (ResponseStatus.OK, ResponseStatus.DL) or (
            isinstance(t, DataTelegram) and t.data
        ):
            what = "Set_Prm" if p.purpose is Purpose.SET_PRM else "Chk_Cfg"
            self._fault(sl, FaultKind.REFUSED, f"the slave refused {what} ({_show(t)})", now)
            return
        if p.purpose is Purpose.SET_PRM:
            self._enter(sl, SlaveState.CHK_CFG, now)
        else:
            self._enter(sl, SlaveState.WAIT_READY, now)

    def _reply_get_cfg(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        sent = describe_cfg(sl.params.cfg)
        slave_cfg: bytes | None = None
        if isinstance(t, DataTelegram) and t.ssap == SlaveSap.GET_CFG:
            slave_cfg = bytes(t.data)
            has = describe_cfg(slave_cfg)
            text = f"Cfg_Fault: the slave refused the configuration {sent}; it has {has}"
        else:
            text = f"Cfg_Fault: the slave refused the configuration {sent} (Get_Cfg: {_show(t)})"
        text += _origin(sl.params) + _slave_words(sl.last_diag)
        self._fault(sl, FaultKind.CFG_FAULT, text, now, slave_cfg)

    def _reply_data(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        """Data_Exchange reply (1.5 step 6): DL with inputs, E5 without, DH: diag waits."""
        status = _status(t)
        if status is ResponseStatus.RS:
            self._enter(sl, SlaveState.WAIT_DIAG, now, "the slave left data exchange (RS)")
            return
        if status not in _DATA_OK or (isinstance(t, DataTelegram) and t.dsap is not None):
            self._restart_bad(sl, f"Data_Exchange answered with {_show(t)}", now)
            return
        data = bytes(t.data) if isinstance(t, DataTelegram) else b""
        if len(data) != sl.params.input_len:
            self._restart_bad(
                sl, f"{len(data)} input bytes, the configuration has {sl.params.input_len}", now
            )
            return
        if status in (ResponseStatus.DH, ResponseStatus.RDH):
            sl.diag_pending = True
        self._took_inputs(sl, data)

    def _took_inputs(self, sl: _Slave, data: bytes) -> None:
        sl.stats.exchanges += 1
        self._out.append(InputsReceived(sl.address, data))

    def _reply_record(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        self._dpv1_answered(sl)
        job = p.job
        if job is None:
            return  # cancelled meanwhile
        status = _status(t)
        if isinstance(t, DataTelegram) and t.data and status in _DATA_OK:
            self._record_answer(sl, job, bytes(t.data), now)
        elif status in (ResponseStatus.OK, ResponseStatus.DL, ResponseStatus.NR):
            job.requested = True  # accepted: poll for the answer (1.10 "Getting the reply")
        elif status is ResponseStatus.RR:
            sl.turn.acyclic_wait = True  # no resources now: ask again next turn
        else:
            self._finish(job, RecordFailure.REFUSED, _refusal_text(status))

    def _reply_poll(self, sl: _Slave, p: _Pending, t: Reply, now: float) -> None:
        self._dpv1_answered(sl)
        job = p.job
        if job is None:
            return
        status = _status(t)
        if isinstance(t, DataTelegram) and t.data and status in _DATA_OK:
            self._record_answer(sl, job, bytes(t.data), now)
        elif status in (ResponseStatus.OK, ResponseStatus.DL, ResponseStatus.NR):
            sl.turn.acyclic_wait = True  # not ready yet
        else:
            self._finish(job, RecordFailure.REFUSED, _refusal_text(status))

    def _record_answer(self, sl: _Slave, job: _Job, data: bytes, now: float) -> None:
        try:
            answer = dpv1.decode_response(data)
        except ProfibusDecodeError as exc:
            sl.stats.invalid_replies += 1
            self._finish(job, RecordFailure.BAD_REPLY, f"undecodable DP-V1 answer: {exc.message}")
            return
        if not _answers(job.request, answer):
            sl.stats.invalid_replies += 1  # a stale answer to an older request: keep polling
            job.requested = True
            sl.turn.acyclic_wait = True
            return
        if isinstance(answer, dpv1.Dpv1ErrorResponse):
            self._finish(job, error=answer, text=answer.text)
        elif isinstance(answer, dpv1.ReadResponse):
            self._finish(job, data=answer.data)
        else:
            self._finish(job, data=b"")

    def _on_status_reply(self, p: _Pending, t: Reply) -> None:
        if isinstance(t, DataTelegram) and isinstance(t.fc, ResponseFc):
            self._stations[p.address] = t.fc.station_type
        else:
            self._stations[p.address] = StationType.SLAVE

    def _invalid(self, sl: _Slave, text: str, now: float) -> None:
        """A reply that is no answer to the request: counted; the state decides what next."""
        sl.stats.invalid_replies += 1
        self.stats.invalid_replies += 1
        if sl.state is SlaveState.DATA_EXCHANGE:
            self._enter(sl, SlaveState.WAIT_DIAG, now, text)

    def _restart_bad(self, sl: _Slave, text: str, now: float) -> None:
        sl.stats.invalid_replies += 1
        self.stats.invalid_replies += 1
        self._enter(sl, SlaveState.WAIT_DIAG, now, text)

    # ------------------------------------------------------------------ diagnosis

    def _on_diag(self, sl: _Slave, diag: SlaveDiag, ext: bytes, now: float) -> None:
        sl.last_diag = diag
        self._out.append(DiagnosisRead(sl.address, diag, ext))
        _DIAG_HANDLERS.get(sl.state, Master._diag_ignored)(self, sl, diag, now)

    def _diag_ignored(self, sl: _Slave, diag: SlaveDiag, now: float) -> None:
        return

    def _diag_start(self, sl: _Slave, diag: SlaveDiag, now: float) -> None:
        """1.5 step 2: a valid diagnosis; go on with Set_Prm unless another master has it."""
        owner = diag.master_address
        if owner not in (0xFF, self.address) and not diag.prm_req:
            self._fault(sl, FaultKind.LOCKED, f"the slave is parameterised by master {owner}", now)
            return
        self._enter(sl, SlaveState.SET_PRM, now)

    def _diag_ready(self, sl: _Slave, diag: SlaveDiag, now: float) -> None:
        """1.5 step 5: ready when Not_Ready, Cfg_Fault, Prm_Fault and Prm_Req are all 0."""
        if diag.prm_fault:
            self._fault(sl, FaultKind.PRM_FAULT, self._prm_fault_text(sl, diag), now)
        elif diag.cfg_fault:
            self._enter(sl, SlaveState.GET_CFG, now)  # learn the slave's own configuration
        elif diag.not_supported:
            self._fault(
                sl,
                FaultKind.NOT_SUPPORTED,
                "Not_Supported: the slave does not support a requested function"
                + _slave_words(diag),
                now,
            )
        elif diag.prm_req:
            if sl.prm_attempts >= MAX_PRM_ATTEMPTS:
                self._fault(
                    sl,
                    FaultKind.PRM_REQ_LOOP,
                    f"the slave keeps asking for parameters (Prm_Req after "
                    f"{sl.prm_attempts} Set_Prm)",
                    now,
                )
            else:
                self._enter(sl, SlaveState.SET_PRM, now)
        elif diag.ready_for_data_exchange:
            sl.diag_pending = diag.stat_diag
            self._enter(sl, SlaveState.DATA_EXCHANGE, now)
        # Not_Ready alone: ask again next turn, until the state times out

    def _diag_exchange(self, sl: _Slave, diag: SlaveDiag, now: float) -> None:
        """A diagnosis read during data exchange (after DH/RDH, or Stat_Diag)."""
        sl.diag_pending = diag.stat_diag  # 1.8 Status_2 b1: keep reading diagnosis
        if diag.prm_req:
            self._enter(sl, SlaveState.SET_PRM, now, "the slave asks for parameters (Prm_Req)")
        elif not diag.ready_for_data_exchange:
            flags = [
                name
                for name, on in (
                    ("Station_Not_Ready", diag.station_not_ready),
                    ("Cfg_Fault", diag.cfg_fault),
                    ("Prm_Fault", diag.prm_fault),
                )
                if on
            ]
            self._enter(sl, SlaveState.WAIT_DIAG, now, f"diagnosis says {', '.join(flags)}")

    def _prm_fault_text(self, sl: _Slave, diag: SlaveDiag) -> str:
        p = sl.params
        text = (
            f"Prm_Fault: the slave refused the parameters (Ident_Number 0x{p.ident_number:04X}, "
            f"{len(p.user_prm)} bytes of user parameters"
            + (f": {p.user_prm.hex(' ').upper()})" if p.user_prm else ")")
        )
        if diag.ident_number != p.ident_number:
            text += f"; the slave reports Ident_Number 0x{diag.ident_number:04X}"
        return text + _origin(p) + _slave_words(diag)

    # ------------------------------------------------------------------ state changes

    def _fault(
        self, sl: _Slave, kind: FaultKind, text: str, now: float, slave_cfg: bytes | None = None
    ) -> None:
        changed = sl.fault != text
        sl.fault = text
        sl.retry_at = now + self.bus.fault_retry
        self._enter(sl, SlaveState.FAULT, now, text)
        if changed:
            self._out.append(SlaveFault(sl.address, kind, text, slave_cfg))

    def _enter(self, sl: _Slave, new: SlaveState, now: float, reason: str = "") -> None:
        old = sl.state
        sl.since = now
        if new is SlaveState.WAIT_DIAG:
            sl.fcb = FcbState.reset()  # 1.3: after a (re)start FCB = 1, FCV = 0
            sl.prm_attempts = 0
        if old is new:
            return
        sl.state = new
        if new in _TIMED_STATES:
            self._timed[sl.address] = sl
        else:
            self._timed.pop(sl.address, None)
        if old is SlaveState.DATA_EXCHANGE:
            sl.stats.restarts += 1
            sl.diag_pending = False
            self._out.append(SlaveDown(sl.address, reason or new.value))
            for job in list(sl.jobs):
                self._finish(job, RecordFailure.OFFLINE, f"slave {sl.address} left data exchange")
        self._out.append(SlaveStateChanged(sl.address, old, new))
        if new is SlaveState.DATA_EXCHANGE:
            sl.fault = None
            sl.turn.count = MAX_TURN  # first Data_Exchange next turn, with the caller's outputs
            self._out.append(SlaveUp(sl.address))

    def _check_state_timeout(self, sl: _Slave, now: float) -> None:
        limit = STATE_TIMEOUTS.get(sl.state)
        if limit is None or sl.state not in _TIMED_STATES:
            return
        limit = max(limit, 4 * self.bus.cycle_time, 4 * self._retry_bound())
        busy = [p.address for p in (self._pending, self._retry) if p is not None]
        if now - sl.since <= limit or sl.address in busy:
            return
        if sl.state is SlaveState.WAIT_READY:
            self._fault(
                sl,
                FaultKind.NOT_READY,
                f"the slave stays not ready {limit:g} s after Set_Prm and Chk_Cfg"
                + _slave_words(sl.last_diag),
                now,
            )
        else:
            self._enter(sl, SlaveState.WAIT_DIAG, now, f"{sl.state.value} timed out")

    def _retry_bound(self) -> float:
        return (1 + self.bus.retries) * (self.bus.reply_wait + self.bus.tx_time(MAX_TELEGRAM))

    def _finish(
        self,
        job: _Job,
        failure: RecordFailure | None = None,
        text: str = "",
        *,
        data: bytes | None = None,
        error: dpv1.Dpv1ErrorResponse | None = None,
    ) -> None:
        if self._jobs.pop(job.id, None) is None:
            return
        sl = self._slaves[job.address]
        if job in sl.jobs:
            sl.jobs.remove(job)
        for p in (self._pending, self._retry):
            if p is not None and p.job is job:
                p.job = None
        self._out.append(RecordDone(job.id, job.address, data, error, failure, text))

    def _check_jobs(self, now: float) -> None:
        for job in [j for j in self._jobs.values() if now >= j.deadline]:
            self._finish(
                job,
                RecordFailure.TIMEOUT,
                f"no DP-V1 answer from slave {job.address} within {self.bus.acyclic_timeout:g} s",
            )

    # ------------------------------------------------------------------ sending

    def _send_next(self, now: float) -> None:
        # 1.1: a request only after the line was idle TSYN (counted from the last byte
        # written or received), and only once the previous telegram was confirmed written
        if self._unwritten or now < self._busy_until or now < self._idle_since + self._tsyn:
            return
        if self._retry is not None:
            retry, self._retry = self._retry, None
            self._transmit(retry, now)
            return
        for _ in range(len(self._slaves) + 8):  # bounded: each pass ends or starts a cycle
            if self._cycle_started is None:
                if now < self._next_cycle:
                    return
                self._begin_cycle(now)
            if self._next_in_cycle(now):
                return
            self._end_cycle(now)

    def _begin_cycle(self, now: float) -> None:
        self._cycle_started = now
        self._cycle_sent = 0
        self._queue = deque(self._slaves)
        self._current = None
        self._line_done = False

    def _end_cycle(self, now: float) -> None:
        started = self._cycle_started if self._cycle_started is not None else now
        self._cycle_started = None
        if self._cycle_sent:
            self.stats.cycles += 1
            self.stats.cycle.add(now - started)
            self._next_cycle = max(now, started + self.bus.cycle_time)
        else:
            self._next_cycle = max(now + IDLE_GUARD, started + self.bus.cycle_time, self._due())

    def _due(self) -> float:
        """The earliest time something wants the line when nobody is exchanging."""
        times = [self._gc_due, self._probe_due]
        for sl in self._slaves.values():
            if sl.state in (SlaveState.ABSENT, SlaveState.FAULT):
                times.append(sl.retry_at)
            else:
                times.append(-math.inf)
        return min(times) if times else math.inf

    def _next_in_cycle(self, now: float) -> bool:
        """Transmit the next telegram of this cycle; False when the cycle is over."""
        while True:
            if self._current is not None:
                sl = self._slaves[self._current]
                purpose = _WANTS[sl.state](self, sl, now) if sl.turn.count < MAX_TURN else None
                if purpose is not None:
                    self._send_for(sl, purpose, now)
                    return True
                self._current = None
            if not self._queue:
                break
            self._start_turn()
        if not self._line_done:
            if self._line_task(now):
                return True
            self._line_done = True
        return False

    def _start_turn(self) -> _Slave:
        """The next slave of the cycle; its turn begins."""
        self._current = self._queue.popleft()
        sl = self._slaves[self._current]
        sl.turn = _Turn()
        return sl

    def _want_exchange(self, sl: _Slave, now: float) -> Purpose | None:
        turn = sl.turn
        if not turn.data:
            return Purpose.DATA
        if sl.diag_pending and not turn.diag:
            return Purpose.DIAG
        if (
            sl.jobs
            and turn.acyclic < MAX_ACYCLIC_PER_TURN
            and not turn.acyclic_wait
            and now >= sl.dpv1_hold_until
        ):
            return Purpose.POLL if sl.jobs[0].requested else Purpose.RECORD
        return None

    def _want_probe(self, sl: _Slave, now: float) -> Purpose | None:
        if sl.turn.count or now < sl.retry_at:
            return None
        if sl.state is SlaveState.FAULT:
            self._enter(sl, SlaveState.WAIT_DIAG, now, "retrying after a fault")
        return Purpose.DIAG

    def _send_for(self, sl: _Slave, purpose: Purpose, now: float) -> None:
        sl.turn.count += 1
        fc = sl.fcb.fc(RequestFunction.SRD_HIGH)
        job: _Job | None = None
        if purpose is Purpose.DATA:  # the message of every cycle: nothing else to decide
            sl.turn.data = True
            data, dsap, tries = self._data_frame(sl, fc), None, 1 + self.bus.retries
        else:
            job = self._count_in_turn(sl, purpose)
            telegram = _BUILDERS[purpose](self, sl, fc, job)
            data, dsap = telegram.encode(), telegram.dsap
            tries = 1 if sl.state is SlaveState.ABSENT else 1 + self.bus.retries
        sl.stats.requests += 1
        pending = _Pending(sl.address, purpose, data, now, now, tries, True, job=job, dsap=dsap)
        self._transmit(pending, now, fresh=True)

    def _count_in_turn(self, sl: _Slave, purpose: Purpose) -> _Job | None:
        """Note a telegram other than Data_Exchange in the slave's turn; a DP-V1 one's job."""
        turn = sl.turn
        if purpose is Purpose.DIAG and sl.state is SlaveState.DATA_EXCHANGE:
            turn.diag = True
        elif purpose is Purpose.DIAG and sl.state is SlaveState.WAIT_READY:
            turn.ready_polls += 1
        elif purpose in (Purpose.RECORD, Purpose.POLL):
            turn.acyclic += 1
            return sl.jobs[0]
        elif purpose is Purpose.SET_PRM:
            sl.prm_attempts += 1
        return None

    def _transmit(self, pending: _Pending, now: float, fresh: bool = False) -> None:
        not_before = max(now, self._idle_since + self._tsyn)
        if not fresh:
            pending.tries += 1
        pending.sent_at = not_before
        # the reply wait starts when the driver confirms the write (Written), not now
        pending.deadline = math.inf
        pending.written = False
        self._unwritten.append((len(pending.data), pending))
        self._pending = pending
        self._cycle_sent += 1
        self.stats.telegrams += 1
        self._out.append(Transmit(pending.data, not_before, True))

    def _broadcast(self, control: GlobalControl, now: float) -> None:
        data = global_control_request(control, sa=self.address).encode()
        not_before = max(now, self._idle_since + self._tsyn)
        self._unwritten.append((len(data), None))  # busy until Written + line time + TSYN
        self._cycle_sent += 1
        self.stats.telegrams += 1
        self._out.append(Transmit(data, not_before, False))

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
        if now >= self._probe_due:
            self._probe_due = now + self.bus.live_list_period
            address = self._next_probe()
            if address is not None:
                data = status_request(address, self.address)
                pending = _Pending(address, Purpose.STATUS, data, now, now, 1, False)
                self._transmit(pending, now, fresh=True)
                return True
        return False

    def _next_probe(self) -> int | None:
        for _ in range(MAX_STATION + 1):
            address = self._probe_next
            self._probe_next = (self._probe_next + 1) % (MAX_STATION + 1)
            if address != self.address and address not in self._slaves:
                return address
        return None

    # ------------------------------------------------------------------ telegrams

    def _build_diag(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        return build_request(SlaveDiagRequest(), da=sl.address, sa=self.address, fc=fc)

    def _build_set_prm(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        return DataTelegram(
            sl.address, self.address, fc, SlaveSap.SET_PRM, MasterSap.MS0, sl.set_prm
        )

    def _build_chk_cfg(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        return DataTelegram(
            sl.address, self.address, fc, SlaveSap.CHK_CFG, MasterSap.MS0, sl.params.cfg
        )

    def _build_get_cfg(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        return build_request(GetCfgRequest(), da=sl.address, sa=self.address, fc=fc)

    def _data_frame(self, sl: _Slave, fc: RequestFc) -> bytes:
        """The Data_Exchange telegram (1.5 step 6; zero outputs in Clear), kept encoded:
        the same outputs go out cycle after cycle with one of two FCB values."""
        outputs = sl.outputs if self.mode is LineMode.OPERATE else bytes(len(sl.outputs))
        sl.outputs_pending = False  # carried (in Clear: dropped, as Clear requires)
        key = (fc.fcb, fc.fcv, outputs)
        frame = sl.frames.get(key)
        if frame is None:
            if len(sl.frames) >= FRAME_MEMO:
                sl.frames.clear()
            request = build_request(DataExchange(outputs), da=sl.address, sa=self.address, fc=fc)
            frame = sl.frames[key] = request.encode()
        return frame

    def _build_record(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        if job is None:  # pragma: no cover - _send_for always passes the head job
            raise FrameEncodeError("DP-V1 request without a job")
        return dpv1.build_request(job.request, da=sl.address, sa=self.address, fc=fc)

    def _build_poll(self, sl: _Slave, fc: RequestFc, job: _Job | None) -> DataTelegram:
        return dpv1.poll_request(da=sl.address, sa=self.address, fc=fc)


# ---------------------------------------------------------------------------------------
# Tables and helpers

_SHORT_ACK_PURPOSES: Final = frozenset(
    {Purpose.SET_PRM, Purpose.CHK_CFG, Purpose.RECORD, Purpose.POLL}
)  # requests that E5 may answer (Data_Exchange: only a slave without inputs)
_DPV1_PURPOSES: Final = frozenset({Purpose.RECORD, Purpose.POLL})
_REQUEST_NAMES: Final[Mapping[Purpose, str]] = {
    Purpose.DIAG: "Slave_Diag",
    Purpose.SET_PRM: "Set_Prm",
    Purpose.CHK_CFG: "Chk_Cfg",
    Purpose.GET_CFG: "Get_Cfg",
    Purpose.DATA: "Data_Exchange",
    Purpose.RECORD: "a DP-V1 request",
    Purpose.POLL: "a DP-V1 poll",
    Purpose.STATUS: "FDL status",
}

_DATA_OK: Final = frozenset(
    {
        ResponseStatus.OK,
        ResponseStatus.DL,
        ResponseStatus.DH,
        ResponseStatus.RDL,
        ResponseStatus.RDH,
    }
)

_WANTS: Final[dict[SlaveState, Callable[[Master, _Slave, float], Purpose | None]]] = {
    SlaveState.WAIT_DIAG: lambda m, sl, now: Purpose.DIAG,
    SlaveState.SET_PRM: lambda m, sl, now: Purpose.SET_PRM,
    SlaveState.CHK_CFG: lambda m, sl, now: Purpose.CHK_CFG,
    SlaveState.WAIT_READY: lambda m, sl, now: None if sl.turn.ready_polls else Purpose.DIAG,
    SlaveState.GET_CFG: lambda m, sl, now: Purpose.GET_CFG,
    SlaveState.DATA_EXCHANGE: Master._want_exchange,
    SlaveState.ABSENT: Master._want_probe,
    SlaveState.FAULT: Master._want_probe,
}

_BUILDERS: Final[
    dict[Purpose, Callable[[Master, _Slave, RequestFc, _Job | None], DataTelegram]]
] = {
    Purpose.DIAG: Master._build_diag,
    Purpose.SET_PRM: Master._build_set_prm,
    Purpose.CHK_CFG: Master._build_chk_cfg,
    Purpose.GET_CFG: Master._build_get_cfg,
    Purpose.RECORD: Master._build_record,
    Purpose.POLL: Master._build_poll,
}

_REPLY_HANDLERS: Final[dict[Purpose, Callable[[Master, _Slave, _Pending, Reply, float], None]]] = {
    Purpose.DIAG: Master._reply_diag,
    Purpose.SET_PRM: Master._reply_ack,
    Purpose.CHK_CFG: Master._reply_ack,
    Purpose.GET_CFG: Master._reply_get_cfg,
    Purpose.DATA: Master._reply_data,
    Purpose.RECORD: Master._reply_record,
    Purpose.POLL: Master._reply_poll,
}

_DIAG_HANDLERS: Final[dict[SlaveState, Callable[[Master, _Slave, SlaveDiag, float], None]]] = {
    SlaveState.WAIT_DIAG: Master._diag_start,
    SlaveState.ABSENT: Master._diag_start,
    SlaveState.FAULT: Master._diag_start,
    SlaveState.WAIT_READY: Master._diag_ready,
    SlaveState.DATA_EXCHANGE: Master._diag_exchange,
}

_REFUSALS: Final[dict[ResponseStatus, str]] = {
    ResponseStatus.RS: "DP-V1 is not active on the slave (RS: SAP 51 not activated)",
    ResponseStatus.UE: "the slave answered UE (user error)",
    ResponseStatus.RR: "the slave has no resources (RR)",
}


def _origin(p: SlaveParams) -> str:
    """Where the bytes sent come from, when not from the profile (a GSD file and module)."""
    return f"; sent as {p.origin} says" if p.origin else ""


def _slave_words(diag: SlaveDiag | None) -> str:
    """The slave's own extended diagnosis (1.8) for a fault text, if it gave one."""
    if diag is None or not diag.blocks:
        return ""
    return f"; the slave's diagnosis: {describe_blocks(diag.blocks)}"


def _refusal_text(status: ResponseStatus | None) -> str:
    if status is None:
        return "unexpected answer"
    return _REFUSALS.get(status, f"the slave answered {status.name}")


def _status(t: Reply) -> ResponseStatus | None:
    """The response status of a reply; a short acknowledgement counts as OK."""
    if isinstance(t, ShortAck):
        return ResponseStatus.OK
    return t.fc.status if isinstance(t.fc, ResponseFc) else None


def _show(t: Reply) -> str:
    if isinstance(t, ShortAck):
        return "a short acknowledgement"
    status = _status(t)
    name = status.name if status is not None else "?"
    sap = "without SAP" if t.ssap is None else f"from SAP {t.ssap}"
    return f"{name} {sap} with {len(t.data)} bytes"


def _answers_request(pending: _Pending, t: DataTelegram, master: int) -> bool:
    """A reply from the station asked, to us, from the SAP asked (1.2: SAPs swapped)."""
    if t.sa != pending.address or t.da != master:
        return False
    if t.ssap is not None:
        return t.ssap == pending.dsap
    return pending.dsap is None or not t.data  # an acknowledgement without SAPs


def _answers(request: dpv1.ReadRequest | dpv1.WriteRequest, answer: dpv1.Dpv1Response) -> bool:
    """Whether a DP-V1 answer belongs to ``request`` (same service, slot and index)."""
    if isinstance(answer, dpv1.Dpv1ErrorResponse):
        want = (
            dpv1.Dpv1Function.READ
            if isinstance(request, dpv1.ReadRequest)
            else (dpv1.Dpv1Function.WRITE)
        )
        return answer.function is want
    if isinstance(request, dpv1.ReadRequest):
        return isinstance(answer, dpv1.ReadResponse) and (answer.slot, answer.index) == (
            request.slot,
            request.index,
        )
    return isinstance(answer, dpv1.WriteResponse) and (answer.slot, answer.index) == (
        request.slot,
        request.index,
    )
