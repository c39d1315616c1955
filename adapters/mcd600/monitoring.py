"""Monitoring structure of the MCD 600 PROFIBUS card (extended and parameter modes).

Installation guide 4.3: the master puts a data request number (1-16) in output byte 2
(table 4); the starter answers in input bytes 2-5 (table 5): the echoed request number,
an "invalid request number" bit, and a 16-bit value, high byte first. Table 6 defines the
values; :data:`DECODERS` turns each into named readings.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Self

from adapters.mcd600.errors import Mcd600DecodeError, require_size
from gateway.errors import FrameEncodeError, require_int

REPLY_SIZE: Final = 4
PRODUCT_TYPE_MCD600: Final = 15  # table 6, request 1 bits 8-15


class DataRequest(IntEnum):
    """Data request numbers (guide 4.3 table 6); 0 is reserved."""

    PRODUCT = 1
    STARTER_STATE = 2
    MOTOR_CURRENT = 3
    MOTOR_TEMPERATURE = 4
    POWER_FACTOR = 5
    POWER_KW = 6
    POWER_KVA = 7
    VOLTAGE = 8
    CURRENT_L1 = 9
    CURRENT_L2 = 10
    CURRENT_L3 = 11
    VOLTAGE_L1 = 12
    VOLTAGE_L2 = 13
    VOLTAGE_L3 = 14
    VERSION = 15
    DIGITAL_INPUTS = 16


REQUESTS: Final = tuple(DataRequest)  # the round-robin order, 1..16


class StarterState(IntEnum):
    """Request 2 bits 0-3 (guide 4.3 table 6)."""

    READY = 1
    STARTING = 2
    RUNNING = 3
    STOPPING = 4  # including braking
    NOT_READY = 5  # restart delay, restart temperature check, run simulation, reset input open
    TRIPPED = 6
    PROGRAMMING = 7
    JOG_FORWARD = 8
    JOG_REVERSE = 9


@dataclass(frozen=True, slots=True)
class MonitorReply:
    """Input bytes 2-5 (guide 4.3 table 5)."""

    echo: int = 0  # byte 2: echoed data request number
    invalid: bool = False  # byte 3 bit 0: invalid data request number
    value: int = 0  # bytes 4 (high) and 5 (low)

    def encode(self) -> bytes:
        echo = require_int("data request echo", self.echo, 0, 255)
        value = require_int("data value", self.value, 0, 0xFFFF)
        return bytes((echo, int(self.invalid), value >> 8, value & 0xFF))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        echo, flags, high, low = require_size("monitoring reply", data, REPLY_SIZE)
        return cls(echo=echo, invalid=bool(flags & 0x01), value=high << 8 | low)


@dataclass(frozen=True, slots=True)
class StarterStateWord:
    """Request 2 value (guide 4.3 table 6)."""

    state: int = 0  # bits 0-3, a StarterState value (others are not defined)
    positive_phase_sequence: bool = False  # bit 4, valid only when initialised
    current_above_flc: bool = False  # bit 5
    initialised: bool = False  # bit 6
    card_comm_error: bool = False  # bit 7: error between the card and the starter
    trip_code: int = 0  # bits 8-15, guide 4.5

    def encode(self) -> int:
        state = require_int("starter state", self.state, 0, 15)
        trip = require_int("trip code", self.trip_code, 0, 255)
        return (
            state
            | self.positive_phase_sequence << 4
            | self.current_above_flc << 5
            | self.initialised << 6
            | self.card_comm_error << 7
            | trip << 8
        )

    @classmethod
    def decode(cls, value: int) -> Self:
        return cls(
            state=value & 0x0F,
            positive_phase_sequence=bool(value >> 4 & 1),
            current_above_flc=bool(value >> 5 & 1),
            initialised=bool(value >> 6 & 1),
            card_comm_error=bool(value >> 7 & 1),
            trip_code=value >> 8 & 0xFF,
        )


class PowerScale(IntEnum):
    """Requests 6 and 7 bits 12-15 (guide 4.3 table 6)."""

    TENS = 0  # value x 10 = W (VA)
    HUNDREDS = 1  # value x 100 = W (VA)
    KILO = 2  # value = kW (kVA)
    TEN_KILO = 3  # value x 10 = kW (kVA)


POWER_FACTOR_UNITS: Final[dict[PowerScale, float]] = {  # units (W or VA) per count
    PowerScale.TENS: 10.0,
    PowerScale.HUNDREDS: 100.0,
    PowerScale.KILO: 1000.0,
    PowerScale.TEN_KILO: 10000.0,
}
POWER_RAW_MAX: Final = 0x0FFF  # bits 0-11


@dataclass(frozen=True, slots=True)
class ScaledPower:
    """A power value with its scale nibble (requests 6 kW and 7 kVA)."""

    raw: int = 0  # bits 0-11
    scale: PowerScale = PowerScale.TENS  # bits 12-15

    @property
    def units(self) -> float:
        """The power in W (request 6) or VA (request 7)."""
        return self.raw * POWER_FACTOR_UNITS[self.scale]

    def encode(self) -> int:
        raw = require_int("power", self.raw, 0, POWER_RAW_MAX)
        return raw | int(self.scale) << 12

    @classmethod
    def decode(cls, value: int) -> Self:
        nibble = value >> 12 & 0x0F
        if nibble > max(PowerScale):
            raise Mcd600DecodeError(
                f"power scale {nibble} is not defined (0-3)", value.to_bytes(2, "big")
            )
        return cls(raw=value & POWER_RAW_MAX, scale=PowerScale(nibble))

    @classmethod
    def from_units(cls, units: float) -> Self:
        """The finest scale that holds ``units`` (W or VA) in 12 bits."""
        if not units >= 0:
            raise FrameEncodeError(f"power must be a non-negative number, got {units!r}")
        for scale in PowerScale:
            raw = round(units / POWER_FACTOR_UNITS[scale])
            if raw <= POWER_RAW_MAX:
                return cls(raw=raw, scale=scale)
        raise FrameEncodeError(f"power {units} does not fit the scales of the guide")


FOURTEEN_BITS: Final = 0x3FFF  # requests 8-14 bits 0-13 (14-15 reserved)

Readings = dict[str, float | int]
Decoder = Callable[[int, float], Readings]


def _product(value: int, _scale: float) -> Readings:
    return {"product_type": value >> 8 & 0xFF}


def _starter_state(value: int, _scale: float) -> Readings:
    word = StarterStateWord.decode(value)
    out: Readings = {
        "starter_state": word.state,
        "current_above_flc": int(word.current_above_flc),
        "initialised": int(word.initialised),
        "card_comm_error": int(word.card_comm_error),
        "trip_code": word.trip_code,
    }
    if word.initialised:  # bit 4 is valid only when bit 6 = 1
        out["phase_sequence"] = 1 if word.positive_phase_sequence else -1
    return out


def _motor_current(value: int, scale: float) -> Readings:
    return {"current_avg_a": value * scale}


def _motor_temperature(value: int, _scale: float) -> Readings:
    return {"motor_temp_pct": float(value & 0xFF)}


def _power_factor(value: int, _scale: float) -> Readings:
    return {"power_factor": (value & 0xFF) / 100.0}


def _power_kw(value: int, _scale: float) -> Readings:
    return {"power_kw": ScaledPower.decode(value).units / 1000.0}


def _power_kva(value: int, _scale: float) -> Readings:
    return {"apparent_power_kva": ScaledPower.decode(value).units / 1000.0}


def _voltage(key: str) -> Decoder:
    return lambda value, _scale: {key: float(value & FOURTEEN_BITS)}


def _phase_current(key: str) -> Decoder:
    return lambda value, scale: {key: (value & FOURTEEN_BITS) * scale}


def _version(value: int, _scale: float) -> Readings:
    return {"software_version_major": value >> 8 & 0xFF, "software_version_minor": value & 0xFF}


DIGITAL_INPUT_BITS: Final[dict[str, int]] = {  # request 16, 0 = open, 1 = closed
    "input_start_stop": 0,
    "input_reset": 2,
    "input_a": 3,
    "input_b": 4,
}


def _digital_inputs(value: int, _scale: float) -> Readings:
    return {key: value >> bit & 1 for key, bit in DIGITAL_INPUT_BITS.items()}


DECODERS: Final[Mapping[DataRequest, Decoder]] = {  # guide 4.3 table 6
    DataRequest.PRODUCT: _product,
    DataRequest.STARTER_STATE: _starter_state,
    DataRequest.MOTOR_CURRENT: _motor_current,
    DataRequest.MOTOR_TEMPERATURE: _motor_temperature,
    DataRequest.POWER_FACTOR: _power_factor,
    DataRequest.POWER_KW: _power_kw,
    DataRequest.POWER_KVA: _power_kva,
    DataRequest.VOLTAGE: _voltage("voltage_v"),
    DataRequest.CURRENT_L1: _phase_current("current_l1_a"),
    DataRequest.CURRENT_L2: _phase_current("current_l2_a"),
    DataRequest.CURRENT_L3: _phase_current("current_l3_a"),
    DataRequest.VOLTAGE_L1: _voltage("voltage_l1_v"),
    DataRequest.VOLTAGE_L2: _voltage("voltage_l2_v"),
    DataRequest.VOLTAGE_L3: _voltage("voltage_l3_v"),
    DataRequest.VERSION: _version,
    DataRequest.DIGITAL_INPUTS: _digital_inputs,
}


def decode_value(request: DataRequest, value: int, current_scale: float = 1.0) -> Readings:
    """Named readings from one data value; ``current_scale`` is A per count (0.1 for
    MCD6-0063B and smaller, whose currents come 10 times too large, guide 4.2 note 1)."""
    if not 0 <= value <= 0xFFFF:
        raise Mcd600DecodeError(f"data value {value} is not 16 bits")
    return DECODERS[request](value, current_scale)
