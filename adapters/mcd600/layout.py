"""The three GSD operating modes of the MCD 600 PROFIBUS card and their telegram layouts.

Installation guide 4.1: basic mode has the control structure (4.2), extended mode adds the
monitoring structure (4.3), parameter upload/download mode adds the programming structure
(4.4). The guide numbers bytes across the structures:

==========  =====================  ==========================
structure   outputs (master ->)    inputs (-> master)
==========  =====================  ==========================
control     0-1 control word       0-1 status word
monitoring  2 data request         2-5 echo, flag, value
programming 3-6 number, flags,     6-9 echo, flags, value
            value
==========  =====================  ==========================

so basic is 2 out / 2 in, extended 3 out / 6 in, parameter 7 out / 10 in. The guide gives no
Chk_Cfg identifiers (they are in the GSD file); we use one compact, consistent identifier per
structure and direction (fact sheet 1.7), see :data:`LAYOUTS` and docs/devices.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Final, Self

from adapters.mcd600.errors import Mcd600DecodeError, require_size
from adapters.mcd600.monitoring import MonitorReply
from adapters.mcd600.programming import IDLE, ParamReply, ParamRequest
from adapters.mcd600.words import ControlWord, StatusWord
from gateway.errors import require_int


class Mode(Enum):
    """GSD operating mode (guide 4.1), the ``mode`` option."""

    BASIC = "basic"
    EXTENDED = "extended"
    PARAMETER = "parameter"


# Fact sheet 1.7 compact identifier: b7 consistent, b6 words, b5-4 direction, b3-0 length-1.
_INPUT: Final = 0b01
_OUTPUT: Final = 0b10
_BOTH: Final = 0b11


def compact_id(direction: int, length: int, *, words: bool = False) -> int:
    """A consistent compact-format identifier byte (fact sheet 1.7)."""
    return 0x80 | words << 6 | direction << 4 | (length - 1)


CONTROL_CFG: Final = compact_id(_BOTH, 1, words=True)  # 0xF0: 1 word out (4.2 t2), in (t3)
REQUEST_CFG: Final = compact_id(_OUTPUT, 1)  # 0xA0: 1 byte out, data request (4.3 t4)
MONITOR_CFG: Final = compact_id(_INPUT, 4)  # 0x93: 4 bytes in, bytes 2-5 (4.3 t5)
PROGRAM_CFG: Final = compact_id(_BOTH, 4)  # 0xB3: 4 bytes out (4.4.1 t7) and in (4.4.2 t8)


@dataclass(frozen=True, slots=True)
class ModeLayout:
    mode: Mode
    cfg: bytes  # Chk_Cfg identifier bytes
    output_len: int
    input_len: int
    monitoring: bool  # has the monitoring structure (4.3)
    programming: bool  # has the programming structure (4.4)


LAYOUTS: Final[dict[Mode, ModeLayout]] = {
    Mode.BASIC: ModeLayout(Mode.BASIC, bytes((CONTROL_CFG,)), 2, 2, False, False),
    Mode.EXTENDED: ModeLayout(
        Mode.EXTENDED, bytes((CONTROL_CFG, REQUEST_CFG, MONITOR_CFG)), 3, 6, True, False
    ),
    Mode.PARAMETER: ModeLayout(
        Mode.PARAMETER,
        bytes((CONTROL_CFG, REQUEST_CFG, MONITOR_CFG, PROGRAM_CFG)),
        7,
        10,
        True,
        True,
    ),
}

CONTROL_OUT: Final = slice(0, 2)  # 4.2 table 2
REQUEST_OUT: Final = 2  # 4.3 table 4
PROGRAM_OUT: Final = slice(3, 7)  # 4.4.1 table 7
STATUS_IN: Final = slice(0, 2)  # 4.2 table 3
MONITOR_IN: Final = slice(2, 6)  # 4.3 table 5
PROGRAM_IN: Final = slice(6, 10)  # 4.4.2 table 8


@dataclass(frozen=True, slots=True)
class OutputTelegram:
    """Master -> starter cyclic data; the structures a mode lacks are not sent."""

    control: ControlWord = field(default_factory=ControlWord)
    request: int = 0  # data request number (extended and parameter modes)
    param: ParamRequest = IDLE  # parameter mode only

    def encode(self, layout: ModeLayout) -> bytes:
        out = bytearray(self.control.encode())
        if layout.monitoring:
            out.append(require_int("data request number", self.request, 0, 255))
        if layout.programming:
            out += self.param.encode()
        return bytes(out)

    @classmethod
    def decode(cls, layout: ModeLayout, data: bytes) -> Self:
        raw = require_size(f"{layout.mode.value} mode outputs", data, layout.output_len)
        return cls(
            control=ControlWord.decode(raw[CONTROL_OUT]),
            request=raw[REQUEST_OUT] if layout.monitoring else 0,
            param=ParamRequest.decode(raw[PROGRAM_OUT]) if layout.programming else IDLE,
        )


@dataclass(frozen=True, slots=True)
class InputTelegram:
    """Starter -> master cyclic data; ``monitor``/``param`` are None when the mode lacks them."""

    status: StatusWord = field(default_factory=StatusWord)
    monitor: MonitorReply | None = None
    param: ParamReply | None = None

    def encode(self, layout: ModeLayout) -> bytes:
        out = bytearray(self.status.encode())
        if layout.monitoring:
            out += (self.monitor or MonitorReply()).encode()
        if layout.programming:
            out += (self.param or ParamReply()).encode()
        return bytes(out)

    @classmethod
    def decode(cls, layout: ModeLayout, data: bytes) -> Self:
        raw = bytes(data)
        if len(raw) != layout.input_len:
            raise Mcd600DecodeError(
                f"{layout.mode.value} mode inputs are {layout.input_len} bytes, got {len(raw)}",
                raw,
            )
        return cls(
            status=StatusWord.decode(raw[STATUS_IN]),
            monitor=MonitorReply.decode(raw[MONITOR_IN]) if layout.monitoring else None,
            param=ParamReply.decode(raw[PROGRAM_IN]) if layout.programming else None,
        )
