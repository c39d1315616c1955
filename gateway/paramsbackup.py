"""Parameter backup, compare and restore: the document, and the steps that make it.

Sans-IO but for one injected coroutine, ``read(number, subindex)`` (the hub's read in the
daemon, a Zenoh query per parameter in the command line): every device family works through
the parameter service it already has (WEG DP-V1 records, the MCD 600 parameter mode, the
CFW-08 explicit messages). The numbers come from the drive's parameter table
(``Capabilities.params``) or from a list given by the user.

The document (``SCHEMA``, version :data:`SCHEMA_VERSION`, docs/operations.md "Parameter
backup and restore"): the drive (id, device, bus, address), the identity the bus gives,
the firmware where it can be read, when it was taken and by which gateway, and per
parameter number, subindex, code, name, unit, raw and scaled value, or the device's error.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from gateway.adapter import ParamInfo, ParamTable, ParamValue, param_table
from gateway.devices import Device
from gateway.errors import GatewayError, ParameterError

SCHEMA = "drive-gateway/params-backup"
SCHEMA_VERSION = 1

Reader = Callable[[int, int], Awaitable[ParamValue]]
"""``read(number, subindex)``: the raw value; raises with the device's error."""
Progress = Callable[[int, int, "ParamEntry"], None]
"""``progress(done, total, entry)`` after each parameter."""

VERSION_VALUES = ("software_version_major", "software_version_minor")
"""State ``values`` with the firmware (MCD 600 data request 15, guide 4.2)."""

IDENTITY_KEYS = (
    "vendor_id",
    "product_code",
    "product_name",
    "revision",
    "serial_number",
    "ident_number",
)
"""Diagnostics fields that identify the device (DeviceNet identity object, Profibus ident)."""

MAX_NUMBERS = 4096
"""Parameters in one backup at most (a range given by mistake is refused, not read)."""


class BackupError(GatewayError, ValueError):
    """A backup file or a request that cannot be used; the text says why."""


# ---------------------------------------------------------------- the document


@dataclass(frozen=True, slots=True)
class ParamEntry:
    """One parameter as read: ``raw`` (and ``scaled``), or ``error`` (and ``error_code``)."""

    number: int
    subindex: int = 0
    code: str = ""
    name: str = ""
    unit: str = ""
    raw: ParamValue | None = None
    scaled: ParamValue | None = None
    error: str | None = None
    error_code: int | None = None

    @property
    def key(self) -> tuple[int, int]:
        return self.number, self.subindex

    @property
    def label(self) -> str:
        code = self.code or f"P{self.number}"
        return f"{code}.{self.subindex}" if self.subindex else code

    def shown(self) -> str:
        """``2.0 s`` (scaled, in its unit), the raw value, or ``error: text``."""
        if self.error is not None:
            return f"error: {self.error}"
        value = self.raw if self.scaled is None else self.scaled
        return f"{value} {self.unit}".rstrip() if self.unit else str(value)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"number": self.number, "subindex": self.subindex}
        for name in ("code", "name", "unit"):
            if getattr(self, name):
                out[name] = getattr(self, name)
        if self.error is None:
            out["raw"] = self.raw
            out["scaled"] = self.scaled
        else:
            out["error"] = self.error
            if self.error_code is not None:
                out["error_code"] = self.error_code
        return out

    @classmethod
    def from_json(cls, doc: Any, where: str) -> ParamEntry:
        if not isinstance(doc, Mapping):
            raise BackupError(f"{where}: a parameter is an object")
        number = _int(doc.get("number"), f"{where}.number", 0, 65535)
        subindex = _int(doc.get("subindex", 0), f"{where}.subindex", 0, 65535)
        texts = {k: doc.get(k, "") for k in ("code", "name", "unit")}
        for key, text in texts.items():
            if not isinstance(text, str):
                raise BackupError(f"{where}.{key}: a string")
        error = doc.get("error")
        if error is not None:
            if not isinstance(error, str):
                raise BackupError(f"{where}.error: a string")
            code = doc.get("error_code")
            return cls(number, subindex, **texts, error=error, error_code=_opt_int(code, where))
        raw = _number(doc.get("raw"), f"{where}.raw")
        scaled = doc.get("scaled")
        scaled = None if scaled is None else _number(scaled, f"{where}.scaled")
        return cls(number, subindex, **texts, raw=raw, scaled=scaled)


