"""The cyclic words of the WEG drives on Profibus DP, and their speed scales.

Manufacturer profile (P0741 = 1): control word P0684, speed reference P0685 (13 bits),
status word P0680, motor speed P0681 (13 bits). PROFIdrive profile (P0741 = 0, CFW-11 and
CFW700 only): control word P0967 (STW1), status word P0968 (ZSW1), speed 4000h = P0134.

The bit layouts are data: a table ``(field, bit)`` per model and word, so a bit the model's
manual calls "reserved" is neither sent nor read. :mod:`.spec` holds the tables per model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from enum import Enum
from typing import Final, Self

from gateway.errors import FrameEncodeError

BitTable = tuple[tuple[str, int], ...]
"""``(field name, bit number)`` for each bit a model's manual defines in a word."""

SPEED_13BIT_BASE: Final = 8192  # P0681/P0685: 2000h (8192) = synchronous speed (CFW-11 3.x,
# CFW700 4.x); CFW320 P681/P685: 2000h = rated frequency P403 (Table 4.x "P681", "P685").
PROFIDRIVE_SPEED_BASE: Final = 0x4000  # CFW-11/CFW700 P0741 "Speed for PROFIdrive profile":
# 4000h (16384) = maximum speed P0134.
PROFIDRIVE_PERCENT_BASE: Final = 0x4000  # CFW-11 P0760-P0762: 0x4000 = 100 % (PROFIdrive scale)
WORD_MIN: Final = -32768
WORD_MAX: Final = 32767


def to_word(value: int) -> int:
    """A signed 16-bit value as the unsigned word on the wire (two's complement)."""
    if not WORD_MIN <= value <= 0xFFFF:
        raise FrameEncodeError(f"{value} does not fit a 16-bit word")
    return value & 0xFFFF


def signed(word: int) -> int:
    """An unsigned 16-bit word read as signed (P0681, P0685, NIST/NSOLL are signed)."""
    word &= 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def saturate(value: float) -> int:
    """Round to the nearest integer and saturate at -32768..32767.

    CFW320 P681/P685 note: "a maximum of 4 times the rated frequency of the motor, with
    saturation in 32767 (or -32768)"; the same arithmetic bounds the other models' words.
    """
    if math.isnan(value):
        return 0
    return max(WORD_MIN, min(WORD_MAX, round(value)))


def speed_to_raw(value: float, base: float, full_scale: int) -> int:
    """``value`` in the unit of ``base`` (rpm, Hz or %) as a signed word where base = full."""
    if base <= 0:
        raise FrameEncodeError(f"speed base must be positive, not {base}")
    return saturate(value * full_scale / base)


def raw_to_speed(raw: int, base: float, full_scale: int) -> float:
    """A signed word back in the unit of ``base``."""
    return raw * base / full_scale


def synchronous_rpm(rated_hz: float, rated_rpm: float) -> float:
    """Synchronous speed of the motor from its rated frequency (P0403) and speed (P0402).

    Pole pairs are the whole number of times the rated speed fits in 60 x f (the rated speed
    is the synchronous speed less the slip): 60 Hz and 1750 rpm give 2 pairs, 1800 rpm.
    """
    if rated_hz <= 0 or rated_rpm <= 0:
        raise ValueError(f"rated frequency {rated_hz} Hz and speed {rated_rpm} rpm must be > 0")
    pairs = max(1, math.floor(60.0 * rated_hz / rated_rpm + 1e-9))
    return 60.0 * rated_hz / pairs


def effective_reference(forward: bool, reference: int) -> int:
    """The signed reference a drive follows from P0684 bit 2 and the sign of P0685.

    P0685 (CFW-11 3.x, CFW700 4.x, CFW320 Table 4.x), the manual's four cases:
    bit 2 = 1 and P0685 > 0: forward; bit 2 = 1 and P0685 < 0: reverse;
    bit 2 = 0 and P0685 > 0: reverse; bit 2 = 0 and P0685 < 0: forward.
    """
    return reference if forward else -reference


def _encode_bits(obj: object, table: BitTable) -> int:
    word = 0
    for name, bit in table:
        if getattr(obj, name):
            word |= 1 << bit
    return word


def _decode_bits(word: int, table: BitTable) -> dict[str, bool]:
    return {name: bool(word >> bit & 1) for name, bit in table}


