"""The starter's parameter table: the gateway reads its names and ranges, the simulator
holds its values.

The installation guide names three parameters (1-1 Command Source, 6-13 Network
Communications, 12-7 PROFIBUS Address) but neither the one-byte numbers the programming
structure (4.4) uses nor the starter's full list (that is in the starter's operating guide).
The simulator numbers its parameters 1, 2, 3... in the order below (1-1 Command Source = 1):
a subset of the starter's list, enough to run the simulation and to exercise the invalid
number and invalid value answers. Values are 16 bits.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Final


class CommandSource(IntEnum):
    """Parameter 1-1 Command Source (guide 3.3: network commands need Network)."""

    DIGITAL_INPUT = 0
    NETWORK = 1
    REMOTE_LCP = 2
    CLOCK = 3


class NetworkCommsAction(IntEnum):
    """Parameter 6-13 Network Communications: the reaction when the comm timeout expires."""

    SOFT_TRIP_AND_LOG = 0
    TRIP_STARTER = 1
    WARN_AND_LOG = 2
    LOG_ONLY = 3


class AutoResetAction(IntEnum):
    """The starter's auto-reset (its operating guide's auto-reset parameters, not in the
    card's guide): reset a trip by itself after a delay, a limited number of times."""

    OFF = 0
    RESET_TRIP = 1


class StopMode(IntEnum):
    COAST_TO_STOP = 0
    SOFT_STOP = 1


@dataclass(frozen=True, slots=True)
class ParamDef:
    number: int
    name: str
    default: int
    low: int
    high: int
    writable: bool = True


COMMAND_SOURCE: Final = 1
MOTOR_FLC: Final = 2
LOCKED_ROTOR_TIME: Final = 3
START_RAMP_TIME: Final = 4
INITIAL_CURRENT: Final = 5
CURRENT_LIMIT: Final = 6
EXCESS_START_TIME: Final = 7
STOP_MODE: Final = 8
STOP_TIME: Final = 9
NETWORK_COMMS: Final = 10
PROFIBUS_ADDRESS: Final = 11
MODEL_FLC: Final = 12
AUTO_RESET_ACTION: Final = 13
AUTO_RESET_MAX: Final = 14
AUTO_RESET_DELAY: Final = 15

PARAMS: Final[tuple[ParamDef, ...]] = (
    # The simulator's default is Network so a demo runs; the starter's own default differs.
    ParamDef(COMMAND_SOURCE, "1-1 Command Source", CommandSource.NETWORK, 0, 3),
    ParamDef(MOTOR_FLC, "Motor Full Load Current (A)", 100, 1, 2000),
    ParamDef(LOCKED_ROTOR_TIME, "Locked Rotor Time (s)", 10, 1, 120),
    ParamDef(START_RAMP_TIME, "Start Ramp Time (s)", 10, 1, 180),
    ParamDef(INITIAL_CURRENT, "Initial Current (%FLC)", 200, 100, 600),
    ParamDef(CURRENT_LIMIT, "Current Limit (%FLC)", 350, 100, 600),
    ParamDef(EXCESS_START_TIME, "Excess Start Time (s, 0 = off)", 20, 0, 250),
    ParamDef(STOP_MODE, "Stop Mode", StopMode.SOFT_STOP, 0, 1),
    ParamDef(STOP_TIME, "Stop Time (s)", 5, 0, 240),
    ParamDef(
        NETWORK_COMMS, "6-13 Network Communications", NetworkCommsAction.SOFT_TRIP_AND_LOG, 0, 3
    ),
    ParamDef(PROFIBUS_ADDRESS, "12-7 PROFIBUS Address", 3, 1, 125),
    ParamDef(MODEL_FLC, "Model FLC (A, read only)", 140, 0, 0xFFFF, writable=False),
    ParamDef(AUTO_RESET_ACTION, "Auto-Reset Action", AutoResetAction.OFF, 0, 1),
    ParamDef(AUTO_RESET_MAX, "Auto-Reset Maximum Resets", 1, 1, 5),
    ParamDef(AUTO_RESET_DELAY, "Auto-Reset Delay (s)", 5, 1, 900),
)
PARAM_DEFS: Final[dict[int, ParamDef]] = {p.number: p for p in PARAMS}


class ParamStore:
    """Parameter values with the checks the starter answers with invalid number/value."""

    def __init__(self, overrides: dict[int, int] | None = None) -> None:
        self._values = {p.number: int(p.default) for p in PARAMS}
        for number, value in (overrides or {}).items():
            if not self.valid_value(number, value):
                raise ValueError(f"simulated parameter {number}: {value} is not valid")
            self._values[number] = value

    def __getitem__(self, number: int) -> int:
        return self._values[number]

    def known(self, number: int) -> bool:
        return number in PARAM_DEFS

    def valid_value(self, number: int, value: int) -> bool:
        p = PARAM_DEFS.get(number)
        return p is not None and p.writable and p.low <= value <= p.high

    def set(self, number: int, value: int) -> None:
        if not self.valid_value(number, value):
            raise ValueError(f"simulated parameter {number}: {value} is not valid")
        self._values[number] = value
