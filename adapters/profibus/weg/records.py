"""Parameter access to a WEG drive over DP-V1: PROFIdrive record 47 or WEG record 48.

Record 47 (CFW-11 4.2.4, CFW700 5.2.4, CFW320 5.2.4): DS_Write(slot 0, index 47, request),
then DS_Read(slot 0, index 47, 240) repeated while the drive answers "response not
available" (Error_Code_1 C3h), several parameters per request. Record 48 (CFW-11 4.2.6,
CFW700 5.2.5, CFW320 5.2.4): a read is DS_Write of the 2-byte number then DS_Read
(240 bytes asked, as in the 4.2.3 telegrams) of the 2-byte value; a change is one DS_Write
of number and value. Values are raw 16-bit words.

The sequencing is sans-IO: :class:`ParamSequence` is a state machine stepped with the
caller's clock (``step(now, event) -> access``, ``next_deadline()``): it says which DS_Write
or DS_Read comes next, takes what the channel answered, and waits ``retry_delay`` between
two DS_Reads by its deadline, never by sleeping. :class:`RecordParams` is the thin async
wrapper that performs each access on a :class:`RecordChannel` and sleeps until the deadline.

Refusals raise :class:`gateway.errors.ParameterError` with the drive's own text and code:
the record 47 error number (Table 4.2 / 5.2) or the DP-V1 Error_Code_1 (4.2.3 / 5.2.3).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum, auto
from functools import partial
from typing import Final

from adapters.profibus.codec import profidrive as pd
from adapters.profibus.codec import wegrecord
from adapters.profibus.codec.dpv1 import MAX_DATA, WEG_ERROR_CODE_1_TEXTS
from adapters.profibus.contract import RecordAccessError, RecordChannel
from gateway.errors import GatewayError, GatewayTimeout, ParameterError

RESPONSE_NOT_AVAILABLE: Final = 0xC3  # 4.2.3 Error Code 1: "resposta não disponível"
MAX_PER_REQUEST: Final = (MAX_DATA - 4) // 6  # 6-byte addresses after a 4-byte header: 39

Address = tuple[int, int]  # (parameter number, subindex)
Clock = Callable[[], float]


def record_error(exc: RecordAccessError) -> ParameterError:
    """A negative DP-V1 answer as the drive's own Error_Code_1 text (4.2.3 / 5.2.3)."""
    text = WEG_ERROR_CODE_1_TEXTS.get(exc.code_1, exc.text)
    error = ParameterError(text, exc.code_1)
    error.__cause__ = exc  # as ``raise ... from exc``
    return error


def block_error(block: pd.ValueBlock) -> ParameterError:
    """A record 47 error block as the drive's text (Table 4.2 / 5.2 "Error code")."""
    number = block.error_number or 0
    return ParameterError(pd.parameter_error_text(number, pd.WEG_PARAMETER_ERROR_TEXTS), number)


# ---------------------------------------------------------------------------------------
# What the sequence asks for, and what the channel answered


@dataclass(frozen=True, slots=True)
class WriteRecord:
    """DS_Write of ``data`` to the record."""

    slot: int
    index: int
    data: bytes


@dataclass(frozen=True, slots=True)
class ReadRecord:
    """DS_Read of up to ``length`` bytes of the record."""

    slot: int
    index: int
    length: int


RecordAccess = WriteRecord | ReadRecord


@dataclass(frozen=True, slots=True)
class RecordWritten:
    """The DS_Write was accepted."""


@dataclass(frozen=True, slots=True)
class RecordRead:
    """The DS_Read answered these bytes."""

    data: bytes


@dataclass(frozen=True, slots=True)
class RecordRefused:
    """The DS_Write or DS_Read was answered negatively."""

    error: RecordAccessError


RecordEvent = RecordWritten | RecordRead | RecordRefused


# ---------------------------------------------------------------------------------------
# The sans-IO sequence


