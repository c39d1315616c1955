"""Control word (outputs 0-1) and status word (inputs 0-1) of the MCD 600 PROFIBUS card.

Installation guide 4.2, table 2 (control word) and table 3 (status word). Both are two
bytes, each byte's bits given by the guide; reserved bits are sent as 0 and ignored when read.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Self

from adapters.mcd600.errors import require_size
from gateway.errors import require_int

WORD_SIZE: Final = 2

# 4.2 table 3 footnote 1: the 6-bit current is %FLC, 63 = 200 %, "divide by 0.315".
CURRENT_RAW_MAX: Final = 63
CURRENT_PCT_PER_COUNT: Final = 1 / 0.315


class MotorSet(IntEnum):
    """Control word byte 0 bits 2-3 (guide 4.2 table 2)."""

    REMOTE_INPUT = 0  # use the starter's remote input to select the motor set
    PRIMARY = 1  # use the primary motor set when starting
    SECONDARY = 2  # use the secondary motor set when starting
    RESERVED = 3  # the guide prints "4=Reservado": a 2-bit field, so 3


def _bit(value: int, bit: int) -> bool:
    return bool(value >> bit & 1)


@dataclass(frozen=True, slots=True)
class ControlWord:
    """Master -> starter control word (guide 4.2 table 2).

    ``quick_stop`` is byte 0 bit 4: 1 = the stop action is a quick stop (coast to stop),
    0 = soft stop as set on the starter. The guide requires it to be 0 for a start.
    """

    start: bool = False  # byte 1 bit 0: 0 = stop, 1 = start
    quick_stop: bool = False  # byte 0 bit 4
    reset: bool = False  # byte 1 bit 3: 1 = reset
    motor_set: MotorSet = MotorSet.REMOTE_INPUT  # byte 0 bits 2-3

    def encode(self) -> bytes:
        motor_set = require_int("motor set", int(self.motor_set), 0, 3)
        byte0 = motor_set << 2 | self.quick_stop << 4
        byte1 = int(self.start) | self.reset << 3
        return bytes((byte0, byte1))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        byte0, byte1 = require_size("control word", data, WORD_SIZE)
        return cls(
            start=_bit(byte1, 0),
            quick_stop=_bit(byte0, 4),
            reset=_bit(byte1, 3),
            motor_set=MotorSet(byte0 >> 2 & 0x03),
        )


@dataclass(frozen=True, slots=True)
class StatusWord:
    """Starter -> master status word (guide 4.2 table 3)."""

    current_raw: int = 0  # byte 0 bits 0-5: motor current, 63 = 200 % FLC
    network_control: bool = False  # byte 0 bit 6: command source, 1 = network
    ramping: bool = False  # byte 0 bit 7: starting or stopping
    ready: bool = False  # byte 1 bit 0
    active: bool = False  # byte 1 bit 1: starting, running or stopping
    tripped: bool = False  # byte 1 bit 2
    warning: bool = False  # byte 1 bit 3

    @property
    def current_pct_flc(self) -> float:
        """Motor current in % of the motor's full load current (63 = 200 %)."""
        return self.current_raw * CURRENT_PCT_PER_COUNT

    def encode(self) -> bytes:
        raw = require_int("current (raw %FLC)", self.current_raw, 0, CURRENT_RAW_MAX)
        byte0 = raw | self.network_control << 6 | self.ramping << 7
        byte1 = int(self.ready) | self.active << 1 | self.tripped << 2 | self.warning << 3
        return bytes((byte0, byte1))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        byte0, byte1 = require_size("status word", data, WORD_SIZE)
        return cls(
            current_raw=byte0 & 0x3F,
            network_control=_bit(byte0, 6),
            ramping=_bit(byte0, 7),
            ready=_bit(byte1, 0),
            active=_bit(byte1, 1),
            tripped=_bit(byte1, 2),
            warning=_bit(byte1, 3),
        )


def current_to_raw(pct_flc: float) -> int:
    """%FLC -> the status word's 6-bit value (rounded, saturating at 63 = 200 %)."""
    if not pct_flc > 0:  # also NaN
        return 0
    return min(CURRENT_RAW_MAX, round(pct_flc * 0.315))