class _Word:
    """A word as a frozen dataclass of flags, encoded and decoded through a bit table."""

    def encode(self, table: BitTable) -> int:
        return _encode_bits(self, table)

    @classmethod
    def decode(cls, word: int, table: BitTable) -> Self:
        known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        return cls(**{k: v for k, v in _decode_bits(word, table).items() if k in known})


@dataclass(frozen=True, slots=True)
class ManufacturerControl(_Word):
    """P0684 control word (CFW-11 Table 3.3, CFW700 Table 4.3, CFW320 Table 4.3)."""

    run: bool = False  # bit 0 run/stop: 1 runs on the acceleration ramp, 0 ramps down
    general_enable: bool = False  # bit 1: 0 disables the drive (the motor coasts)
    forward: bool = False  # bit 2: 1 = direction of the reference, 0 = opposite (see P0685)
    jog: bool = False  # bit 3
    remote: bool = False  # bit 4 LOC/REM: 1 = remote
    second_ramp: bool = False  # bit 5: P0102/P0103 instead of P0100/P0101
    quick_stop: bool = False  # bit 6 (CFW-11, CFW700; "Reserved" on the CFW320)
    fault_reset: bool = False  # bit 7: resets a fault (we send it as a pulse)


@dataclass(frozen=True, slots=True)
class ManufacturerStatus(_Word):
    """P0680 status word (CFW-11 Table 3.2, CFW700 Table 4.2, CFW320 Table 4.2)."""

    run_command: bool = False  # bit 1 (CFW320 only): there was a run command
    fire_mode: bool = False  # bit 2 (CFW320 only)
    quick_stop_active: bool = False  # bit 4 (CFW-11, CFW700)
    second_ramp: bool = False  # bit 5
    config_mode: bool = False  # bit 6: special condition, cannot be enabled (P0692)
    alarm: bool = False  # bit 7: the alarm number is in P0048
    running: bool = False  # bit 8: turning at the reference or on a ramp
    general_enable: bool = False  # bit 9
    forward: bool = False  # bit 10: 1 = forward (clockwise), 0 = reverse
    jog: bool = False  # bit 11
    remote: bool = False  # bit 12
    undervoltage: bool = False  # bit 13
    automatic: bool = False  # bit 14 (CFW-11 only): PID automatic
    fault: bool = False  # bit 15: the fault number is in P0049


@dataclass(frozen=True, slots=True)
class ProfidriveControl(_Word):
    """P0967 STW1 (CFW-11 Table 3.8, CFW700 Table 4.7); bits 5, 9, 11-15 reserved."""

    on: bool = False  # bit 0 ON/OFF (OFF1: stop on the ramp and disable)
    no_coast_stop: bool = False  # bit 1: 0 = coast stop (OFF2)
    no_quick_stop: bool = False  # bit 2: 0 = quick stop (OFF3)
    enable_operation: bool = False  # bit 3
    enable_ramp: bool = False  # bit 4: 0 disables via the deceleration ramp
    enable_setpoint: bool = False  # bit 6: 0 zeroes the speed reference
    fault_ack: bool = False  # bit 7
    jog: bool = False  # bit 8 JOG 1 ON
    control_by_plc: bool = False  # bit 10: 1 = remote, 0 = local


@dataclass(frozen=True, slots=True)
class ProfidriveStatus(_Word):
    """P0968 ZSW1 (CFW-11 Table 3.9, CFW700 Table 4.8); bit 8 and 11-15 reserved."""

    ready_to_switch_on: bool = False  # bit 0
    ready_to_operate: bool = False  # bit 1
    operation_enabled: bool = False  # bit 2
    fault: bool = False  # bit 3
    coast_stop_not_active: bool = False  # bit 4
    quick_stop_not_active: bool = False  # bit 5
    switching_on_inhibited: bool = False  # bit 6
    warning: bool = False  # bit 7
    control_requested: bool = False  # bit 9: remote
    frequency_reached: bool = False  # bit 10 (CFW-11 only; reserved on the CFW700)

    @property
    def state(self) -> ProfidriveState:
        """The switching-on state this word reports (fact sheet 1.11 state machine)."""
        if self.fault:
            return ProfidriveState.FAULT
        if self.switching_on_inhibited:
            return ProfidriveState.SWITCHING_ON_INHIBITED
        if self.operation_enabled:
            return ProfidriveState.OPERATION
        if self.ready_to_operate:
            return ProfidriveState.SWITCHED_ON
        if self.ready_to_switch_on:
            return ProfidriveState.READY_TO_SWITCH_ON
        return ProfidriveState.NOT_READY