@dataclass(frozen=True)
class Transaction:
    """One DS_Write and, when an answer is expected, DS_Reads until it is there.

    ``accept`` turns the bytes read into the values (raising the drive's refusal), or
    gives None when they are not this request's answer yet (an older request's answer).
    """

    write: WriteRecord
    read: ReadRecord | None = None
    accept: Callable[[bytes], list[int] | None] = lambda data: []
    timeout_text: str = ""


class _Phase(Enum):
    START = auto()  # the next transaction starts at the next step
    WRITING = auto()  # the DS_Write is out
    READING = auto()  # a DS_Read is out
    WAITING = auto()  # between two DS_Reads: until the deadline
    DONE = auto()


class ParamSequence:
    """The transactions of one parameter access, one after the other (module docstring).

    ``step(now, event)`` returns the next access to make (None: wait for the deadline, or
    done); ``event`` is the channel's answer to the access it returned last. When
    :attr:`done`, :attr:`values` holds what was read, or :attr:`error` why it failed.
    """

    def __init__(
        self, plan: Sequence[Callable[[], Transaction]], retries: int, retry_delay: float
    ) -> None:
        self._plan = deque(plan)  # each built when it starts (a record 47 reference then)
        self.retries = retries
        self.retry_delay = retry_delay
        self._phase = _Phase.START
        self._tx: Transaction | None = None
        self._reads = 0  # DS_Reads of the transaction that found no answer
        self._deadline: float | None = None
        self.values: list[int] = []
        self.error: GatewayError | None = None

    @property
    def done(self) -> bool:
        return self._phase is _Phase.DONE

    def next_deadline(self) -> float | None:
        """When to step again without an answer (only between two DS_Reads)."""
        return self._deadline if self._phase is _Phase.WAITING else None

    def step(self, now: float, event: RecordEvent | None = None) -> RecordAccess | None:
        try:
            return self._step(now, event)
        except GatewayError as exc:  # a refusal, an undecodable answer, a bad request
            self._finish(exc)
            return None

    def _step(self, now: float, event: RecordEvent | None) -> RecordAccess | None:
        phase = self._phase
        if phase is _Phase.START:
            return self._start()
        if phase is _Phase.WAITING:
            if self._deadline is not None and now < self._deadline:
                return None
            return self._read_again()
        tx = self._tx
        if tx is None or event is None or phase is _Phase.DONE:
            return None  # nothing outstanding: a step without news
        if isinstance(event, RecordRefused):
            return self._refused(tx, event.error, now)
        if phase is _Phase.WRITING:
            if tx.read is None:
                return self._next()
            self._phase = _Phase.READING
            return tx.read
        if isinstance(event, RecordRead):
            values = tx.accept(event.data)
            if values is not None:
                self.values += values
                return self._next()
        self._wait(now)
        return None

    def _start(self) -> RecordAccess | None:
        if not self._plan:
            self._finish(None)
            return None
        self._tx = tx = self._plan.popleft()()
        self._reads = 0
        self._phase = _Phase.WRITING
        return tx.write

    def _next(self) -> RecordAccess | None:
        self._phase = _Phase.START
        return self._start()

    def _refused(self, tx: Transaction, exc: RecordAccessError, now: float) -> RecordAccess | None:
        if self._phase is _Phase.READING and exc.code_1 == RESPONSE_NOT_AVAILABLE:
            self._wait(now)  # 4.2.4 step 3: the read must be repeated
            return None
        raise record_error(exc)

    def _wait(self, now: float) -> None:
        """No answer in this DS_Read: the next one after ``retry_delay``."""
        self._reads += 1
        self._deadline = now + self.retry_delay
        self._phase = _Phase.WAITING

    def _read_again(self) -> RecordAccess | None:
        tx = self._tx
        if tx is None or tx.read is None:  # pragma: no cover - WAITING only after a read
            return None
        self._deadline = None
        if self._reads > self.retries:
            raise GatewayTimeout(tx.timeout_text)
        self._phase = _Phase.READING
        return tx.read

    def _finish(self, error: GatewayError | None) -> None:
        self.error = error
        self._phase = _Phase.DONE
        self._deadline = None
        self._plan.clear()


