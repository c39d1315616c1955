"""Parameter read/write through the programming structure (installation guide 4.4).

The cyclic data carries one request at a time: :meth:`ParamChannel.transact` parks a request
and awaits a future; the profile's ``outputs()`` sends it (:meth:`ParamChannel.output`) and
its ``inputs()`` completes it (:meth:`ParamChannel.take`) when the starter echoes the number.

Handshake (our choice; the guide only defines the bytes): between two requests the master
sends the idle request (all zero, so the echo becomes 0). A request is sent only once the
echo differs from its number, so an echo left over from an earlier request for the same
number cannot complete it.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from enum import Enum, auto

from gateway.errors import GatewayError, GatewayTimeout, ParameterError

from .programming import (
    IDLE,
    INVALID_NUMBER_BIT,
    INVALID_VALUE_BIT,
    PARAM_ERROR_TEXTS,
    ParamReply,
    ParamRequest,
)


class _Phase(Enum):
    WAIT_CLEAR = auto()  # sending idle until the echo is not this request's number
    SEND = auto()  # sending the request until the echo is its number


@dataclass
class _Job:
    request: ParamRequest
    future: asyncio.Future[int]
    phase: _Phase = _Phase.WAIT_CLEAR
    sent: bool = False


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


class ParamChannel:
    def __init__(self, timeout: float, name: str = "MCD 600") -> None:
        self.timeout = timeout
        self.name = name
        self._job: _Job | None = None
        self._lock = asyncio.Lock()

    @property
    def busy(self) -> bool:
        return self._job is not None

    def output(self) -> ParamRequest:
        """Output bytes 3-6 for this cycle."""
        job = self._job
        if job is None or job.future.done():
            self._job = None
            return IDLE
        if job.phase is _Phase.WAIT_CLEAR:
            return IDLE
        job.sent = True
        return job.request

    def take(self, reply: ParamReply) -> None:
        """Input bytes 6-9 of this cycle."""
        job = self._job
        if job is None:
            return
        if job.future.done():
            self._job = None
            return
        number = job.request.number
        if job.phase is _Phase.WAIT_CLEAR:
            if reply.echo != number:
                job.phase = _Phase.SEND
            return
        if not job.sent or reply.echo != number:
            return
        self._job = None
        error = reply_error(number, reply)
        if error is not None:
            job.future.set_exception(error)
        else:
            job.future.set_result(reply.value)

    def fail(self, error: GatewayError) -> None:
        """End the request in progress with ``error`` (communication lost)."""
        job, self._job = self._job, None
        if job is not None and not job.future.done():
            job.future.set_exception(error)

    async def transact(self, request: ParamRequest) -> int:
        """Send one request; the value the starter answers, or ParameterError/GatewayTimeout."""
        async with self._lock:
            future: asyncio.Future[int] = asyncio.get_running_loop().create_future()
            job = _Job(request, future)
            self._job = job
            try:
                return await asyncio.wait_for(future, self.timeout)
            except TimeoutError:
                raise GatewayTimeout(
                    f"{self.name}: no answer to parameter {request.number} in {self.timeout:g} s"
                ) from None
            finally:
                if self._job is job:
                    self._job = None
