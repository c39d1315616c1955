"""Parameter access to a WEG drive over DP-V1: PROFIdrive record 47 or WEG record 48.

Record 47 (CFW-11 4.2.4, CFW700 5.2.4, CFW320 5.2.4): DS_Write(slot 0, index 47, request),
then DS_Read(slot 0, index 47, 240) repeated while the drive answers "response not
available" (Error_Code_1 C3h), several parameters per request. Record 48 (CFW-11 4.2.6,
CFW700 5.2.5, CFW320 5.2.4): a read is DS_Write of the 2-byte number then DS_Read
(240 bytes asked, as in the 4.2.3 telegrams) of the 2-byte value; a change is one DS_Write
of number and value. Values are raw 16-bit words.

Refusals raise :class:`gateway.errors.ParameterError` with the drive's own text and code:
the record 47 error number (Table 4.2 / 5.2) or the DP-V1 Error_Code_1 (4.2.3 / 5.2.3).
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Final

from adapters.profibus import profidrive as pd
from adapters.profibus import wegrecord
from adapters.profibus.dpv1 import MAX_DATA, WEG_ERROR_CODE_1_TEXTS
from adapters.profibus.profile import RecordAccessError, RecordChannel
from gateway.errors import GatewayTimeout, ParameterError

RESPONSE_NOT_AVAILABLE: Final = 0xC3  # 4.2.3 Error Code 1: "resposta não disponível"
MAX_PER_REQUEST: Final = (MAX_DATA - 4) // 6  # 6-byte addresses after a 4-byte header: 39

Address = tuple[int, int]  # (parameter number, subindex)


def record_error(exc: RecordAccessError) -> ParameterError:
    """A negative DP-V1 answer as the drive's own Error_Code_1 text (4.2.3 / 5.2.3)."""
    text = WEG_ERROR_CODE_1_TEXTS.get(exc.code_1, exc.text)
    return ParameterError(text, exc.code_1)


def block_error(block: pd.ValueBlock) -> ParameterError:
    """A record 47 error block as the drive's text (Table 4.2 / 5.2 "Error code")."""
    number = block.error_number or 0
    return ParameterError(pd.parameter_error_text(number, pd.WEG_PARAMETER_ERROR_TEXTS), number)


