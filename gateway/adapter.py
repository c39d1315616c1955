"""The contract between the gateway core and the fieldbus adapters.

The core never imports an adapter: the config loader finds an adapter's class by its
registered name (:func:`gateway.config.load_adapter`) and imports it lazily.

An adapter owns the schema of its bus table and of its drives' extra keys
(``parse_bus_options`` / ``parse_drive_options``, the class side of the contract:
:class:`gateway.config.AdapterClass`), runs against the hub until cancelled
(cancellation is the signal to leave the bus cleanly), serves parameter reads and
writes, and reports its bus diagnostics.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Any, Protocol, Unpack, runtime_checkable

from gateway.model import DesiredCommand, DriveState, DriveUpdate, SpeedScale

ParamValue = int | float


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

    def on_command(self, listener: Callable[[str], None]) -> Callable[[], None]:
        """Call ``listener(drive_id)`` on the adapter's own loop whenever a drive's desired
        command changed (the adapter need not read ``desired`` on every cycle to see a
        new one: a line's steady fast path); returns the call that ends it."""
        ...


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