# ---------------------------------------------------------------------------------------
# The async wrapper


class RecordParams:
    """Parameter access to one drive through one record (47 or 48).

    ``clock`` is the clock the sequence is stepped with (default: the running event
    loop's); the wrapper sleeps only until the sequence's deadline.
    """

    def __init__(
        self,
        record: int = 47,
        slot: int = 0,
        retries: int = 20,
        retry_delay: float = 0.02,
        clock: Clock | None = None,
    ) -> None:
        if record not in (pd.PARAMETER_INDEX, wegrecord.WEG_RECORD_INDEX):
            raise ValueError(f"parameter record {record} is neither 47 nor 48")
        self.record = record
        self.slot = slot
        self.retries = retries
        self.retry_delay = retry_delay
        self.clock = clock
        self._reference = 0

    def next_reference(self) -> int:
        """Request reference 1..255 (Table 4.1: "número entre 1 e 255"), a new one each time."""
        self._reference = self._reference % 255 + 1
        return self._reference

    # ------------------------------------------------------------------ sequences

    def reading(self, addresses: Sequence[Address]) -> ParamSequence:
        """The sequence reading raw words of several parameters (record 47: up to 39 per
        request; record 48: one at a time)."""
        plan: list[Callable[[], Transaction]]
        if self.record == wegrecord.WEG_RECORD_INDEX:
            plan = [partial(self._read_48, n, s) for n, s in addresses]
        else:
            chunks = [
                addresses[start : start + MAX_PER_REQUEST]
                for start in range(0, len(addresses), MAX_PER_REQUEST)
            ]
            plan = [partial(self._read_47, chunk) for chunk in chunks]
        return ParamSequence(plan, self.retries, self.retry_delay)

    def writing(self, number: int, raw: int, subindex: int = 0) -> ParamSequence:
        """The sequence changing one parameter to a raw word (0..65535)."""
        if self.record == wegrecord.WEG_RECORD_INDEX:
            plan = [partial(self._write_48, number, raw, subindex)]
        else:
            plan = [partial(self._write_47, number, raw, subindex)]
        return ParamSequence(plan, self.retries, self.retry_delay)

    # ------------------------------------------------------------------ public

    async def read(self, channel: RecordChannel, number: int, subindex: int = 0) -> int:
        """The raw word of one parameter."""
        return (await self.read_many(channel, [(number, subindex)]))[0]

    async def read_many(self, channel: RecordChannel, addresses: Sequence[Address]) -> list[int]:
        """Raw words of several parameters (record 47: up to 39 per request)."""
        return await self.run(channel, self.reading(addresses))

    async def write(self, channel: RecordChannel, number: int, raw: int, subindex: int = 0) -> None:
        """Change one parameter to a raw word (0..65535)."""
        await self.run(channel, self.writing(number, raw, subindex))

    async def run(self, channel: RecordChannel, sequence: ParamSequence) -> list[int]:
        """Perform ``sequence`` on ``channel``: its values, or its error raised."""
        clock = self.clock or asyncio.get_running_loop().time
        access = sequence.step(clock())
        while not sequence.done:
            if access is not None:
                event = await _perform(channel, access)
                access = sequence.step(clock(), event)
                continue
            deadline = sequence.next_deadline()
            if deadline is None:  # pragma: no cover - not done and nothing to wait for
                raise GatewayError("parameter sequence stalled")
            await asyncio.sleep(max(0.0, deadline - clock()))
            access = sequence.step(clock())
        if sequence.error is not None:
            raise sequence.error
        return sequence.values

    # ------------------------------------------------------------------ record 47

    def _read_47(self, addresses: Sequence[Address]) -> Transaction:
        request = pd.ParameterRequest.read(
            self.next_reference(), *(pd.ParameterAddress(n, s) for n, s in addresses)
        )

        def accept(data: bytes) -> list[int] | None:
            response = _response_to(request, data)
            if response is None:
                return None
            if len(response.values) != len(addresses):
                raise ParameterError(
                    f"read answer has {len(response.values)} values for {len(addresses)} parameters"
                )
            _raise_block_errors(response)
            if response.response_id != pd.ResponseId.READ_OK:
                raise ParameterError(f"unexpected answer {response.response_id.name} to a read")
            return [_first_value(block) for block in response.values]

        return self._transaction_47(request, accept)

    def _write_47(self, number: int, raw: int, sub: int) -> Transaction:
        request = pd.ParameterRequest.change(
            self.next_reference(), [(pd.ParameterAddress(number, sub), pd.ValueBlock.word(raw))]
        )

        def accept(data: bytes) -> list[int] | None:
            response = _response_to(request, data)
            if response is None:
                return None
            _raise_block_errors(response)
            if response.response_id != pd.ResponseId.CHANGE_OK:
                raise ParameterError(f"unexpected answer {response.response_id.name} to a change")
            return []

        return self._transaction_47(request, accept)

    def _transaction_47(
        self, request: pd.ParameterRequest, accept: Callable[[bytes], list[int] | None]
    ) -> Transaction:
        """Write the request, then read until the answer with its reference is there."""
        return Transaction(
            WriteRecord(self.slot, pd.PARAMETER_INDEX, request.encode()),
            ReadRecord(self.slot, pd.PARAMETER_INDEX, MAX_DATA),
            accept,
            f"no answer to parameter request {request.reference} in time",
        )

    # ------------------------------------------------------------------ record 48

    def _read_48(self, number: int, subindex: int) -> Transaction:
        _no_subindex(subindex)
        return Transaction(
            WriteRecord(self.slot, wegrecord.WEG_RECORD_INDEX, _select(number)),
            ReadRecord(self.slot, wegrecord.WEG_RECORD_INDEX, wegrecord.READ_LENGTH),
            lambda data: [wegrecord.WegValue.decode(data).value],
            f"no answer to the read of parameter {number} in time",
        )

    def _write_48(self, number: int, raw: int, sub: int) -> Transaction:
        _no_subindex(sub)
        data = wegrecord.WegWrite(number, raw).encode()
        return Transaction(WriteRecord(self.slot, wegrecord.WEG_RECORD_INDEX, data))


