"""The contract between the gateway core and the fieldbus adapters.

The core never imports an adapter: the daemon and the config loader find an
adapter class through :data:`ADAPTERS` (name -> "module:Class") and import it
lazily. A third-party adapter is an installed distribution that declares an
entry point in the group :data:`ENTRY_POINT_GROUP` (``drive_gateway.adapters``);
its name cannot shadow one of the project's. A config file names an adapter by
its registered name only: a ``"module:Class"`` path in a config is refused and
never imported (a config file must not choose code to run, docs/decisions.md).

An adapter owns the schema of its bus table and of its drives' extra keys
(``parse_bus_options`` / ``parse_drive_options``), runs against the hub until
cancelled (cancellation is the signal to leave the bus cleanly), serves
parameter reads and writes, and reports its bus diagnostics.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.metadata
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, Unpack, runtime_checkable

from gateway.errors import AdapterError
from gateway.loader import NotLoadable, load
from gateway.model import DesiredCommand, Device, DriveState, DriveUpdate, SpeedScale

if TYPE_CHECKING:
    from gateway.config import BusConfig, DriveConfig
    from gateway.schema import Table

ParamValue = int | float

ADAPTERS: dict[str, str] = {
    "profibus": "adapters.profibus.adapter:ProfibusAdapter",
    "devicenet": "adapters.devicenet.adapter:DeviceNetAdapter",
    "canopen": "adapters.canopen.adapter:CanOpenAdapter",
}
"""Adapter name (the ``adapter`` key of a bus table) -> "module:Class"."""

ENTRY_POINT_GROUP = "drive_gateway.adapters"
"""Where installed third-party adapters declare themselves (name = "module:Class")."""

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")


class EventKind(Enum):
    COMM = "comm"
    FAULT = "fault"
    TRIP = "trip"
    ALARM = "alarm"
    COMMAND = "command"
    COMMAND_REFUSED = "command_refused"
    SAFETY = "safety"
    CONTROL = "control"
    PARAMETER = "parameter"
    CONFIG = "config"
    BUS = "bus"


@dataclass(frozen=True, slots=True)
class Event:
    drive_id: str
    kind: EventKind
    text: str
    ts: float
    data: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "drive": self.drive_id,
            "kind": self.kind.value,
            "text": self.text,
            "ts": self.ts,
            **dict(self.data),
        }


@dataclass(frozen=True, slots=True)
class ParamInfo:
    """What a device's manual (or its EDS) says of one parameter.

    The front ends name a raw value and put it in its unit with it; the core never needs the
    adapter for that. ``code`` is the number as the manual writes it ("P0100", "P100"; empty:
    ``P<number>``). The value in its unit is ``(raw + offset) * multiplier / 10**decimals``:
    a WEG table gives only ``decimals`` ("P0100 = 5.0 s is sent as 50"); an EDS may also give
    a multiplier and an offset. ``minimum``/``maximum`` are in the unit, None when not given.
    """

    number: int
    name: str
    unit: str = ""
    decimals: int = 0
    minimum: float | None = None
    maximum: float | None = None
    code: str = ""
    multiplier: float = 1.0
    offset: float = 0.0

    @property
    def label(self) -> str:
        return self.code or f"P{self.number}"

    def scaled(self, raw: ParamValue) -> ParamValue:
        """``raw`` in the parameter's unit (an int when nothing scales it)."""
        if not self.decimals and self.multiplier == 1.0 and not self.offset:
            return raw
        value = (raw + self.offset) * self.multiplier / float(10**self.decimals)
        return round(value, self.decimals) if self.multiplier == 1.0 else value


ParamTable = Mapping[int, ParamInfo]
"""Parameter number -> :class:`ParamInfo`, as a drive's adapter declares it (capabilities)."""


def param_table(infos: Iterable[ParamInfo]) -> ParamTable:
    """A read-only table keyed by number (a number given twice is a data error)."""
    table: dict[int, ParamInfo] = {}
    for info in infos:
        if info.number in table:
            raise ValueError(f"parameter {info.number} listed twice")
        table[info.number] = info
    return MappingProxyType(table)


@dataclass(frozen=True, slots=True)
class Capabilities:
    """What a drive can be commanded to do, as its adapter knows it.

    ``speed_scale`` None: the device has no speed (a soft starter).
    ``unsupported``: command field -> the reason it is refused for this drive.
    ``alarm_texts``: alarm code -> the device's own text, for the alarm events (a code
    missing here is shown as its number only).
    ``reverse_refused``: None when the drive can turn in reverse; else the reason a
    command asking for reverse (a negative ``speed_rpm`` or ``speed_pct``, or
    ``direction`` reverse) is refused.
    ``params``: what the drive's manual (or EDS) says of its parameters, by number: the
    lookup the front ends name parameter values with (empty: numbers and raw values only).
    """

    speed_scale: SpeedScale | None = None
    unsupported: Mapping[str, str] = field(default_factory=dict)
    alarm_texts: Mapping[int, str] = field(default_factory=dict)
    reverse_refused: str | None = None
    params: ParamTable = field(default_factory=dict)
    run_needs_ready: bool = False
    """A run command while the drive is ``not_ready`` is refused (a soft starter that is not
    ready does not keep a start for later: docs/safety.md)."""
    stop_substitutes: Mapping[str, str] = field(default_factory=dict)
    """A stop kind the drive lacks -> the nearest one it has (safety rule 1 of
    docs/architecture.md, "a stop is never refused"): ``"quick_stop": "coast_stop"``
    or ``"quick_stop": "run"`` (a ramp stop). The hub applies the substitute and says
    so once in a ``safety`` event; a stop kind listed here is never refused."""


