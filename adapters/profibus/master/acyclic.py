"""The acyclic job queue: DP-V1 MSAC_C1 reads and writes, their deadlines and back-off.

Fact sheet 1.10. A job is queued for a slave in data exchange that runs DP-V1; the
scheduler gives the head job of a slave at most two telegrams per turn (the request and a
first poll), and polls again in later turns until the answer is there. Each job has a
deadline (``acyclic_timeout``) and ends with exactly one :class:`RecordDone`, unless its
caller cancelled it.

A DP-V1 telegram that stays unanswered after every try does not restart the slave: its
jobs fail, DP-V1 to it is held for a back-off (:data:`DPV1_BACKOFF`, doubling), its
Data_Exchange goes on, and a :class:`SlaveFault` reports it once (again only after a DP-V1
answer came in between).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.fdl import DataTelegram, RequestFc, ResponseStatus
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.master.common import DATA_OK, Job, Pending, Reply, status_of
from adapters.profibus.master.events import (
    Action,
    FaultKind,
    Purpose,
    RecordDone,
    RecordFailure,
    SlaveFault,
    SlaveState,
)
from adapters.profibus.master.line import Line
from adapters.profibus.master.station import Station
from adapters.profibus.master.timing import BusParams
from gateway.errors import FrameEncodeError

MAX_ACYCLIC_PER_TURN: Final = 2  # DP-V1 request + first poll
DPV1_BACKOFF: Final = (1.0, 60.0)  # s: DP-V1 held after an unanswered request, doubling


@dataclass
class _Queue:
    """One slave's DP-V1 jobs, oldest first, and whether DP-V1 to it is held."""

    jobs: deque[Job] = field(default_factory=deque)
    hold_until: float = -math.inf  # DP-V1 held after an unanswered request
    backoff: float = 0.0  # the last hold, s (0: none since the last answer)
    reported: bool = False  # the unanswered DP-V1 fault was reported