@dataclass(frozen=True, slots=True)
class Identity:
    """Which drive a backup is of."""

    id: str
    device: str
    bus: str = ""
    address: int | None = None
    identity: Mapping[str, Any] = field(default_factory=dict)
    firmware: str | None = None
    firmware_source: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "device": self.device,
            "bus": self.bus,
            "address": self.address,
            "identity": dict(self.identity),
            "firmware": self.firmware,
            "firmware_source": self.firmware_source,
        }

    @classmethod
    def from_json(cls, doc: Any) -> Identity:
        if not isinstance(doc, Mapping):
            raise BackupError("drive: an object")
        for key in ("id", "device"):
            if not isinstance(doc.get(key), str) or not doc[key]:
                raise BackupError(f"drive.{key}: a non-empty string")
        identity = doc.get("identity", {})
        if not isinstance(identity, Mapping):
            raise BackupError("drive.identity: an object")
        firmware = doc.get("firmware")
        return cls(
            id=doc["id"],
            device=doc["device"],
            bus=str(doc.get("bus", "")),
            address=_opt_int(doc.get("address"), "drive.address"),
            identity=dict(identity),
            firmware=None if firmware is None else str(firmware),
            firmware_source=str(doc.get("firmware_source", "")),
        )


@dataclass(frozen=True, slots=True)
class Backup:
    drive: Identity
    params: tuple[ParamEntry, ...]
    taken: str = ""  # ISO 8601, UTC
    gateway: str = ""  # the gateway's name and version

    def to_json(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "version": SCHEMA_VERSION,
            "taken": self.taken,
            "gateway": self.gateway,
            "drive": self.drive.to_json(),
            "params": [p.to_json() for p in self.params],
        }

    @classmethod
    def from_json(cls, doc: Any) -> Backup:
        """A backup document, checked; :class:`BackupError` names what is wrong."""
        if not isinstance(doc, Mapping) or doc.get("schema") != SCHEMA:
            raise BackupError(f'not a parameter backup (no "schema": "{SCHEMA}")')
        version = doc.get("version")
        if version != SCHEMA_VERSION:
            raise BackupError(
                f"backup format version {version!r}; this drive-gateway reads {SCHEMA_VERSION}"
            )
        params = doc.get("params")
        if not isinstance(params, list):
            raise BackupError("params: a list")
        entries = tuple(ParamEntry.from_json(p, f"params[{i}]") for i, p in enumerate(params))
        keys = [e.key for e in entries]
        if len(set(keys)) != len(keys):
            raise BackupError("params: a parameter is listed twice")
        return cls(
            drive=Identity.from_json(doc.get("drive")),
            params=entries,
            taken=str(doc.get("taken", "")),
            gateway=str(doc.get("gateway", "")),
        )

    def by_key(self) -> dict[tuple[int, int], ParamEntry]:
        return {p.key: p for p in self.params}


def now_iso() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


