"""What a simulated WEG drive does with the line itself: SYNC/FREEZE, the detected baud
rate and the DS_Write answer (the hooks of :class:`adapters.profibus.contract.SimDevice`).

* SYNC/UNSYNC, FREEZE/UNFREEZE (CFW-11 4.1.2, CFW700 5.1.2, CFW320 5.1.2): "on a SYNC
  the command and reference values each slave received are frozen; later values are
  stored, and taken only at a new SYNC or at the UNSYNC that ends the function"; "on a
  FREEZE the values of variables and states are frozen until a new FREEZE, or the
  UNFREEZE that ends the function".
* P0963 / P754 "indicate the baud rate detected by the Profibus DP interface" (CFW-11
  P0963, CFW700 P0963, CFW320 Table 4.8): the code of the line's rate, 5 = not detected.
* DS_Write positive answer: "Data Length 0" (CFW-11 4.2.3, CFW700 5.2.3, CFW320 5.2.3).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import ClassVar, Final

from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.contract import SimDeviceBase
from adapters.profibus.weg.spec import ModelSpec

BAUD_CODES: Final[Mapping[int, int]] = {
    9600: 0,
    19200: 1,
    93750: 2,
    187500: 3,
    500000: 4,
    1500000: 6,
    3000000: 7,
    6000000: 8,
    12000000: 9,
    45450: 11,
}
"""P0963 / P754 codes of the DP baud rates (the manuals' tables; 10 is reserved)."""
BAUD_NOT_DETECTED: Final = 5

Words = tuple[int, ...]


@dataclass
class SyncFreeze:
    """The held outputs of SYNC and the frozen inputs of FREEZE (fresh after a power-up or
    a lost communication: the master's next Set_Prm starts without either)."""

    synced: bool = False
    held: Words | None = None  # received while synced, taken at the next SYNC or UNSYNC
    frozen: bytes | None = None

    def outputs(self, words: Words) -> Words | None:
        """The words to take now (None: held until the next SYNC or UNSYNC)."""
        if self.synced:
            self.held = words
            return None
        return words

    def inputs(self, fresh: bytes) -> bytes:
        return fresh if self.frozen is None else self.frozen

    def control(self, control: GlobalControl, fresh: Callable[[], bytes]) -> Words | None:
        """Apply one Global_Control; the held words a SYNC or UNSYNC releases."""
        released: Words | None = None
        if control.sync or control.unsync:
            released, self.held = self.held, None
            self.synced = control.sync and not control.unsync
        if control.unfreeze:
            self.frozen = None
        elif control.freeze:
            self.frozen = fresh()
        return released


class WegBusSide(SimDeviceBase):
    """The line hooks of a simulated WEG drive (the drive itself is :class:`WegSim`)."""

    spec: ClassVar[ModelSpec]
    values: dict[int, int]
    sync_freeze: SyncFreeze
    clear: bool
    # the drive's own steps (WegSim's methods)
    tick: Callable[[float], None]
    _inputs: Callable[[], bytes]
    _take_outputs: Callable[[Words, float], None]
    _drive_motor: Callable[[], None]

    def global_control(self, control: GlobalControl, now: float) -> None:
        self.tick(now)
        released = self.sync_freeze.control(control, self._inputs)
        if released is not None and not self.clear:
            self._take_outputs(released, now)
            self._drive_motor()

    def baud_detected(self, baudrate: int) -> None:
        self.values[self.spec.baud_param] = BAUD_CODES.get(baudrate, BAUD_NOT_DETECTED)

    def write_answer_length(self, written: int) -> int:
        return 0
