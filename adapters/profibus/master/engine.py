"""The Profibus DP class-1 master engine: the composition of its parts, stepped with a clock.

``Master.step(now, event) -> actions``: events are what the line delivered (a decoded
telegram, garbage, bytes still arriving, the confirmation of a write); actions are
telegrams to transmit (each with the earliest time it may go out) and what happened to
the slaves (reached data exchange, left it, inputs, diagnosis, faults, DP-V1 results).
Between steps, :meth:`Master.next_deadline` says when to step again if nothing arrives.
Commands (outputs, DP-V1 jobs, Global_Control, line mode) are plain method calls; the
caller steps afterwards to get them going.

A step hands each event to the part it concerns: the line (:class:`.line.Line`) takes
confirmations and noise and matches a reply to the request on the line; the reply then
goes to its station (:class:`.station.Station`) or, for DP-V1, to the job queue
(:class:`.acyclic.JobQueue`); deadlines are looked at (jobs, the reply wait, start-up
states); and when the line is free the scheduler (:class:`.scheduler.Scheduler`) sends
what comes next.

The steady case (a plain reply to a Data_Exchange, nothing else waiting, the next turn a
Data_Exchange too) takes a short path from reply to request; a property test runs it and
the general path on the same lines and finds every telegram, action and counter equal.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from adapters.link.ringplan import RingPlan, RingResult
from adapters.profibus.codec import dpv1
from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.codec.fdl import (
    DataTelegram,
    FcbState,
    ResponseFc,
    ResponseStatus,
    ShortAck,
    TokenTelegram,
)
from adapters.profibus.errors import FdlDecodeError
from adapters.profibus.master.acyclic import JobQueue
from adapters.profibus.master.common import DPV1_PURPOSES, SHORT_ACK_PURPOSES, Pending
from adapters.profibus.master.events import (
    Action,
    Event,
    FrameIn,
    LineMode,
    LineNoise,
    Purpose,
    SlaveParams,
    SlaveState,
    Transmit,
    Written,
    check_slave,
)
from adapters.profibus.master.figures import LineFigures, SlaveFigures
from adapters.profibus.master.line import Line
from adapters.profibus.master.ring import SteadyRing
from adapters.profibus.master.scheduler import Scheduler
from adapters.profibus.master.station import Station, StationContext
from adapters.profibus.master.timing import BusParams
from gateway.errors import FrameEncodeError


class Master:
    """A DP class-1 master for the slaves of one line (see the module docstring)."""

    def __init__(self, bus: BusParams, slaves: Iterable[SlaveParams], now: float = 0.0) -> None:
        self.bus = bus
        self.address = bus.master_address
        self.figures = LineFigures()
        self._out: list[Action] = []
        self._line = Line(bus, self.figures, self._out, now)
        self._acyclic = JobQueue(bus, self._line, self._out)
        self._jobs = self._acyclic.jobs  # the unfinished DP-V1 jobs (looked at every step)
        context = StationContext(bus, self._out, self.figures, self._acyclic.station_left)
        self._timed = context.timed  # stations in a start-up state with a timeout
        self._slaves: dict[int, Station] = {}
        for params in sorted(slaves, key=lambda s: s.address):
            check_slave(params, self.address)
            if params.address in self._slaves:
                raise FrameEncodeError(f"slave address {params.address} configured twice")
            self._slaves[params.address] = Station(params, context, now)
            self._acyclic.add_station(params.address)
        self._scheduler = Scheduler(
            bus, self._slaves, self._line, self._acyclic, now, context=context
        )
        self._ring = SteadyRing(self._line, self._slaves, self._scheduler, self._out)
        self._stopped = False
        # a steady reply was taken while the line was not free yet (TSYN): the next turn,
        # once it is, is the steady one unless an event comes first (see _steady_turn)
        self._steady_due = False

    @property
    def mode(self) -> LineMode:
        """Operate or Clear (1.9)."""
        return self._scheduler.mode

    # ------------------------------------------------------------------ views

    def slave_params(self) -> tuple[SlaveParams, ...]:
        """What each slave is sent at start-up (Set_Prm, Chk_Cfg), by address."""
        return tuple(sl.params for sl in self._slaves.values())

    @property
    def addresses(self) -> tuple[int, ...]:
        return tuple(self._slaves)

    def state_of(self, address: int) -> SlaveState:
        return self._slave(address).state

    def slave_figures(self, address: int) -> SlaveFigures:
        return self._slave(address).figures

    def fault_of(self, address: int) -> str | None:
        return self._slave(address).fault

    def live_list(self) -> list[int]:
        """Stations that answered lately: configured slaves not absent, and probed ones."""
        live = {a for a, s in self._slaves.items() if s.state is not SlaveState.ABSENT}
        return sorted(live | set(self._scheduler.probed))

    def slave_diagnostics(self, address: int) -> dict[str, Any]:
        sl = self._slave(address)
        return {
            "address": address,
            "state": sl.state.value,
            "fault": sl.fault,
            "jobs_queued": self._acyclic.queued(address),
            **sl.figures.to_json(),
        }

    def line_diagnostics(self) -> dict[str, Any]:
        return {
            "mode": self.mode.value,
            "baudrate": self.bus.baudrate,
            "master_address": self.address,
            **self.figures.to_json(),
            "live_list": self.live_list(),
        }

    def _slave(self, address: int) -> Station:
        try:
            return self._slaves[address]
        except KeyError:
            raise KeyError(f"no slave {address} on this line") from None

    # ------------------------------------------------------------------ commands

    def set_outputs(self, address: int, data: bytes) -> None:
        """The outputs for the slave's next Data_Exchange (its configured length)."""
        self._slave(address).set_outputs(data)

    def outputs_pending(self, address: int) -> bool:
        """Outputs were given that no Data_Exchange has carried yet.

        A reply's inputs may come before the next telegram to that slave is built (when
        it is built later, at the cycle time); a caller that computes outputs on every
        reply skips one while this is true, so that none it computed (a one-telegram
        pulse, say) is replaced before it went out.
        """
        return self._slave(address).outputs_pending

    def quiet_inputs(self, address: int, quiet: bool) -> None:
        """``quiet``: the slave's unchanged inputs need not be reported on every reply,
        only when they change and every :data:`~.station.INPUTS_REFRESH` s; False: the
        next reply's inputs are reported, and every one after until quiet again."""
        self._slave(address).quiet = quiet

    def set_mode(self, mode: LineMode, now: float) -> None:
        """Operate or Clear; the new Global_Control goes out at the end of this cycle."""
        self._scheduler.set_mode(mode, now)

    def global_control(self, control: GlobalControl) -> None:
        """A one-shot Global_Control (Sync, Freeze...) at the end of this cycle (1.9)."""
        self._scheduler.global_control(control)

    def read_record(self, address: int, slot: int, index: int, length: int, now: float) -> int:
        """Queue a DP-V1 read (1.10); the result comes as :class:`RecordDone`."""
        request = dpv1.ReadRequest(slot, index, length)
        return self._acyclic.submit(self._slave(address), request, now)

    def write_record(self, address: int, slot: int, index: int, data: bytes, now: float) -> int:
        request = dpv1.WriteRequest(slot, index, bytes(data))
        return self._acyclic.submit(self._slave(address), request, now)

    def cancel_record(self, job_id: int) -> None:
        """Forget a job (its caller gave up); no RecordDone follows."""
        self._acyclic.cancel(job_id)

    def reset(self, now: float) -> list[Action]:
        """Start every slave up again (the port was reopened): nothing is outstanding."""
        self._steady_due = False
        self._line.reset(now)
        for sl in self._slaves.values():
            sl.enter(SlaveState.WAIT_DIAG, now, "the serial port was reopened")
        self._scheduler.reset(now)
        return self._take()

    def restart(self, address: int, now: float, reason: str) -> list[Action]:
        """Take one slave out of data exchange and start it up again (Slave_Diag, Set_Prm,
        Chk_Cfg): a slave that takes a parameter only without cyclic data (WEG P0741)
        is parameterised again. Its SlaveDown and state changes are returned."""
        self._slave(address).enter(SlaveState.WAIT_DIAG, now, reason)
        return self._take()

    def leave(self, now: float) -> list[Transmit]:
        """Leave the line: Global_Control Clear to everyone, twice (SDN is unacknowledged)."""
        self._stopped = True
        self._scheduler.mode = LineMode.CLEAR
        return self._line.leave(now)

    def count_noise(self, error: FdlDecodeError, address: int | None = None) -> None:
        """Count undecodable bytes (line level, and for ``address`` if given)."""
        sl = self._slaves.get(address) if address is not None else None
        self._line.count_noise(error, sl.figures if sl is not None else None)

    # ------------------------------------------------------------------ stepping

    def step(self, now: float, event: Event | None = None) -> list[Action]:
        if self._stopped:
            return []
        if event is not None:
            self._steady_due = False
            if type(event) is FrameIn and self._steady_reply(event.telegram, now, event.raw):
                return self._take()
            self._on_event(event, now)
        elif self._steady_due and self._steady_turn(now):
            return self._take()
        if self._jobs:
            self._acyclic.expire(now)
        line = self._line
        if line.pending is not None and now >= line.pending.deadline:
            self._on_timeout(line.pending, now)
        if self._timed:  # slaves in start-up only: nothing to do per step in data exchange
            busy = line.busy_with()
            for sl in list(self._timed.values()):
                sl.check_timeout(now, busy)
        if line.pending is None:
            self._scheduler.send_next(now)
        return self._take()

    def next_deadline(self) -> float | None:
        """When to step again if nothing arrives (None: only after a command)."""
        if self._stopped:
            return None
        line = self._line
        if line.unwritten:  # the line is ours until the driver confirms the write
            return self._acyclic.earliest()
        if line.pending is not None:
            return line.pending.deadline
        line_free = max(line.busy_until, line.idle_since + line.tsyn)
        if line.retry is not None:
            return line_free
        # in a cycle (after a broadcast): go on when the line is free; else the next cycle
        scheduler = self._scheduler
        base = line.busy_until if scheduler.cycle_started is not None else scheduler.next_cycle
        if self._jobs:  # (twice per message: no list built when no DP-V1 job waits)
            base = min(base, *(j.deadline for j in self._jobs.values()))
        return max(line_free, base)

    def awaiting_reply(self) -> bool:
        """A request is on the line (confirmed written) and its reply deadline runs."""
        return self._line.awaiting_reply()

    def _take(self) -> list[Action]:
        out = self._out  # shared with the parts: emptied, never replaced
        taken = out[:]
        del out[:]
        return taken

    # ------------------------------------------------------------------ events

    def _on_event(self, event: Event, now: float) -> None:
        line = self._line
        if isinstance(event, Written):
            line.on_written(event.at)
            return
        # 1.1: any byte on the line restarts the idle time before the next request
        line.heard(now)
        if isinstance(event, FrameIn):
            self._on_received(event.telegram, now)
        elif isinstance(event, LineNoise):
            pending = line.pending
            self.count_noise(event.error, pending.address if pending is not None else None)
            line.garbled(now)
        else:  # Receiving: the rest of a telegram is on its way
            line.receiving(now)

    def _on_received(self, telegram: DataTelegram | ShortAck | TokenTelegram, now: float) -> None:
        pending = self._line.pending
        if isinstance(telegram, DataTelegram) and telegram.is_request:
            return  # our own echo (half-duplex converters) or another station's request
        if pending is None or not pending.written or isinstance(telegram, TokenTelegram):
            self.figures.unexpected += 1
            return
        if isinstance(telegram, DataTelegram) and not _answers_request(
            pending, telegram, self.address
        ):
            self.figures.unexpected += 1  # e.g. a late reply to an earlier request
            return
        if isinstance(telegram, ShortAck) and not self._takes_short_ack(pending):
            self.figures.unexpected += 1  # E5 has no address: a late answer to another request
            return
        self._line.end_request(now)
        if pending.purpose is Purpose.STATUS:
            self._scheduler.on_status_reply(pending, telegram)
            return
        sl = self._slaves[pending.address]
        sl.answered(pending, now)
        if pending.purpose in DPV1_PURPOSES:
            self._acyclic.on_reply(sl, pending, telegram, now)
        else:
            sl.on_reply(pending, telegram, now)

    def _takes_short_ack(self, pending: Pending) -> bool:
        """Whether E5 may answer ``pending`` (1.2: an acknowledgement without data)."""
        if pending.purpose is Purpose.DATA:
            return self._slaves[pending.address].params.input_len == 0
        return pending.purpose in SHORT_ACK_PURPOSES

    def _steady_reply(self, t: object, now: float, raw: bytes = b"") -> bool:
        """The steady case of data exchange on a short path; False (nothing changed) else.

        A DL reply without SAPs, with the configured inputs, to a Data_Exchange, while no
        DP-V1 job, diagnosis or start-up is waiting: the slave's turn is over (1.5 step 6)
        and, most often, the next slave's Data_Exchange goes out. The general path
        (``_on_event``, then the scheduler) does the same with every case in view; this
        one keeps the turnaround short (a test runs both on the same lines and compares).
        """
        line = self._line
        p = line.pending
        sl = self._steady_slave(p, t)
        if p is None or sl is None or not isinstance(t, DataTelegram):
            return False
        line.pending = None  # line.end_request(now), inline on the path of every reply
        line.idle_since = max(line.idle_since, now)
        sl.answered(p, now)
        sl.took_inputs(bytes(t.data), now)
        sl.steady_reply = raw
        if line.unwritten or now < line.busy_until or now < line.idle_since + line.tsyn:
            # the line is not free yet (with TSYN > 0, always: its idle time starts at this
            # reply), and the scheduler would send nothing: the step at that deadline takes
            # the short path (_steady_turn)
            self._steady_due = True
            return True
        scheduler = self._scheduler
        if not scheduler.steady_next(now):
            scheduler.send_next(now)
        return True

    def lane(self, data: bytes, now: float, horizon: float = math.inf) -> list[Action] | None:
        """The steady exchange by its bytes: a reply identical to the slave's last plain
        Data_Exchange reply taken whole, from a slave whose caller is quiet
        (:meth:`quiet_inputs`) and whose inputs are not due, while nothing else waits. It is
        taken as :meth:`step` would take it (the turn ends, its inputs unchanged and not
        reported) without decoding it, and the next turn is built for the moment the line
        is free (TSYN after the reply), as the step at that deadline would build it, when
        that moment is within ``horizon`` s (the caller waits that long without taking
        anything else: a command cannot come between; later, the step at the deadline
        builds it). The
        actions, as :meth:`step` returns them; None: not such a reply, nothing changed (step
        it). A property test runs the lane and the steps on the same lines and finds every
        telegram and counter equal (docs/decisions/0096)."""
        line = self._line
        p = line.data_exchange_on_line()
        if p is None or self._jobs or self._timed or self._stopped:
            return None
        sl = self._slaves[p.address]
        if not sl.quiet or data != sl.steady_reply or now >= sl.inputs_due or sl.diag_pending:
            return None
        line.pending = None
        line.idle_since = max(line.idle_since, now)
        sl.answered(p, now)
        sl.figures.exchanges += 1
        free = max(line.busy_until, line.idle_since + line.tsyn)
        if free - now > horizon:
            self._steady_due = True  # the step at that deadline takes the short path
            return self._take()
        self._steady_due = not self._scheduler.steady_next(free)
        return self._take()

    def ring_plan(self, now: float, horizon: float) -> RingPlan | None:
        """The steady ring from the Data_Exchange on the line (:mod:`.ring`): the cycle's
        next steady exchanges as bytes, none of them sent for after ``horizon``; None
        when anything else waits or there is nothing to gain."""
        if self._jobs or self._timed or self._stopped:
            return None
        return self._ring.plan(now, horizon)

    def ring_done(self, result: RingResult) -> list[Action]:
        """Enter what the ring of the last plan did (as a step enters each steady reply);
        after a taken reply with the line free, the next turn is the steady one. The
        actions: the inputs whose refresh fell due during the ring (never a request)."""
        self._steady_due = self._ring.enter(result)
        return self._take()

    def _steady_turn(self, now: float) -> bool:
        """A step without an event after a steady reply, nothing else having happened but
        time passing and commands: the next Data_Exchange on the short path if the line
        is free now; False (the general path decides) else. A command that wants more
        than the next turn (a DP-V1 job, a start-up timeout) sends it to the general path;
        Global_Control and the line tasks are the scheduler's own checks."""
        line = self._line
        if self._jobs or self._timed or line.pending is not None or line.retry is not None:
            self._steady_due = False
            return False
        if line.unwritten or now < line.busy_until or now < line.idle_since + line.tsyn:
            return False  # not free yet: a later step tries again
        self._steady_due = False
        return self._scheduler.steady_next(now)

    def _steady_slave(self, p: Pending | None, t: object) -> Station | None:
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

    def _on_timeout(self, pending: Pending, now: float) -> None:
        self._line.end_request(now)
        if pending.purpose is Purpose.STATUS:  # a live-list probe: silence is an answer
            self._scheduler.probed.pop(pending.address, None)
            return
        sl = self._slaves[pending.address]
        counters: list[LineFigures | SlaveFigures] = [self.figures, sl.figures]
        if pending.tries < pending.max_tries:
            for c in counters:
                c.retries += 1
            self._line.retry = pending  # repeated once the line was idle TSYN (1.1)
            return
        for c in counters:
            c.timeouts += 1
        sl.fcb = FcbState.reset()
        if pending.purpose in DPV1_PURPOSES and sl.state is SlaveState.DATA_EXCHANGE:
            self._acyclic.unanswered(sl, pending, now)
            return
        sl.gave_up(pending, now)


def _answers_request(pending: Pending, t: DataTelegram, master: int) -> bool:
    """A reply from the station asked, to us, from the SAP asked (1.2: SAPs swapped)."""
    if t.sa != pending.address or t.da != master:
        return False
    if t.ssap is not None:
        return t.ssap == pending.dsap
    return pending.dsap is None or not t.data  # an acknowledgement without SAPs