class HubPort(Protocol):
    """What an adapter may do with the hub."""

    def state(self, drive_id: str) -> DriveState: ...

    def update(self, drive_id: str, **changes: Unpack[DriveUpdate]) -> DriveState:
        """Report readings (typed: :class:`gateway.model.DriveUpdate`)."""
        ...

    def desired(self, drive_id: str) -> DesiredCommand: ...

    def set_capabilities(self, drive_id: str, caps: Capabilities) -> None: ...

    def event(self, drive_id: str, kind: EventKind, text: str, **data: Any) -> None: ...

    def now(self) -> float: ...


@runtime_checkable
class DriveAdapter(Protocol):
    """One fieldbus line and its drives."""

    name: str

    async def run(self, hub: HubPort) -> None:
        """Run the bus until cancelled; on cancellation leave the bus cleanly."""
        ...

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue: ...

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None: ...

    def diagnostics(self) -> dict[str, Any]:
        """Bus figures: line-level keys, and per drive under ``"drives"``."""
        ...


class AdapterClass(Protocol):
    """The class-level side of an adapter: its schema and its constructor. An adapter may
    also define ``check_bus(table, bus_options, drive_options)``, a classmethod raising a
    ConfigError for a rule across the bus's drives (the config reader calls it once the
    drives are read), and ``safety_warnings(bus, drive)``, a classmethod returning what
    ``check-config`` warns of a drive's safety settings (a reaction to a lost master
    switched off; docs/safety.md): see :func:`safety_warnings`."""

    devices: ClassVar[frozenset[Device]]
    address_range: ClassVar[tuple[int, int]]

    @classmethod
    def parse_bus_options(cls, table: Table) -> Any: ...

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> Any: ...

    def __call__(self, bus: BusConfig, *, links: Any = None) -> DriveAdapter:
        """``links``: the line the composition root chose for the adapter (a simulated line
        for ``simulate = true``, given only then); None: the adapter's configured line."""
        ...


def _installed() -> dict[str, importlib.metadata.EntryPoint]:
    """Adapters declared by installed distributions (the project's own names win)."""
    try:
        points = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    except Exception:  # broken metadata of some distribution: no third-party adapters
        return {}
    return {ep.name: ep for ep in points if ep.name not in ADAPTERS}


def adapter_names() -> list[str]:
    """Every name a bus table may give as its ``adapter``."""
    return sorted({*ADAPTERS, *_installed()})


def _unknown(name: str) -> AdapterError:
    known = adapter_names()
    close = difflib.get_close_matches(name, known, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    if ":" in name or "." in name:
        return AdapterError(
            f"{name!r} is not an adapter name: a config names a registered adapter "
            f"({', '.join(known)}), never a module; a third-party adapter is installed "
            f"as an entry point in the group {ENTRY_POINT_GROUP!r}{hint}"
        )
    return AdapterError(f"unknown adapter {name!r} (known: {', '.join(known)}){hint}")


def _import(name: str, target: str) -> Any:
    try:
        return load(target)
    except NotLoadable as exc:
        raise AdapterError(f"adapter {name!r}: {exc}") from None
    except Exception as exc:  # an adapter that cannot be imported, for whatever reason
        raise AdapterError(f"adapter {name!r} is not available: {exc}") from exc


def load_adapter(name: str) -> AdapterClass:
    """The adapter class registered as ``name`` (the project's table, then installed
    entry points); raises :class:`AdapterError` naming the reason. Nothing is imported
    for a name that is not registered."""
    if not _NAME.fullmatch(name):
        raise _unknown(name)
    if name in ADAPTERS:
        cls = _import(name, ADAPTERS[name])
    else:
        point = _installed().get(name)
        if point is None:
            raise _unknown(name)
        cls = _import(name, point.value)
    _check_class_side(name, cls)
    result: AdapterClass = cls
    return result


def safety_warnings(bus: BusConfig, drive: DriveConfig) -> list[str]:
    """What the drive's adapter warns of its safety settings, read from the config alone
    (``check-config``; nothing is opened): each a line naming the drive, the key or the
    drive's parameter, and what follows from it."""
    cls = load_adapter(bus.adapter)
    hook = getattr(cls, "safety_warnings", None)
    if not callable(hook):
        return []
    return [str(w) for w in hook(bus, drive)]


def _check_class_side(name: str, cls: object) -> None:
    missing = [a for a in _CLASS_SIDE if not hasattr(cls, a)]
    if not isinstance(cls, type) or missing:
        raise AdapterError(
            f"adapter {name!r} is not a drive adapter class (missing: {', '.join(missing)})"
        )


_CLASS_SIDE = ("devices", "address_range", "parse_bus_options", "parse_drive_options")
