"""The simulated drive's DP-V1 parameter records: PROFIdrive record 47 and WEG record 48
(CFW-11 4.2.3-4.2.6, CFW700 and CFW320 5.2.3-5.2.5), with the manuals' errors.

Record 47 checks a request at DS_Write and answers it at the next DS_Read (busy, C3h,
for the drive's ``busy_reads`` reads first); record 48 selects a parameter with 2 bytes
and changes one with 4, a DS_Read answers the selected one. Both read and change the
drive's parameters as any other source does (:class:`Parameters`).
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import Enum
from typing import Final, Protocol

from adapters.profibus.codec import profidrive as pd
from adapters.profibus.codec import wegrecord
from adapters.profibus.codec.dpv1 import WEG_ERROR_CODE_1_TEXTS
from adapters.profibus.contract import RecordAccessError
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.weg.sim.params import ParamSpec

# DP-V1 Error_Code_1 (CFW-11 4.2.3, CFW700 5.2.3, CFW320 5.2.3).
E_SLOT: Final = 0xB0
E_INDEX: Final = 0xB2
E_NOT_ALLOWED: Final = 0xB5
E_READ_ONLY: Final = 0xB6
E_VALUES: Final = 0xB7
E_PARAMETER: Final = 0xB8
E_NOT_AVAILABLE: Final = 0xC3

# Record 47 error numbers (Table 4.2 / 5.2).
PD_NO_PARAMETER: Final = 0x0000
PD_READ_ONLY: Final = 0x0001
PD_LIMITS: Final = 0x0002
PD_SUBINDEX: Final = 0x0003
PD_NO_ARRAY: Final = 0x0004
PD_FORMAT: Final = 0x0005
PD_NO_DESCRIPTION: Final = 0x0009
PD_NO_TEXT: Final = 0x000F
PD_ACCESS: Final = 0x0016
PD_VALUE_COUNT: Final = 0x0018


class Refusal(Enum):
    """Why the drive refuses a parameter change."""

    NO_PARAMETER = "no parameter"
    READ_ONLY = "read-only"
    LIMITS = "out of limits"
    RUNNING = "CFG parameter while running"


REFUSAL_47: Final[Mapping[Refusal, int]] = {
    Refusal.NO_PARAMETER: PD_NO_PARAMETER,
    Refusal.READ_ONLY: PD_READ_ONLY,
    Refusal.LIMITS: PD_LIMITS,
    Refusal.RUNNING: PD_ACCESS,  # Table 4.2 has no "state" error: "incorrect access"
}
REFUSAL_48: Final[Mapping[Refusal, int]] = {
    Refusal.NO_PARAMETER: E_PARAMETER,
    Refusal.READ_ONLY: E_READ_ONLY,
    Refusal.LIMITS: E_VALUES,
    Refusal.RUNNING: E_NOT_ALLOWED,  # "modification not allowed for the parameter"
}


def access_error(code_1: int) -> RecordAccessError:
    return RecordAccessError(WEG_ERROR_CODE_1_TEXTS.get(code_1, f"{code_1:02X}h"), code_1)


class Parameters(Protocol):
    """What the records read and change of the drive."""

    @property
    def table(self) -> Mapping[int, ParamSpec]: ...

    @property
    def busy_reads(self) -> int: ...

    def param(self, number: int, subindex: int = 0) -> int: ...

    def write_param(self, number: int, raw: int) -> Refusal | None: ...


class SimRecord(Protocol):
    """One parameter record's DS_Write and DS_Read (slot 0)."""

    def write(self, data: bytes) -> None: ...

    def read(self, length: int) -> bytes: ...


class Record48:
    """WEG record 48 (4.2.6 / 5.2.5 / 5.2.4): 2 bytes select, 4 bytes change."""

    def __init__(self, drive: Parameters) -> None:
        self.drive = drive
        self._selected: int | None = None

    def write(self, data: bytes) -> None:
        try:
            request = wegrecord.decode_write_data(data)
        except ProfibusDecodeError:
            raise access_error(E_VALUES) from None
        if isinstance(request, wegrecord.WegSelect):
            if request.number not in self.drive.table:
                raise access_error(E_PARAMETER)
            self._selected = request.number
            return
        refusal = self.drive.write_param(request.number, request.value)
        if refusal is not None:
            raise access_error(REFUSAL_48[refusal])

    def read(self, length: int) -> bytes:
        if self._selected is None:
            raise access_error(E_NOT_AVAILABLE)
        return wegrecord.WegValue(self.drive.param(self._selected)).encode()[:length]


