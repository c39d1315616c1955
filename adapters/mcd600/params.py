"""Parameter read/write through the programming structure (installation guide 4.4).

The cyclic data carries one request at a time. :class:`ParamSequencer` is the sans-IO state
machine, stepped with an injected clock like the engines: :meth:`~ParamSequencer.submit`
queues a request, :meth:`~ParamSequencer.output` says what output bytes 3-6 carry this
cycle, :meth:`~ParamSequencer.step` takes the cycle's input bytes 6-9 (or the loss of
communication) with ``now`` and returns the requests that ended; a request without its
answer ``timeout`` seconds after it began ends with :class:`GatewayTimeout` at the first
step past :meth:`~ParamSequencer.next_deadline`. :class:`ParamChannel` is the thin async
wrapper the profile uses: ``transact`` awaits a request's end, stepping the sequencer at
its deadline when no bus cycle did; the profile's ``outputs()`` and ``inputs()`` feed it.

Handshake (our choice; the guide only defines the bytes): between two requests the master
sends the idle request (all zero, so the echo becomes 0). A request is sent only once the
echo differs from its number, so an echo left over from an earlier request for the same
number cannot complete it.
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum, auto

from adapters.mcd600.programming import (
    IDLE,
    INVALID_NUMBER_BIT,
    INVALID_VALUE_BIT,
    PARAM_ERROR_TEXTS,
    ParamReply,
    ParamRequest,
)
from gateway.errors import GatewayError, GatewayTimeout, ParameterError

Clock = Callable[[], float]


class _Phase(Enum):
    WAIT_CLEAR = auto()  # sending idle until the echo is not this request's number
    SEND = auto()  # sending the request until the echo is its number


@dataclass
class _Job:
    id: int
    request: ParamRequest
    phase: _Phase = _Phase.WAIT_CLEAR
    sent: bool = False
    deadline: float = 0.0  # set when the request begins (it is the one on the bus)


@dataclass(frozen=True, slots=True)
class ParamLost:
    """Communication with the starter was lost: the request in progress ends with ``error``."""

    error: GatewayError


ParamEvent = ParamReply | ParamLost


@dataclass(frozen=True, slots=True)
class ParamDone:
    """A request ended: the value the starter answered, or why not."""

    job: int
    value: int = 0  # when no error
    error: GatewayError | None = None


def reply_error(number: int, reply: ParamReply) -> ParameterError | None:
    """The starter's refusal (table 8 byte 7) as a ParameterError, or None."""
    for bit, flagged in (
        (INVALID_NUMBER_BIT, reply.invalid_number),
        (INVALID_VALUE_BIT, reply.invalid_value),
    ):
        if flagged:
            code = 1 << bit
            return ParameterError(f"parameter {number}: {PARAM_ERROR_TEXTS[code]}", code)
    return None


class ParamSequencer:
    """The parameter requests of one starter, one at a time (see the module docstring)."""

    def __init__(self, timeout: float, name: str = "MCD 600") -> None:
        self.timeout = timeout
        self.name = name
        self._current: _Job | None = None
        self._queue: deque[_Job] = deque()
        self._ids = 0

    @property
    def busy(self) -> bool:
        return self._current is not None

    def next_deadline(self) -> float | None:
        """When the request in progress times out (None: no request)."""
        return self._current.deadline if self._current is not None else None

    def submit(self, request: ParamRequest, now: float) -> int:
        """Queue a request; it begins once those before it ended. Its id."""
        self._ids += 1
        job = _Job(self._ids, request)
        if self._current is None:
            self._begin(job, now)
        else:
            self._queue.append(job)
        return job.id

    def cancel(self, job_id: int, now: float) -> None:
        """Forget a request (its caller gave up); no ParamDone follows."""
        current = self._current
        if current is not None and current.id == job_id:
            self._current = None
            if self._queue:
                self._begin(self._queue.popleft(), now)
            return
        for job in self._queue:
            if job.id == job_id:
                self._queue.remove(job)
                return

    def output(self) -> ParamRequest:
        """Output bytes 3-6 for this cycle."""
        job = self._current
        if job is None or job.phase is _Phase.WAIT_CLEAR:
            return IDLE
        job.sent = True
        return job.request

    def step(self, now: float, event: ParamEvent | None = None) -> list[ParamDone]:
        """Input bytes 6-9 of this cycle, the loss of communication, or only the time."""
        done: list[ParamDone] = []
        if isinstance(event, ParamReply):
            self._take(event, done)
        elif isinstance(event, ParamLost) and self._current is not None:
            done.append(ParamDone(self._current.id, error=event.error))
            self._current = None
        job = self._current
        if job is not None and now >= job.deadline:
            text = f"{self.name}: no answer to parameter {job.request.number} in {self.timeout:g} s"
            done.append(ParamDone(job.id, error=GatewayTimeout(text)))
            self._current = None
        if self._current is None and self._queue:
            self._begin(self._queue.popleft(), now)
        return done

    def _begin(self, job: _Job, now: float) -> None:
        job.deadline = now + self.timeout
        self._current = job

    def _take(self, reply: ParamReply, done: list[ParamDone]) -> None:
        job = self._current
        if job is None:
            return
        number = job.request.number
        if job.phase is _Phase.WAIT_CLEAR:
            if reply.echo != number:
                job.phase = _Phase.SEND
            return
        if not job.sent or reply.echo != number:
            return
        self._current = None
        error = reply_error(number, reply)
        done.append(ParamDone(job.id, reply.value, error))


class ParamChannel:
    """The async wrapper of a :class:`ParamSequencer`, stepped with ``clock``."""

    def __init__(
        self, timeout: float, name: str = "MCD 600", clock: Clock = time.monotonic
    ) -> None:
        self.timeout = timeout
        self.name = name
        self.sequencer = ParamSequencer(timeout, name)
        self._clock = clock
        self._futures: dict[int, asyncio.Future[int]] = {}

    @property
    def busy(self) -> bool:
        return self.sequencer.busy

    def output(self) -> ParamRequest:
        """Output bytes 3-6 for this cycle."""
        return self.sequencer.output()

    def take(self, reply: ParamReply) -> None:
        """Input bytes 6-9 of this cycle."""
        self._settle(self.sequencer.step(self._clock(), reply))

    def fail(self, error: GatewayError) -> None:
        """End the request in progress with ``error`` (communication lost)."""
        self._settle(self.sequencer.step(self._clock(), ParamLost(error)))

    async def transact(self, request: ParamRequest) -> int:
        """Send one request; the value the starter answers, or ParameterError/GatewayTimeout."""
        future: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        job = self.sequencer.submit(request, self._clock())
        self._futures[job] = future
        try:
            while not future.done():
                deadline = self.sequencer.next_deadline()
                delay = None if deadline is None else max(0.0, deadline - self._clock())
                await asyncio.wait([future], timeout=delay)
                if not future.done():
                    self._settle(self.sequencer.step(self._clock()))
            return future.result()
        finally:
            if self._futures.pop(job, None) is not None:
                self.sequencer.cancel(job, self._clock())  # given up (cancelled) before it ended

    def _settle(self, done: list[ParamDone]) -> None:
        for end in done:
            future = self._futures.pop(end.job, None)
            if future is None or future.done():
                continue
            if end.error is not None:
                future.set_exception(end.error)
            else:
                future.set_result(end.value)
