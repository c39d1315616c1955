"""The common drive model: what every drive looks like to SCADA and to PLCs.

Frozen dataclasses and enums; states are never strings. ``DriveState.to_json``
gives the JSON form the Zenoh front end publishes. Its field names are a
contract (issue 2); values a device cannot give are ``None`` (JSON null),
never 0 pretending to be a reading.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from enum import Enum, IntEnum
from typing import Any, TypedDict

from gateway import devices
from gateway.errors import CommandRejected

Device = devices.Device
"""The device models (the registry, gateway/devices.py), importable from the model."""


class CommState(Enum):
    """Communication state of one drive on its bus."""

    OFFLINE = "offline"
    CONNECTING = "connecting"
    ONLINE = "online"
    CLEAR = "clear"  # on the bus, outputs in clear/idle: the master is not driving it


class DriveStatus(IntEnum):
    """Drive status; the value is the Modbus status code (input register 1)."""

    NOT_READY = 0
    READY = 1
    STARTING = 2
    RUNNING = 3
    STOPPING = 4
    FAULTED = 5
    TRIPPED = 6  # soft starters

    @property
    def label(self) -> str:
        return self.name.lower()


class Direction(Enum):
    FORWARD = "forward"
    REVERSE = "reverse"


class Source(Enum):
    """Who gave the command that is in force."""

    NONE = "none"
    ZENOH = "zenoh"
    MODBUS = "modbus"
    GATEWAY = "gateway"  # a safety action of the gateway itself
    WEB = "web"  # a user of the web status page (web.commands, gateway/web)
    OPCUA = "opcua"  # an OPC UA session (gateway/opcua)


def client_label(raw: str) -> str:
    """The name a client id is published under (``control_client``, events, logs): the
    first 16 hex digits of its SHA-256. A Zenoh session id or a page id is chosen by the
    client: published as it is, another client could copy it and become the one in control
    (feed its watchdog, keep its run). The label cannot be turned back into the id
    (docs/safety.md, "A copied client id")."""
    return hashlib.sha256(raw.encode("utf-8", "surrogatepass")).hexdigest()[:16]


class ControlMode(Enum):
    """Per-drive arbitration between command sources."""

    ANY = "any"
    ZENOH = "zenoh"
    MODBUS = "modbus"
    WEB = "web"
    OPCUA = "opcua"

    def admits(self, source: Source) -> bool:
        if self is ControlMode.ANY:
            return source in (Source.ZENOH, Source.MODBUS, Source.WEB, Source.OPCUA)
        return bool(source.value == self.value)


class StopAction(Enum):
    """What to do when a command times out or the gateway shuts down."""

    RAMP_STOP = "ramp_stop"
    COAST = "coast"
    HOLD = "hold"


JSON_FIELDS: tuple[str, ...] = (
    "id",
    "device",
    "bus",
    "address",
    "comm",
    "status",
    "running",
    "direction",
    "at_reference",
    "remote",
    "alarm",
    "speed_rpm",
    "speed_pct",
    "speed_ref_rpm",
    "speed_ref_pct",
    "current_a",
    "current_pct_flc",
    "motor_temp_pct",
    "power_kw",
    "voltage_v",
    "fault_code",
    "fault_text",
    "alarm_code",
    "seq",
    "ts",
)
"""The fixed JSON fields, in order (issue 2). Extra documented fields follow them."""

EXTRA_JSON_FIELDS: tuple[str, ...] = (
    "control_source",
    "speed_base",
    "values",
    "control_client",
    "local_control",
    "failsafe",
    "failsafe_text",
    "doubtful",
)
"""Documented additions: who is in control, which scale base the speed uses,
named raw values (telegram words mapped to parameters the profile does not model),
which client of ``control_source`` is in control (safety rule 3, an opaque label),
whether the drive is in local control (it ignores the network's run commands),
the drive's own reaction to a lost master (``failsafe``: true when it stops or
faults, false when it keeps running, null when unknown; ``failsafe_text`` says
which parameter and value), and whether frames that contradict each other were
heard for this drive (``doubtful``: its readings may be forged or mixed)."""

PUBLISHED_FIELDS: tuple[str, ...] = JSON_FIELDS + EXTRA_JSON_FIELDS
"""Every field of the JSON form, in its order."""


@dataclass(frozen=True)
class DriveState:
    """The latest known state of one drive."""

    id: str
    device: Device
    bus: str
    address: int
    comm: CommState = CommState.OFFLINE
    status: DriveStatus = DriveStatus.NOT_READY
    running: bool = False
    direction: Direction = Direction.FORWARD
    at_reference: bool = False
    remote: bool = False
    alarm: bool = False
    speed_rpm: float | None = None
    speed_pct: float | None = None
    speed_ref_rpm: float | None = None
    speed_ref_pct: float | None = None
    current_a: float | None = None
    current_pct_flc: float | None = None
    motor_temp_pct: float | None = None
    power_kw: float | None = None
    voltage_v: float | None = None
    fault_code: int | None = None
    fault_text: str | None = None
    alarm_code: int | None = None
    seq: int = 0
    ts: float = 0.0
    control_source: Source = Source.NONE
    speed_base: str | None = None
    values: Mapping[str, float | int] = field(default_factory=dict)
    control_client: str | None = None
    local_control: bool = False
    failsafe: bool | None = None
    failsafe_text: str | None = None
    doubtful: bool = False

    @property
    def online(self) -> bool:
        return self.comm is CommState.ONLINE

    @property
    def faulted(self) -> bool:
        return self.status in (DriveStatus.FAULTED, DriveStatus.TRIPPED)

    def to_json(self) -> dict[str, Any]:
        """The JSON form: the fixed fields first, then the documented extras."""
        out: dict[str, Any] = {}
        for name in PUBLISHED_FIELDS:
            out[name] = _json_value(getattr(self, name))
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DriveState:
        """Inverse of :meth:`to_json` (used by clients and tests)."""
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in data:
                kwargs[f.name] = _FROM_JSON.get(f.name, _identity)(data[f.name])
        return cls(**kwargs)

    def changed(self, **changes: Any) -> DriveState:
        """This state with ``changes`` applied: the one way to make a state from another.

        Field names are checked (TypeError naming those that are no field); values are taken
        as given, like ``dataclasses.replace``, without its per-call overhead (hot path of the
        hub): the new state's fields are a copy of this one's with ``changes`` applied, one
        dict copy instead of a call per field.
        """
        unknown = changes.keys() - _STATE_FIELDS
        if unknown:
            raise TypeError(f"DriveState has no field(s) {sorted(unknown)}")
        new = object.__new__(DriveState)
        values = self.__dict__.copy()
        values.update(changes)
        _set_attribute(new, "__dict__", values)  # frozen: past its __setattr__
        return new


class Readings(TypedDict, total=False):
    """What a device profile reads from its device, on the way to the hub: the reading
    fields of :class:`DriveState`, each optional (a profile gives what it has). Typed keys:
    a misspelt field or a wrong type fails in mypy; at run time it is a plain dict (the
    hub's hot path stays as it was). ``comm`` is not a reading: the adapter adds it
    (:class:`DriveUpdate`)."""

    status: DriveStatus
    running: bool
    direction: Direction
    at_reference: bool
    remote: bool
    alarm: bool
    speed_rpm: float | None
    speed_pct: float | None
    speed_ref_rpm: float | None
    speed_ref_pct: float | None
    current_a: float | None
    current_pct_flc: float | None
    motor_temp_pct: float | None
    power_kw: float | None
    voltage_v: float | None
    fault_code: int | None
    fault_text: str | None
    alarm_code: int | None
    speed_base: str | None
    values: Mapping[str, float | int]
    local_control: bool
    failsafe: bool | None
    failsafe_text: str | None
    doubtful: bool


class DriveUpdate(Readings, total=False):
    """What an adapter reports to the hub (``HubPort.update``): readings and the drive's
    communication state."""

    comm: CommState


_set_attribute = object.__setattr__

_STATE_FIELDS: frozenset[str] = frozenset(f.name for f in fields(DriveState))
if tuple(f.name for f in fields(DriveState)) != PUBLISHED_FIELDS:
    # a state's ``__dict__`` holds its fields in this order (``__init__`` and ``changed``
    # keep it): the encoder writes it as it is, so the JSON form's order is checked here
    raise ImportError("DriveState's fields are not PUBLISHED_FIELDS in order")
STATE_FIELDS = _STATE_FIELDS
"""Every field name of DriveState."""


def _json_value(value: Any) -> Any:
    if isinstance(value, DriveStatus):
        return value.label
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return dict(value)
    return value


def _identity(value: Any) -> Any:
    return value


_FROM_JSON: dict[str, Any] = {
    "device": Device,
    "comm": CommState,
    "status": lambda v: DriveStatus[str(v).upper()],
    "direction": Direction,
    "control_source": Source,
    "values": dict,
}


# ---------------------------------------------------------------- commands

COMMAND_FIELDS: tuple[str, ...] = (
    "run",
    "direction",
    "speed_rpm",
    "speed_pct",
    "fault_reset",
    "quick_stop",
    "coast_stop",
    "jog",
    "remote",
)


@dataclass(frozen=True, slots=True)
class DriveCommand:
    """A partial command: ``None`` means "leave as it is".

    ``fault_reset`` True asks for one reset edge; it is never stored as a level.
    """

    run: bool | None = None
    direction: Direction | None = None
    speed_rpm: float | None = None
    speed_pct: float | None = None
    fault_reset: bool = False
    quick_stop: bool | None = None
    coast_stop: bool | None = None
    jog: bool | None = None
    remote: bool | None = None

    def __post_init__(self) -> None:
        if self.speed_rpm is not None and self.speed_pct is not None:
            raise CommandRejected("give speed_rpm or speed_pct, not both")
        for name in ("speed_rpm", "speed_pct"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise CommandRejected(f"{name} must be a finite number")

    @property
    def has_speed(self) -> bool:
        return self.speed_rpm is not None or self.speed_pct is not None

    @property
    def is_empty(self) -> bool:
        return self == DriveCommand()

    @classmethod
    def from_json(cls, data: Any) -> DriveCommand:
        """Parse the northbound JSON command; every problem is a CommandRejected."""
        if not isinstance(data, Mapping):
            raise CommandRejected("a command is a JSON object")
        unknown = sorted(set(data) - set(COMMAND_FIELDS))
        if unknown:
            raise CommandRejected(f"unknown field(s): {', '.join(unknown)}")
        kwargs: dict[str, Any] = {}
        for name, value in data.items():
            kwargs[name] = _COMMAND_PARSERS[name](name, value)
        if kwargs.get("fault_reset") is None:
            kwargs.pop("fault_reset", None)
        return cls(**kwargs)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in COMMAND_FIELDS:
            value = getattr(self, name)
            if name == "fault_reset":
                if value:
                    out[name] = True
            elif value is not None:
                out[name] = _json_value(value)
        return out


def _parse_bool(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise CommandRejected(f"{name} must be true or false, not {value!r}")
    return value


def _parse_number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CommandRejected(f"{name} must be a number, not {value!r}")
    if not math.isfinite(value):
        raise CommandRejected(f"{name} must be a finite number")
    return float(value)


def _parse_direction(name: str, value: Any) -> Direction:
    try:
        return Direction(value)
    except ValueError:
        raise CommandRejected(f"{name} must be 'forward' or 'reverse', not {value!r}") from None


_COMMAND_PARSERS: dict[str, Any] = {
    "run": _parse_bool,
    "direction": _parse_direction,
    "speed_rpm": _parse_number,
    "speed_pct": _parse_number,
    "fault_reset": _parse_bool,
    "quick_stop": _parse_bool,
    "coast_stop": _parse_bool,
    "jog": _parse_bool,
    "remote": _parse_bool,
}


@dataclass(frozen=True, slots=True)
class DesiredCommand:
    """The complete command the gateway wants a drive to follow.

    ``fault_reset_seq`` counts reset requests: an adapter sends one reset edge
    each time it sees the number grow, and never repeats it on its own.
    ``speed_rpm`` / ``speed_pct``: at most one is set (the last one given).
    """

    run: bool = False
    direction: Direction = Direction.FORWARD
    speed_rpm: float | None = None
    speed_pct: float | None = None
    quick_stop: bool = False
    coast_stop: bool = False
    jog: bool = False
    remote: bool = True
    fault_reset_seq: int = 0
    source: Source = Source.NONE
    client: str = ""
    """Which client of ``source`` gave it (a Modbus peer address, a Zenoh session id)."""

    @property
    def controller(self) -> tuple[Source, str]:
        """The client in control (safety rule 3): its source and its id within it."""
        return self.source, self.client

    def merged(self, cmd: DriveCommand, source: Source, client: str = "") -> DesiredCommand:
        """This command with the given fields of a partial command applied."""
        changes: dict[str, Any] = {"source": source, "client": client}
        for name in ("run", "direction", "quick_stop", "coast_stop", "jog", "remote"):
            value = getattr(cmd, name)
            if value is not None:
                changes[name] = value
        if cmd.speed_rpm is not None:
            changes.update(speed_rpm=cmd.speed_rpm, speed_pct=None)
        if cmd.speed_pct is not None:
            changes.update(speed_pct=cmd.speed_pct, speed_rpm=None)
        if cmd.fault_reset:
            changes["fault_reset_seq"] = self.fault_reset_seq + 1
        return replace(self, **changes)

    def stopped(self, action: StopAction, source: Source) -> DesiredCommand:
        """This command after a stop action (HOLD leaves it as it is)."""
        if action is StopAction.HOLD:
            return self
        return replace(
            self,
            run=False,
            jog=False,
            coast_stop=action is StopAction.COAST,
            source=source,
            client="",
        )

    def to_json(self) -> dict[str, Any]:
        return {f.name: _json_value(getattr(self, f.name)) for f in fields(self)}


@dataclass(frozen=True, slots=True)
class SpeedScale:
    """How a drive's speed maps to percent: ``base_rpm`` is 100 %.

    ``max_pct`` bounds references (for example 13-bit speed saturating at 400 %).
    """

    base_rpm: float
    max_pct: float = 100.0
    label: str = "configured"

    def rpm_to_pct(self, rpm: float) -> float:
        return 100.0 * rpm / self.base_rpm

    def pct_to_rpm(self, pct: float) -> float:
        return pct * self.base_rpm / 100.0

    @property
    def max_rpm(self) -> float:
        return self.pct_to_rpm(self.max_pct)
