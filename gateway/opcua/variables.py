"""What a drive's OPC UA variables hold: the drive model's fields as OPC UA values.

Sans-IO: tables and pure functions from a :class:`DriveState` (and the drive's
capabilities) to values; gateway/opcua/space.py makes the nodes from these tables and
gateway/opcua/publisher.py writes the values. Units are UNECE codes as OPC UA encodes
them (Part 8, 5.6.3: ``UnitId`` is the code's characters in one integer), ranges are
the display ranges a SCADA draws with (EURange): the drive's own scale where the gateway
knows it, else a fixed range of the quantity.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

from gateway.adapter import Capabilities
from gateway.model import DriveState

UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"


class Kind(Enum):
    """The OPC UA data type of a variable."""

    DOUBLE = "Double"
    BOOLEAN = "Boolean"
    STRING = "String"
    INT32 = "Int32"


@dataclass(frozen=True, slots=True)
class Unit:
    """An engineering unit: its UNECE common code, what a display shows, its name."""

    code: str
    display: str
    description: str

    @property
    def unit_id(self) -> int:
        """The UNECE code as OPC UA's UnitId (Part 8, 5.6.3)."""
        out = 0
        for char in self.code:
            out = (out << 8) | ord(char)
        return out


RPM = Unit("RPM", "rpm", "revolutions per minute")
PERCENT = Unit("P1", "%", "percent")
AMPERE = Unit("AMP", "A", "ampere")
KILOWATT = Unit("KWT", "kW", "kilowatt")
VOLT = Unit("VLT", "V", "volt")

Range = tuple[float, float]
RangeOf = Callable[[Capabilities], Range]


def _fixed(low: float, high: float) -> RangeOf:
    return lambda _caps: (low, high)


def _rpm_range(caps: Capabilities) -> Range:
    scale = caps.speed_scale
    top = 3600.0 if scale is None else scale.max_rpm
    return -top, top


def _pct_range(caps: Capabilities) -> Range:
    scale = caps.speed_scale
    top = 100.0 if scale is None else scale.max_pct
    return -top, top


@dataclass(frozen=True, slots=True)
class Reading:
    """A drive model field shown as an analog variable (AnalogItemType)."""

    field: str
    name: str
    unit: Unit
    range_of: RangeOf


READINGS: tuple[Reading, ...] = (
    Reading("speed_rpm", "SpeedRpm", RPM, _rpm_range),
    Reading("speed_pct", "SpeedPercent", PERCENT, _pct_range),
    Reading("speed_ref_rpm", "SpeedReferenceRpm", RPM, _rpm_range),
    Reading("speed_ref_pct", "SpeedReferencePercent", PERCENT, _pct_range),
    Reading("current_a", "CurrentA", AMPERE, _fixed(0.0, 1000.0)),
    Reading("current_pct_flc", "CurrentPercentFlc", PERCENT, _fixed(0.0, 600.0)),
    Reading("motor_temp_pct", "MotorTemperaturePercent", PERCENT, _fixed(0.0, 200.0)),
    Reading("power_kw", "PowerKw", KILOWATT, _fixed(0.0, 1000.0)),
    Reading("voltage_v", "VoltageV", VOLT, _fixed(0.0, 1000.0)),
)
"""The readings, in the order they are browsed."""


def _text(value: Any) -> str:
    return "" if value is None else str(getattr(value, "value", value))


def _status(state: DriveState) -> str:
    return state.status.label


def _code(value: Any) -> int:
    return -1 if value is None else int(value)


@dataclass(frozen=True, slots=True)
class Status:
    """A field shown as a plain variable: its name, type and how it is read."""

    name: str
    kind: Kind
    read: Callable[[DriveState], Any]


STATUS: tuple[Status, ...] = (
    Status("Comm", Kind.STRING, lambda s: s.comm.value),
    Status("Status", Kind.STRING, _status),
    Status("StatusCode", Kind.INT32, lambda s: int(s.status)),
    Status("Running", Kind.BOOLEAN, lambda s: s.running),
    Status("Direction", Kind.STRING, lambda s: s.direction.value),
    Status("AtReference", Kind.BOOLEAN, lambda s: s.at_reference),
    Status("Remote", Kind.BOOLEAN, lambda s: s.remote),
    Status("LocalControl", Kind.BOOLEAN, lambda s: s.local_control),
    Status("Alarm", Kind.BOOLEAN, lambda s: s.alarm),
    Status("AlarmCode", Kind.INT32, lambda s: _code(s.alarm_code)),
    Status("FaultCode", Kind.INT32, lambda s: _code(s.fault_code)),
    Status("FaultText", Kind.STRING, lambda s: _text(s.fault_text)),
    Status("ControlSource", Kind.STRING, lambda s: s.control_source.value),
    Status("ControlClient", Kind.STRING, lambda s: _text(s.control_client)),
    Status("Doubtful", Kind.BOOLEAN, lambda s: s.doubtful),
)
"""Status fields; a code the drive does not give is -1, a text it does not give is empty."""

IDENTITY: tuple[str, ...] = ("Device", "Bus", "Address", "Firmware")
"""The identity properties of a drive object (Firmware read once the drive is online)."""


def reading_value(state: DriveState, reading: Reading) -> float | None:
    """A reading as a Double, None when the drive does not give it (or it is not finite):
    the variable's status is then BadNoData-like (gateway/opcua/publisher.py)."""
    value = getattr(state, reading.field)
    if value is None:
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def values_of(state: DriveState) -> dict[str, Any]:
    """Every variable of a drive by its browse name: readings (None: no value) and status."""
    out: dict[str, Any] = {r.name: reading_value(state, r) for r in READINGS}
    for status in STATUS:
        out[status.name] = status.read(state)
    return out


def changed_values(old: Mapping[str, Any] | None, new: Mapping[str, Any]) -> dict[str, Any]:
    """The variables whose value differs from what was written last (all when none was)."""
    if old is None:
        return dict(new)
    return {name: value for name, value in new.items() if old.get(name, _MISSING) != value}


_MISSING = object()


def bus_figures(diagnostics: Mapping[str, Any]) -> dict[str, float]:
    """A line's figures that are numbers (booleans as 0/1), by key: what the bus objects
    show; per-drive figures and texts are left out."""
    out: dict[str, float] = {}
    for key, value in diagnostics.items():
        if key == "drives" or not isinstance(key, str):
            continue
        if isinstance(value, bool | int | float) and math.isfinite(float(value)):
            out[key] = float(value)
    return out