class Record47:
    """PROFIdrive record 47 (4.2.4 / 5.2.4): checked, then answered at the next read."""

    def __init__(self, drive: Parameters) -> None:
        self.drive = drive
        self._pending: bytes | None = None
        self._busy_left = 0

    def write(self, data: bytes) -> None:
        try:
            request = pd.ParameterRequest.decode(data)
        except ProfibusDecodeError:
            raise access_error(E_VALUES) from None
        if request.request_id is pd.RequestId.READ:
            response = self._read(request)
        else:
            response = self._change(request)
        self._pending = response.encode()
        self._busy_left = self.drive.busy_reads

    def read(self, length: int) -> bytes:
        if self._pending is None or self._busy_left > 0:
            self._busy_left = max(0, self._busy_left - 1)
            raise access_error(E_NOT_AVAILABLE)
        data, self._pending = self._pending, None
        return data[:length]

    def _read(self, request: pd.ParameterRequest) -> pd.ParameterResponse:
        blocks = [self._read_block(a) for a in request.parameters]
        failed = any(b.is_error for b in blocks)
        rid = pd.ResponseId.READ_ERROR if failed else pd.ResponseId.READ_OK
        return pd.ParameterResponse(
            request.reference, rid, len(blocks), tuple(blocks), request.axis
        )

    def _read_block(self, a: pd.ParameterAddress) -> pd.ValueBlock:
        if a.attribute is pd.Attribute.DESCRIPTION:
            return pd.ValueBlock.error(PD_NO_DESCRIPTION)
        if a.attribute is pd.Attribute.TEXT:
            return pd.ValueBlock.error(PD_NO_TEXT)
        p = self.drive.table.get(a.number)
        if p is None:
            return pd.ValueBlock.error(PD_NO_PARAMETER)
        count = max(1, a.elements)
        param = self.drive.param
        if p.array:
            if a.subindex + count > p.array:
                return pd.ValueBlock.error(PD_SUBINDEX)
            return pd.ValueBlock.word(*(param(a.number, a.subindex + i) for i in range(count)))
        if a.subindex:
            return pd.ValueBlock.error(PD_SUBINDEX)
        if count > 1:
            return pd.ValueBlock.error(PD_NO_ARRAY)
        return pd.ValueBlock.word(param(a.number))

    def _change(self, request: pd.ParameterRequest) -> pd.ParameterResponse:
        codes = [
            self._change_one(a, v) for a, v in zip(request.parameters, request.values, strict=True)
        ]
        n = len(codes)
        if all(c is None for c in codes):
            return pd.ParameterResponse.change_ok(request.reference, n, request.axis)
        blocks = tuple(
            pd.ValueBlock(pd.DataFormat.ZERO) if c is None else pd.ValueBlock.error(c)
            for c in codes
        )
        # The manuals' negative change answer (CFW-11 4.2.5, CFW320 5.2.5) declares 2
        # parameters for a one-parameter change: the simulator answers exactly that.
        count = 2 if n == 1 else n
        return pd.ParameterResponse(
            request.reference, pd.ResponseId.CHANGE_ERROR, count, blocks, request.axis
        )

    def _change_one(self, a: pd.ParameterAddress, v: pd.ValueBlock) -> int | None:
        if a.attribute is not pd.Attribute.VALUE:
            return PD_ACCESS
        p = self.drive.table.get(a.number)
        if p is None:
            return PD_NO_PARAMETER
        if p.array:
            return PD_READ_ONLY if a.subindex < p.array else PD_SUBINDEX
        if a.subindex:
            return PD_SUBINDEX
        if a.elements > 1:
            return PD_NO_ARRAY
        if v.format is not pd.DataFormat.WORD:
            return PD_FORMAT  # "the value 42h (16 bit word) must be used"
        if len(v.values) != 1:
            return PD_VALUE_COUNT
        refusal = self.drive.write_param(a.number, int(v.values[0]))
        return None if refusal is None else REFUSAL_47[refusal]


class Records:
    """The drive's parameter records by index (slot 0), as at power-up: nothing pending,
    nothing selected."""

    def __init__(self, drive: Parameters) -> None:
        self._by_index: dict[int, SimRecord] = {
            pd.PARAMETER_INDEX: Record47(drive),
            wegrecord.WEG_RECORD_INDEX: Record48(drive),
        }

    def write(self, slot: int, index: int, data: bytes) -> None:
        self._at(slot, index).write(data)

    def read(self, slot: int, index: int, length: int) -> bytes:
        return self._at(slot, index).read(length)

    def _at(self, slot: int, index: int) -> SimRecord:
        if slot != 0:
            raise access_error(E_SLOT)
        record = self._by_index.get(index)
        if record is None:
            raise access_error(E_INDEX)
        return record