class JobQueue:
    """The DP-V1 jobs of one line (see the module docstring)."""

    def __init__(self, bus: BusParams, line: Line, out: list[Action]) -> None:
        self.bus = bus
        self.line = line
        self.out = out
        self.jobs: dict[int, Job] = {}  # every job not finished, by id
        self._queues: dict[int, _Queue] = {}
        self._ids = 0

    def add_station(self, address: int) -> None:
        self._queues[address] = _Queue()

    def queued(self, address: int) -> int:
        return len(self._queues[address].jobs)

    def earliest(self) -> float | None:
        """The earliest job deadline (None: no job)."""
        return min((j.deadline for j in self.jobs.values()), default=None)

    # ------------------------------------------------------------------ commands

    def submit(
        self, station: Station, request: dpv1.ReadRequest | dpv1.WriteRequest, now: float
    ) -> int:
        """Queue a job; refused at once (a RecordDone) when the slave cannot take it."""
        request.encode()  # FrameEncodeError for a bad slot/index/length now
        self._ids += 1
        job = Job(self._ids, station.address, request, now + self.bus.acyclic_timeout)
        self.jobs[job.id] = job
        queue = self._queues[station.address]
        exchanging = station.state is SlaveState.DATA_EXCHANGE and station.params.dpv1
        if exchanging and now < queue.hold_until:
            self.finish(job, RecordFailure.TIMEOUT, self._held_text(station.address, now))
        elif exchanging:
            queue.jobs.append(job)
        else:
            why = "not in data exchange" if station.params.dpv1 else "runs without DP-V1"
            self.finish(job, RecordFailure.OFFLINE, f"slave {station.address} {why}")
        return job.id

    def cancel(self, job_id: int) -> None:
        """Forget a job (its caller gave up); no RecordDone follows."""
        job = self.jobs.pop(job_id, None)
        if job is None:
            return
        self._drop(job)

    def finish(
        self,
        job: Job,
        failure: RecordFailure | None = None,
        text: str = "",
        *,
        data: bytes | None = None,
        error: dpv1.Dpv1ErrorResponse | None = None,
    ) -> None:
        if self.jobs.pop(job.id, None) is None:
            return
        self._drop(job)
        self.out.append(RecordDone(job.id, job.address, data, error, failure, text))

    def _drop(self, job: Job) -> None:
        queue = self._queues[job.address].jobs
        if job in queue:
            queue.remove(job)
        self.line.forget_job(job)

    def expire(self, now: float) -> None:
        """End the jobs whose deadline has come."""
        for job in [j for j in self.jobs.values() if now >= j.deadline]:
            self.finish(
                job,
                RecordFailure.TIMEOUT,
                f"no DP-V1 answer from slave {job.address} within {self.bus.acyclic_timeout:g} s",
            )

    def station_left(self, station: Station) -> None:
        """The slave left data exchange: its jobs end."""
        for job in list(self._queues[station.address].jobs):
            self.finish(job, RecordFailure.OFFLINE, f"slave {station.address} left data exchange")

    # ------------------------------------------------------------------ scheduling

    def want(self, station: Station, now: float) -> Purpose | None:
        """The slave's next DP-V1 telegram in this turn, if it is its head job's turn."""
        queue = self._queues[station.address]
        turn = station.turn
        if (
            queue.jobs
            and turn.acyclic < MAX_ACYCLIC_PER_TURN
            and not turn.acyclic_wait
            and now >= queue.hold_until
        ):
            return Purpose.POLL if queue.jobs[0].requested else Purpose.RECORD
        return None

    def head(self, address: int) -> Job:
        return self._queues[address].jobs[0]

    def request(
        self, purpose: Purpose, station: Station, fc: RequestFc, job: Job | None
    ) -> DataTelegram:
        """The DP-V1 telegram of ``job``: its request, or a poll for its answer."""
        master = self.bus.master_address
        if purpose is Purpose.POLL:
            return dpv1.poll_request(da=station.address, sa=master, fc=fc)
        if job is None:  # pragma: no cover - the scheduler always passes the head job
            raise FrameEncodeError("DP-V1 request without a job")
        return dpv1.build_request(job.request, da=station.address, sa=master, fc=fc)

    # ------------------------------------------------------------------ the line's answers

    def unanswered(self, station: Station, pending: Pending, now: float) -> None:
        """A DP-V1 telegram unanswered after every try (1.10): the slave keeps its data
        exchange (the next Data_Exchange tells whether it is still there); DP-V1 to it is
        held for a back-off; the fault is reported once."""
        queue = self._queues[station.address]
        low, high = DPV1_BACKOFF
        queue.backoff = min(2 * queue.backoff, high) if queue.backoff else low
        queue.hold_until = now + queue.backoff
        tries = pending.max_tries
        text = (
            f"slave {station.address} left a DP-V1 {pending.purpose.value} (MSAC_C1) "
            f"unanswered after {tries} {'try' if tries == 1 else 'tries'}; data exchange "
            f"goes on, DP-V1 held for {queue.backoff:g} s"
        )
        for job in list(queue.jobs):
            self.finish(job, RecordFailure.TIMEOUT, text)
        if not queue.reported:
            queue.reported = True
            self.out.append(SlaveFault(station.address, FaultKind.DPV1_UNANSWERED, text))

    def _held_text(self, address: int, now: float) -> str:
        queue = self._queues[address]
        return (
            f"DP-V1 to slave {address} is held for {queue.hold_until - now:.1f} s more: "
            "it left a DP-V1 request unanswered"
        )

    def on_reply(self, station: Station, pending: Pending, t: Reply, now: float) -> None:
        """The answer to a DP-V1 request or poll."""
        _REPLY_HANDLERS[pending.purpose](self, station, pending, t, now)

    def _answered(self, address: int) -> None:
        queue = self._queues[address]
        queue.backoff = 0.0
        queue.reported = False

    def _reply_record(self, station: Station, p: Pending, t: Reply, now: float) -> None:
        self._answered(station.address)
        job = p.job
        if job is None:
            return  # cancelled meanwhile
        status = status_of(t)
        if isinstance(t, DataTelegram) and t.data and status in DATA_OK:
            self._record_answer(station, job, bytes(t.data))
        elif status in (ResponseStatus.OK, ResponseStatus.DL, ResponseStatus.NR):
            job.requested = True  # accepted: poll for the answer (1.10 "Getting the reply")
        elif status is ResponseStatus.RR:
            station.turn.acyclic_wait = True  # no resources now: ask again next turn
        else:
            self.finish(job, RecordFailure.REFUSED, _refusal_text(status))

    def _reply_poll(self, station: Station, p: Pending, t: Reply, now: float) -> None:
        self._answered(station.address)
        job = p.job
        if job is None:
            return
        status = status_of(t)
        if isinstance(t, DataTelegram) and t.data and status in DATA_OK:
            self._record_answer(station, job, bytes(t.data))
        elif status in (ResponseStatus.OK, ResponseStatus.DL, ResponseStatus.NR):
            station.turn.acyclic_wait = True  # not ready yet
        else:
            self.finish(job, RecordFailure.REFUSED, _refusal_text(status))

    def _record_answer(self, station: Station, job: Job, data: bytes) -> None:
        try:
            answer = dpv1.decode_response(data)
        except ProfibusDecodeError as exc:
            station.figures.invalid_replies += 1
            self.finish(job, RecordFailure.BAD_REPLY, f"undecodable DP-V1 answer: {exc.message}")
            return
        if not _answers(job.request, answer):
            station.figures.invalid_replies += 1  # a stale answer to an older request: poll on
            job.requested = True
            station.turn.acyclic_wait = True
            return
        if isinstance(answer, dpv1.Dpv1ErrorResponse):
            self.finish(job, error=answer, text=answer.text)
        elif isinstance(answer, dpv1.ReadResponse):
            self.finish(job, data=answer.data)
        else:
            self.finish(job, data=b"")


# ---------------------------------------------------------------------------------------
# Tables and helpers

_ReplyHandler = Callable[[JobQueue, Station, Pending, Reply, float], None]
_REPLY_HANDLERS: Final[dict[Purpose, _ReplyHandler]] = {
    Purpose.RECORD: JobQueue._reply_record,
    Purpose.POLL: JobQueue._reply_poll,
}

_REFUSALS: Final[dict[ResponseStatus, str]] = {
    ResponseStatus.RS: "DP-V1 is not active on the slave (RS: SAP 51 not activated)",
    ResponseStatus.UE: "the slave answered UE (user error)",
    ResponseStatus.RR: "the slave has no resources (RR)",
}


def _refusal_text(status: ResponseStatus | None) -> str:
    if status is None:
        return "unexpected answer"
    return _REFUSALS.get(status, f"the slave answered {status.name}")


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