class RecordParams:
    """Parameter access to one drive through one record (47 or 48)."""

    def __init__(
        self, record: int = 47, slot: int = 0, retries: int = 20, retry_delay: float = 0.02
    ) -> None:
        if record not in (pd.PARAMETER_INDEX, wegrecord.WEG_RECORD_INDEX):
            raise ValueError(f"parameter record {record} is neither 47 nor 48")
        self.record = record
        self.slot = slot
        self.retries = retries
        self.retry_delay = retry_delay
        self._reference = 0

    def next_reference(self) -> int:
        """Request reference 1..255 (Table 4.1: "número entre 1 e 255"), a new one each time."""
        self._reference = self._reference % 255 + 1
        return self._reference

    # ------------------------------------------------------------------ public

    async def read(self, channel: RecordChannel, number: int, subindex: int = 0) -> int:
        """The raw word of one parameter."""
        return (await self.read_many(channel, [(number, subindex)]))[0]

    async def read_many(self, channel: RecordChannel, addresses: Sequence[Address]) -> list[int]:
        """Raw words of several parameters (record 47: up to 39 per request)."""
        if self.record == wegrecord.WEG_RECORD_INDEX:
            return [await self._read_48(channel, n, s) for n, s in addresses]
        out: list[int] = []
        for start in range(0, len(addresses), MAX_PER_REQUEST):
            out += await self._read_47(channel, addresses[start : start + MAX_PER_REQUEST])
        return out

    async def write(self, channel: RecordChannel, number: int, raw: int, subindex: int = 0) -> None:
        """Change one parameter to a raw word (0..65535)."""
        if self.record == wegrecord.WEG_RECORD_INDEX:
            await self._write_48(channel, number, raw, subindex)
        else:
            await self._write_47(channel, number, raw, subindex)

    # ------------------------------------------------------------------ record 47

    async def _read_47(self, channel: RecordChannel, addresses: Sequence[Address]) -> list[int]:
        request = pd.ParameterRequest.read(
            self.next_reference(), *(pd.ParameterAddress(n, s) for n, s in addresses)
        )
        response = await self._transact_47(channel, request)
        if len(response.values) != len(addresses):
            raise ParameterError(
                f"read answer has {len(response.values)} values for {len(addresses)} parameters"
            )
        for block in response.values:
            if block.is_error:
                raise block_error(block)
        if response.response_id != pd.ResponseId.READ_OK:
            raise ParameterError(f"unexpected answer {response.response_id.name} to a read")
        return [_first_value(block) for block in response.values]

    async def _write_47(self, channel: RecordChannel, number: int, raw: int, sub: int) -> None:
        request = pd.ParameterRequest.change(
            self.next_reference(), [(pd.ParameterAddress(number, sub), pd.ValueBlock.word(raw))]
        )
        response = await self._transact_47(channel, request)
        for block in response.values:
            if block.is_error:
                raise block_error(block)
        if response.response_id != pd.ResponseId.CHANGE_OK:
            raise ParameterError(f"unexpected answer {response.response_id.name} to a change")

    async def _transact_47(
        self, channel: RecordChannel, request: pd.ParameterRequest
    ) -> pd.ParameterResponse:
        """Write the request, then read until the answer with its reference is there."""
        try:
            await channel.write_record(self.slot, pd.PARAMETER_INDEX, request.encode())
        except RecordAccessError as exc:
            raise record_error(exc) from exc
        for _ in range(self.retries + 1):
            data = await self._read_ready(channel, pd.PARAMETER_INDEX, MAX_DATA)
            if data is not None:
                response = pd.ParameterResponse.decode(data)
                if response.reference == request.reference:
                    return response
            await asyncio.sleep(self.retry_delay)
        raise GatewayTimeout(f"no answer to parameter request {request.reference} in time")

    # ------------------------------------------------------------------ record 48

    async def _read_48(self, channel: RecordChannel, number: int, subindex: int) -> int:
        _no_subindex(subindex)
        try:
            await channel.write_record(self.slot, wegrecord.WEG_RECORD_INDEX, _select(number))
        except RecordAccessError as exc:
            raise record_error(exc) from exc
        for _ in range(self.retries + 1):
            data = await self._read_ready(
                channel, wegrecord.WEG_RECORD_INDEX, wegrecord.READ_LENGTH
            )
            if data is not None:
                return wegrecord.WegValue.decode(data).value
            await asyncio.sleep(self.retry_delay)
        raise GatewayTimeout(f"no answer to the read of parameter {number} in time")

    async def _write_48(self, channel: RecordChannel, number: int, raw: int, sub: int) -> None:
        _no_subindex(sub)
        data = wegrecord.WegWrite(number, raw).encode()
        try:
            await channel.write_record(self.slot, wegrecord.WEG_RECORD_INDEX, data)
        except RecordAccessError as exc:
            raise record_error(exc) from exc

    # ------------------------------------------------------------------ shared

    async def _read_ready(self, channel: RecordChannel, index: int, length: int) -> bytes | None:
        """One DS_Read; None while the drive answers C3h "response not available"."""
        try:
            return await channel.read_record(self.slot, index, length)
        except RecordAccessError as exc:
            if exc.code_1 == RESPONSE_NOT_AVAILABLE:
                return None
            raise record_error(exc) from exc


def _select(number: int) -> bytes:
    return wegrecord.WegSelect(number).encode()


def _no_subindex(subindex: int) -> None:
    if subindex:
        raise ParameterError("the WEG record 48 has no subindex (use param_record = 47)")


def _first_value(block: pd.ValueBlock) -> int:
    if not block.values or isinstance(block.values[0], float):
        raise ParameterError(f"answer block {block.format.name} carries no integer value")
    return int(block.values[0]) & 0xFFFF