def _int(value: Any, where: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise BackupError(f"{where}: an integer {low}-{high}, not {value!r}")
    return value


def _opt_int(value: Any, where: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int):
        raise BackupError(f"{where}: an integer, not {value!r}")
    return value


def _number(value: Any, where: str) -> ParamValue:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BackupError(f"{where}: a number, not {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise BackupError(f"{where}: a finite number")
    return value


# ---------------------------------------------------------------- which parameters


def parse_numbers(text: str) -> tuple[tuple[int, int], ...]:
    """``"100-103,134,P0313,964.2"`` -> (number, subindex) pairs, in the order given."""
    out: list[tuple[int, int]] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        low_text, dash, high_text = part.partition("-")
        if dash:
            low, high = _one(low_text)[0], _one(high_text)[0]
            if high < low:
                raise BackupError(f"{part!r}: the range ends below its start")
            if high - low >= MAX_NUMBERS:
                raise BackupError(f"{part!r}: over {MAX_NUMBERS} parameters")
            out += [(n, 0) for n in range(low, high + 1)]
        else:
            out.append(_one(part))
    if not out:
        raise BackupError("no parameter given (e.g. 100-103,134,P0313)")
    if len(out) > MAX_NUMBERS:
        raise BackupError(f"over {MAX_NUMBERS} parameters")
    return tuple(dict.fromkeys(out))


def _one(text: str) -> tuple[int, int]:
    text = text.strip()
    digits = text[1:] if text[:1] in ("P", "p") else text
    number_text, dot, sub_text = digits.partition(".")
    if not number_text.isascii() or not number_text.isdigit():
        raise BackupError(f"{text!r} is not a parameter number (100, P0100 or 964.2)")
    if dot and (not sub_text.isascii() or not sub_text.isdigit()):
        raise BackupError(f"{text!r}: the subindex is not a number")
    number, subindex = int(number_text), int(sub_text) if dot else 0
    if number > 65535 or subindex > 65535:
        raise BackupError(f"{text!r}: beyond 65535")
    return number, subindex


def choose(
    table: ParamTable,
    asked: Sequence[tuple[int, int]] | None,
    entries: Iterable[tuple[int, int]] = (),
) -> list[tuple[int, int]]:
    """What to read: the given list, else every number of the drive's table (subindex 0)
    and the subindex entries of its ``writable_params`` (``"0x2000:4"``), in order."""
    if asked:
        return list(asked)
    extra = set(entries)
    if not table and not extra:
        raise BackupError(
            "the drive has no parameter table (docs/devices.md): give the parameters, "
            "e.g. 1-20 or 100,101"
        )
    return sorted({(n, 0) for n in table} | extra)


def entries_to_json(entries: Iterable[tuple[int, int]]) -> list[list[int]]:
    """``writable_params``' subindex entries (``"0x2000:4"``) as ``[[8192, 4]]``, for the
    ``params?describe`` answer (``writable_entries``)."""
    return [[number, subindex] for number, subindex in sorted(entries)]


def entries_from_json(value: Any) -> frozenset[tuple[int, int]]:
    """The ``writable_entries`` of a ``params?describe`` answer (absent: none)."""
    if value is None:
        return frozenset()
    if not isinstance(value, list):
        raise BackupError(f"writable_entries: not a list: {value!r}")
    out: set[tuple[int, int]] = set()
    for i, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2:
            raise BackupError(f"writable_entries[{i}]: not a [number, subindex] pair: {pair!r}")
        where = f"writable_entries[{i}]"
        out.add((_int(pair[0], where, 0, 65535), _int(pair[1], where, 0, 255)))
    return frozenset(out)


# ---------------------------------------------------------------- reading


def entry_of(number: int, subindex: int, info: ParamInfo | None, raw: ParamValue) -> ParamEntry:
    if info is None:
        return ParamEntry(number, subindex, raw=raw, scaled=raw)
    return ParamEntry(
        number, subindex, info.label, info.name, info.unit, raw=raw, scaled=info.scaled(raw)
    )


def error_entry(number: int, subindex: int, info: ParamInfo | None, exc: Exception) -> ParamEntry:
    if isinstance(exc, ParameterError):
        text, code = exc.text, exc.code
    elif isinstance(exc, TimeoutError):
        text, code = f"no answer ({exc})" if str(exc) else "no answer", None
    else:
        text, code = str(exc) or type(exc).__name__, None
    named = (info.label, info.name, info.unit) if info is not None else ("", "", "")
    return ParamEntry(number, subindex, *named, error=text, error_code=code)


async def read_entry(
    number: int, subindex: int, info: ParamInfo | None, read: Reader
) -> ParamEntry:
    """One parameter, or its error (a refusal, a timeout): a backup goes on after either."""
    try:
        raw = await read(number, subindex)
    except (GatewayError, TimeoutError) as exc:
        return error_entry(number, subindex, info, exc)
    return entry_of(number, subindex, info, raw)


async def read_all(
    numbers: Iterable[tuple[int, int]],
    table: ParamTable,
    read: Reader,
    progress: Progress | None = None,
) -> tuple[ParamEntry, ...]:
    todo = list(numbers)
    entries: list[ParamEntry] = []
    for number, subindex in todo:
        entry = await read_entry(number, subindex, table.get(number), read)
        entries.append(entry)
        if progress is not None:
            progress(len(entries), len(todo), entry)
    return tuple(entries)


def _firmware_param(model: str) -> int | None:
    """The parameter holding the firmware version of a device model (its registration in
    gateway/devices.py), None for a model without one or not known."""
    try:
        return Device(model).spec.firmware_param
    except ValueError:
        return None


async def firmware_of(
    device: str, values: Mapping[str, Any], diag: Mapping[str, Any], table: ParamTable, read: Reader
) -> tuple[str | None, str]:
    """The firmware version and where it came from (or why there is none)."""
    major, minor = (values.get(k) for k in VERSION_VALUES)
    if isinstance(major, int) and isinstance(minor, int):
        return f"{major}.{minor}", "state values software_version_major/minor"
    revision = diag.get("revision")
    if revision is not None:
        return str(revision), "identity object revision"
    number = _firmware_param(device)
    if number is None:
        return None, f"the {device}'s firmware version is not readable through the gateway"
    entry = await read_entry(number, 0, table.get(number), read)
    if entry.error is not None:
        return None, f"{entry.label}: {entry.error}"
    info = table.get(number)
    if info is not None and info.decimals and entry.scaled is not None:
        return f"{entry.scaled:.{info.decimals}f}", entry.label
    return str(entry.scaled), entry.label


async def identify(
    state: Mapping[str, Any], diag: Mapping[str, Any], table: ParamTable, read: Reader
) -> Identity:
    """The drive as a backup names it, from its state (JSON) and diagnostics."""
    device = str(state.get("device"))
    values = state.get("values") or {}
    firmware, source = await firmware_of(device, values, diag, table, read)
    address = state.get("address")
    return Identity(
        id=str(state.get("id")),
        device=device,
        bus=str(state.get("bus", "")),
        address=address if isinstance(address, int) else None,
        identity={k: diag[k] for k in IDENTITY_KEYS if diag.get(k) is not None},
        firmware=firmware,
        firmware_source=source,
    )


async def take(
    drive: Identity,
    table: ParamTable,
    asked: Sequence[tuple[int, int]] | None,
    read: Reader,
    *,
    gateway: str = "",
    progress: Progress | None = None,
    entries: Iterable[tuple[int, int]] = (),
) -> Backup:
    """Read the parameters (:func:`choose`; ``entries``: ``writable_params``' subindex
    entries, read beside the table's numbers) into a backup document."""
    numbers = choose(table, asked, entries)
    params = await read_all(numbers, table, read, progress)
    return Backup(drive=drive, params=params, taken=now_iso(), gateway=gateway)


# ---------------------------------------------------------------- the table over the wire


def table_to_json(table: ParamTable) -> list[dict[str, Any]]:
    return [
        {
            "number": i.number,
            "code": i.label,
            "name": i.name,
            "unit": i.unit,
            "decimals": i.decimals,
            "minimum": i.minimum,
            "maximum": i.maximum,
            "multiplier": i.multiplier,
            "offset": i.offset,
        }
        for i in (table[n] for n in sorted(table))
    ]


def table_from_json(rows: Any) -> ParamTable:
    if not isinstance(rows, list):
        raise BackupError("table: a list")
    try:
        return param_table(
            ParamInfo(
                number=int(r["number"]),
                name=str(r["name"]),
                unit=str(r.get("unit", "")),
                decimals=int(r.get("decimals", 0)),
                minimum=r.get("minimum"),
                maximum=r.get("maximum"),
                code=str(r.get("code", "")),
                multiplier=float(r.get("multiplier", 1.0)),
                offset=float(r.get("offset", 0.0)),
            )
            for r in rows
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise BackupError(f"table: {exc}") from None


def reading_table(drive_table: ParamTable, backup: Backup) -> ParamTable:
    """The table to read a file's parameters back from a drive with, so both sides of a
    compare are in the same unit: the drive's own table (its decimals, multiplier and
    offset), and for a number it lacks, the file's name without a unit (the file keeps no
    scale, so such a value is shown raw, never a raw value with a unit beside it)."""
    rows = dict(drive_table)
    for entry in backup.params:
        if entry.number not in rows and entry.name:
            unscaled = type(entry.scaled) is type(entry.raw) and entry.scaled == entry.raw
            unit = entry.unit if unscaled else ""
            rows[entry.number] = ParamInfo(entry.number, entry.name, unit, code=entry.code)
    return param_table(rows.values())


# ---------------------------------------------------------------- compare


@dataclass(frozen=True, slots=True)
class DiffRow:
    label: str
    name: str
    left: str
    right: str
    status: str  # "same", "differs", "only left", "only right", "error"

    def to_json(self) -> dict[str, str]:
        return {
            "parameter": self.label,
            "name": self.name,
            "left": self.left,
            "right": self.right,
            "status": self.status,
        }


def compare(left: Iterable[ParamEntry], right: Iterable[ParamEntry]) -> list[DiffRow]:
    """Both sides by (number, subindex), in number order; raw values are compared."""
    a = {e.key: e for e in left}
    b = {e.key: e for e in right}
    rows = []
    for key in sorted(a.keys() | b.keys()):
        one, other = a.get(key), b.get(key)
        some = a[key] if key in a else b[key]  # the key came from one side or the other
        if one is None or other is None:
            status = "only left" if other is None else "only right"
        elif one.error is not None or other.error is not None:
            status = "same" if one.error == other.error else "error"
        else:
            status = "same" if one.raw == other.raw else "differs"
        rows.append(
            DiffRow(
                some.label,
                some.name,
                "-" if one is None else one.shown(),
                "-" if other is None else other.shown(),
                status,
            )
        )
    return rows


# ---------------------------------------------------------------- restore


@dataclass(frozen=True, slots=True)
class Step:
    """What a restore does with one parameter of the file."""

    entry: ParamEntry  # the file's
    action: str  # "write", "same", "skip"
    reason: str = ""
    current: ParamEntry | None = None


def plan(
    backup: Backup,
    current: Mapping[tuple[int, int], ParamEntry],
    writable: Iterable[int],
    drive_id: str,
    entries: Iterable[tuple[int, int]] = (),
) -> list[Step]:
    """The restore, in number order: what differs and may be written is written; the rest
    is left with the reason (docs/operations.md). ``writable``: whole numbers of
    ``writable_params`` (every subindex); ``entries``: its ``"0x2000:4"`` entries (that
    subindex only)."""
    allowed = frozenset(writable)
    allowed_entries = frozenset(entries)
    steps = []
    for entry in sorted(backup.params, key=lambda e: e.key):
        now = current.get(entry.key)
        if entry.error is not None:
            steps.append(Step(entry, "skip", f"not in the file (when taken: {entry.error})", now))
        elif now is None or now.error is not None:
            why = "not read" if now is None else now.error
            steps.append(Step(entry, "skip", f"cannot be read from the drive: {why}", now))
        elif now.raw == entry.raw:
            steps.append(Step(entry, "same", "", now))
        elif entry.number not in allowed and entry.key not in allowed_entries:
            steps.append(Step(entry, "skip", f"not in writable_params of drive {drive_id}", now))
        else:
            steps.append(Step(entry, "write", "", now))
    return steps


def check_target(backup: Backup, state: Mapping[str, Any]) -> None:
    """Refuse a restore onto another device model (numbers mean other things there)."""
    device = state.get("device")
    if device != backup.drive.device:
        raise BackupError(
            f"the file is of a {backup.drive.device} ({backup.drive.id}); "
            f"drive {state.get('id')} is a {device}"
        )


STOPPED_STATUSES = frozenset({"not_ready", "ready", "faulted", "tripped"})


def not_stopped(state: Mapping[str, Any]) -> str | None:
    """Why a restore may not write to this drive now, or None (online and stopped)."""
    drive = state.get("id")
    if state.get("comm") != "online":
        return f"drive {drive} is not online (comm {state.get('comm')})"
    status = state.get("status")
    if state.get("running") or status not in STOPPED_STATUSES:
        return f"drive {drive} is running (status {status}): stop it before a restore"
    return None