async def _perform(channel: RecordChannel, access: RecordAccess) -> RecordEvent:
    """One DS_Write or DS_Read on the channel, its answer as an event."""
    try:
        if isinstance(access, WriteRecord):
            await channel.write_record(access.slot, access.index, access.data)
            return RecordWritten()
        return RecordRead(await channel.read_record(access.slot, access.index, access.length))
    except RecordAccessError as exc:
        return RecordRefused(exc)


def _response_to(request: pd.ParameterRequest, data: bytes) -> pd.ParameterResponse | None:
    """The record 47 answer to ``request``; None for another request's (a stale one)."""
    response = pd.ParameterResponse.decode(data)
    return response if response.reference == request.reference else None


def _raise_block_errors(response: pd.ParameterResponse) -> None:
    for block in response.values:
        if block.is_error:
            raise block_error(block)


def _select(number: int) -> bytes:
    return wegrecord.WegSelect(number).encode()


def _no_subindex(subindex: int) -> None:
    if subindex:
        raise ParameterError("the WEG record 48 has no subindex (use param_record = 47)")


def _first_value(block: pd.ValueBlock) -> int:
    if not block.values or isinstance(block.values[0], float):
        raise ParameterError(f"answer block {block.format.name} carries no integer value")
    return int(block.values[0]) & 0xFFFF
