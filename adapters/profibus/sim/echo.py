"""A generic simulated DP slave device: N bytes in and out, the inputs echo the outputs.

For tests, benchmarks and line checks (``drive-gateway sim profibus --slaves 3-34:echo``).
DP-V1 records on slot 0: index 0 read-only (Ident_Number and a version), indexes 1..
:data:`RECORDS` read-write, up to :data:`RECORD_SIZE` bytes; other slots and indexes get the
fact sheet's access errors (1.10: B0h invalid index, B1h write length, B2h invalid slot,
B6h access denied).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, Final

from adapters.profibus.codec.chkcfg import CompactId, IoDirection, encode_identifiers
from adapters.profibus.codec.dpv1 import error_code_1_text
from adapters.profibus.contract import RecordAccessError, SimDeviceBase

if TYPE_CHECKING:
    from gateway.config import DriveConfig

ECHO_IDENT: Final = 0xEC00  # our choice for the generic device
RECORDS: Final = 4
RECORD_SIZE: Final = 16
VERSION: Final = b"\x01\x00"
GLOBAL_CONTROLS_KEPT: Final = 256  # Operate comes every 50 x TSL: remember the last ones only

INVALID_INDEX: Final = 0xB0  # 1.10 access class, code 0
WRITE_LENGTH: Final = 0xB1  # code 1
INVALID_SLOT: Final = 0xB2  # code 2
ACCESS_DENIED: Final = 0xB6  # code 6


def echo_cfg(size: int) -> bytes:
    """Compact identifiers of ``size`` bytes in and out, consistent (1.7), 16 bytes each."""
    if size <= 0:
        return b""
    ids = []
    left = size
    while left:
        chunk = min(left, 16)
        ids.append(CompactId(IoDirection.INPUT_OUTPUT, chunk, consistent=True))
        left -= chunk
    return encode_identifiers(ids)


def _refuse(code: int) -> RecordAccessError:
    return RecordAccessError(error_code_1_text(code), code)


class EchoSim(SimDeviceBase):
    """A :class:`adapters.profibus.contract.SimDevice` echoing its outputs."""

    dpv1 = True

    def __init__(self, size: int = 4, ident_number: int = ECHO_IDENT) -> None:
        self.size = size
        self.ident_number = ident_number
        self.accept_prm = True  # False: every Set_Prm is a Prm_Fault
        self.diag = b""  # extended diagnosis to report (device-related block, header included)
        self.diag_alert: bool | None = None  # None: any diagnosis is worth a DH
        self.outputs = bytes(size)
        self.records: dict[int, bytes] = {i: b"" for i in range(1, RECORDS + 1)}
        self.user_prm = b""
        self.comm_losses = 0
        self.power_cycles = 0
        self.exchanges = 0
        self.global_controls: deque[Any] = deque(maxlen=GLOBAL_CONTROLS_KEPT)  # the last ones

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> EchoSim:
        """The device a drive's config describes (``size`` and ``ident_number`` options);
        a default one for ``None``."""
        if drive is None:
            return cls()
        size = getattr(drive.options, "size", 4)
        ident = getattr(drive.options, "ident_number", ECHO_IDENT)
        return cls(int(size), int(ident))

    # ------------------------------------------------------------------ SimDevice

    def expected_cfg(self) -> bytes:
        return echo_cfg(self.size)

    def set_prm(self, user_prm: bytes) -> bool:
        self.user_prm = bytes(user_prm)
        return self.accept_prm

    def exchange(self, outputs: bytes, now: float) -> bytes:
        self.exchanges += 1
        self.outputs = bytes(outputs)
        return self.outputs

    def comm_lost(self, now: float) -> None:
        self.comm_losses += 1
        self.outputs = bytes(self.size)  # fail-safe: outputs off

    def global_control(self, control: Any, now: float) -> None:
        self.global_controls.append(control)

    def alerts(self, ext: bytes) -> bool:
        return bool(ext) if self.diag_alert is None else self.diag_alert

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        self._check(slot, index)
        if index == 0:
            return bytes((self.ident_number >> 8, self.ident_number & 0xFF)) + VERSION
        return self.records[index][:length]

    def write_record(self, slot: int, index: int, data: bytes, now: float) -> None:
        self._check(slot, index)
        if index == 0:
            raise _refuse(ACCESS_DENIED)
        if len(data) > RECORD_SIZE:
            raise _refuse(WRITE_LENGTH)
        self.records[index] = bytes(data)

    def _check(self, slot: int, index: int) -> None:
        if slot != 0:
            raise _refuse(INVALID_SLOT)
        if index != 0 and index not in self.records:
            raise _refuse(INVALID_INDEX)

    def ext_diag(self) -> bytes:
        return self.diag

    def tick(self, now: float) -> None:
        return

    def power_cycle(self, now: float) -> None:
        self.power_cycles += 1
        self.outputs = bytes(self.size)