class ProfidriveState(Enum):
    """PROFIdrive switching-on states (fact sheet 1.11: S1 .. S4, plus fault)."""

    NOT_READY = "not ready"  # no bit of S1..S4 set (only transiently)
    SWITCHING_ON_INHIBITED = "switching on inhibited"  # S1, ZSW1.6
    READY_TO_SWITCH_ON = "ready to switch on"  # S2, ZSW1.0
    SWITCHED_ON = "switched on"  # S3, ZSW1.1
    OPERATION = "operation"  # S4, ZSW1.2
    FAULT = "fault"  # ZSW1.3


# ----------------------------------------------------------------------- bit tables

MANUFACTURER_CONTROL_BITS: Final[BitTable] = (  # CFW-11 Table 3.3 / CFW700 Table 4.3
    ("run", 0),
    ("general_enable", 1),
    ("forward", 2),
    ("jog", 3),
    ("remote", 4),
    ("second_ramp", 5),
    ("quick_stop", 6),
    ("fault_reset", 7),
)
CFW320_CONTROL_BITS: Final[BitTable] = tuple(  # CFW320 Table 4.3: bit 6 "Reserved"
    (name, bit) for name, bit in MANUFACTURER_CONTROL_BITS if bit != 6
)

_COMMON_STATUS_BITS: Final[BitTable] = (
    ("second_ramp", 5),
    ("config_mode", 6),
    ("alarm", 7),
    ("running", 8),
    ("general_enable", 9),
    ("forward", 10),
    ("jog", 11),
    ("remote", 12),
    ("undervoltage", 13),
    ("fault", 15),
)
CFW11_STATUS_BITS: Final[BitTable] = (  # CFW-11 Table 3.2 (bits 0-3 reserved)
    ("quick_stop_active", 4),
    *_COMMON_STATUS_BITS,
    ("automatic", 14),
)
CFW700_STATUS_BITS: Final[BitTable] = (  # CFW700 Table 4.2 (bits 0-3 and 14 reserved)
    ("quick_stop_active", 4),
    *_COMMON_STATUS_BITS,
)
CFW320_STATUS_BITS: Final[BitTable] = (  # CFW320 Table 4.2 (bits 0, 3, 4 and 14 reserved)
    ("run_command", 1),
    ("fire_mode", 2),
    *_COMMON_STATUS_BITS,
)

STW1_BITS: Final[BitTable] = (  # CFW-11 Table 3.8 / CFW700 Table 4.7
    ("on", 0),
    ("no_coast_stop", 1),
    ("no_quick_stop", 2),
    ("enable_operation", 3),
    ("enable_ramp", 4),
    ("enable_setpoint", 6),
    ("fault_ack", 7),
    ("jog", 8),
    ("control_by_plc", 10),
)
CFW700_ZSW1_BITS: Final[BitTable] = (  # CFW700 Table 4.8 (bits 8, 10-15 reserved)
    ("ready_to_switch_on", 0),
    ("ready_to_operate", 1),
    ("operation_enabled", 2),
    ("fault", 3),
    ("coast_stop_not_active", 4),
    ("quick_stop_not_active", 5),
    ("switching_on_inhibited", 6),
    ("warning", 7),
    ("control_requested", 9),
)
CFW11_ZSW1_BITS: Final[BitTable] = (  # CFW-11 Table 3.9: bit 10 "frequency reached"
    *CFW700_ZSW1_BITS,
    ("frequency_reached", 10),
)

NAMUR_BITS: Final[tuple[tuple[int, str, tuple[int, ...]], ...]] = (
    # CFW-11 P0763, Table 3.7 (VIK-NAMUR): bit, category, the faults it stands for.
    (0, "control electronics/software fault", (80,)),
    (2, "DC link overvoltage", (22,)),
    (4, "inverter overtemperature", (51, 54, 57)),
    (5, "ground fault", (74,)),
    (6, "motor overload", (71, 72)),
    (9, "speed sensor fault", (65, 66)),
    (10, "internal communication fault", (229, 230)),
)


def namur_categories(word: int) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """The fault categories a P0763 word reports (Table 3.7), lowest bit first."""
    return tuple((text, codes) for bit, text, codes in NAMUR_BITS if word >> bit & 1)
