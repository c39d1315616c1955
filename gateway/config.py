"""The gateway's configuration: one TOML file read into frozen dataclasses.

Layout (see config/site.example.toml for every key)::

    [gateway]            name, log_level, library_log_level, shutdown_timeout, tick
    [zenoh]              prefix, mode, listen, connect, multicast_scouting, heartbeat, config_file
    [modbus]             bind, allow, read_only, gateway_unit, frame_timeout, max_connections,
                         max_connections_per_peer, idle_timeout
    [web]                bind, allow, names, commands, tls_cert, tls_key, anonymous
                         (gateway/webconfig.py)
    [history]            enabled, path, period, batch_interval, max_age, max_size_mb
    [opcua]              enabled, bind, security, certificate, private_key, trusted_clients,
                         publish_interval, max_sessions, max_subscriptions,
                         max_monitored_items, min_publishing_interval
                         (gateway/opcuaconfig.py)
    [[users]]            name, role, password, token_sha256 (gateway/access/users.py)
    [audit]              file, max_kib, backups, journal (gateway/access/audit.py)
    [buses.<name>]       adapter = "profibus" | "devicenet" | an installed adapter's name
                         (never a module path: :func:`load_adapter`), plus the adapter's keys
    [[buses.<name>.drives]]  id, device, address, modbus_unit, control, command_timeout,
                         on_command_timeout, on_shutdown, require_failsafe, writable_params,
                         plus the adapter's keys

Every error names the file, the key path and what is wrong, and one pass reports
every error of a file (gateway/schema.py); a drive is named by its id
(``buses.line1.drives[cfw11].address``); unknown keys are errors, with the nearest
known key as a hint; duplicate drive ids, Modbus units and bus addresses are
errors naming both drives. The file itself is bounded (:data:`MAX_FILE_BYTES`,
:data:`MAX_DEPTH`), and so is ``zenoh.config_file``: it is read and checked here
(:func:`read_zenoh_config_file`), once, by ``check-config`` and ``run`` alike, and
the text checked is the text Zenoh gets.

A bus table names its adapter, and the loader finds the adapter's class through
:data:`ADAPTERS` (name -> "module:Class") and imports it lazily: the core never imports
an adapter. A third-party adapter is an installed distribution that declares an entry
point in the group :data:`ENTRY_POINT_GROUP` (``drive_gateway.adapters``); its name
cannot shadow one of the project's. A config file names an adapter by its registered
name only: a ``"module:Class"`` path in a config is refused and never imported (a config
file must not choose code to run, docs/decisions/0009-adapters-by-name-only.md).
"""

from __future__ import annotations

import difflib
import importlib.metadata
import ipaddress
import os
import re
import stat
import sys
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, ClassVar, Protocol, TypeVar

from gateway.access.audit import AuditSection, read_audit_section
from gateway.access.users import User, read_users
from gateway.adapter import DriveAdapter
from gateway.errors import AdapterError, ConfigError, ConfigErrors
from gateway.json5check import Json5Error, check_json5
from gateway.loader import NotLoadable
from gateway.loader import load as load_target
from gateway.model import ControlMode, Device, StopAction
from gateway.opcuaconfig import OpcuaSection, read_opcua_section
from gateway.schema import Table
from gateway.webconfig import WebSection, read_web_section
from gateway.webconfig import web_bind as _web_bind

SHARE = "share/drive-gateway"
"""Where a wheel installs config/ (the demo, the site template, the unit): under the
installation's data directory (``<venv>/share/drive-gateway``)."""


def shipped_file(name: str) -> Path:
    """A file of config/: the source tree's, else the installed copy (a wheel), found
    through the distribution's record so it works for a venv, ``--user`` or a system
    install alike; the source tree's path when neither exists (the error names it)."""
    source = Path(__file__).resolve().parent.parent / "config" / name
    if source.is_file():
        return source
    try:
        for entry in importlib.metadata.files("drive-gateway") or ():
            if str(entry).replace("\\", "/").endswith(f"{SHARE}/{name}"):
                return Path(str(entry.locate())).resolve()
    except importlib.metadata.PackageNotFoundError:
        pass
    installed = Path(sys.prefix) / SHARE / name
    return installed if installed.is_file() else source


DEFAULT_CONFIG = shipped_file("demo.toml")
LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
T = TypeVar("T")
IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
MAX_FILE_BYTES = 1 << 20
"""The largest config file, and the largest ``zenoh.config_file``, read (1 MiB)."""
MAX_DEPTH = 32
"""Tables and arrays inside each other in the TOML file (the layout needs 4)."""


@dataclass(frozen=True, slots=True)
class GatewaySection:
    name: str = "drive-gateway"
    log_level: str = "INFO"
    library_log_level: str = "WARNING"
    """The level of the libraries' own loggers (the canopen library narrates each PDO map
    and SDO at INFO: about 100 lines per reconnect); DEBUG to see them."""
    shutdown_timeout: float = 10.0
    tick: float = 0.05


@dataclass(frozen=True, slots=True)
class ZenohSection:
    enabled: bool = True
    prefix: str = "drive-gateway"
    mode: str = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    heartbeat: float = 1.0
    recovery_cache: int = 100
    """Events (and states) kept per drive key for subscribers that come back (0: none)."""
    config_file: Path | None = None
    config_text: str | None = field(default=None, repr=False, compare=False)
    """The text of ``config_file`` as checked at load: what Zenoh is given."""


DEFAULT_HISTORY_PATH = Path("/var/lib/drive-gateway/history.sqlite")


@dataclass(frozen=True, slots=True)
class HistorySection:
    """``[history]``: every drive's readings and every event in SQLite on the box
    (docs/decisions/0083-history-store.md)."""

    enabled: bool = False
    path: Path = DEFAULT_HISTORY_PATH
    period: float = 1.0  # s between two samples of every drive
    batch_interval: float = 1.0  # s between two writes (what a power cut may lose)
    max_age: float = 30 * 86400.0  # s a row is kept
    max_size_mb: float = 1024.0  # MiB the file may use; beyond it the oldest rows go


@dataclass(frozen=True, slots=True)
class ModbusSection:
    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = 1502
    allow: tuple[IpNetwork, ...] = ()
    read_only: bool = False
    gateway_unit: int = 0
    frame_timeout: float = 5.0  # s for the rest of a begun frame to arrive
    max_connections: int = 100  # clients connected at once
    max_connections_per_peer: int = 0  # from one client address; 0: only max_connections
    idle_timeout: float = 60.0  # s with no complete request before a connection is closed; 0: never
    peers: tuple[tuple[IpNetwork, bool], ...] = ()
    """``[[modbus.peers]]``: a network and whether its clients may command (rights
    "command") or only read ("read"); the longest matching network decides, and a client
    no entry names may command unless ``read_only`` (docs/modbus-map.md, "Connections")."""

    def may_command(self, host: str) -> bool:
        """Whether a client at ``host`` may write (command): not read only, and its most
        specific ``peers`` entry, if any, gives it command rights."""
        if self.read_only:
            return False
        try:
            address = ipaddress.ip_address(host.partition("%")[0])
        except ValueError:
            return not self.peers
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        matching = [
            (net.prefixlen, command)
            for net, command in self.peers
            if address.version == net.version and address in net
        ]
        return max(matching, key=lambda m: (m[0], not m[1]))[1] if matching else True


@dataclass(frozen=True, slots=True)
class DriveConfig:
    id: str
    bus: str
    device: Device
    address: int
    modbus_unit: int | None = None
    control: ControlMode = ControlMode.ANY
    command_timeout: float | None = None
    on_command_timeout: StopAction = StopAction.RAMP_STOP
    on_shutdown: StopAction = StopAction.RAMP_STOP
    require_failsafe: bool = False
    """Refuse run commands while the drive's own reaction to a lost master is not known
    to stop it (docs/safety.md, "The drive's own reaction to a lost master")."""
    writable_params: frozenset[int] = frozenset()
    writable_entries: frozenset[tuple[int, int]] = frozenset()
    """``"0x2000:1"`` entries of writable_params: that subindex of the object only."""
    options: Any = None


@dataclass(frozen=True, slots=True)
class BusConfig:
    name: str
    adapter: str
    options: Any = None
    drives: tuple[DriveConfig, ...] = ()
    simulate: bool = False
    """``simulate = true``: the daemon gives the adapter a simulated line."""


@dataclass(frozen=True, slots=True)
class Config:
    file: str
    gateway: GatewaySection = field(default_factory=GatewaySection)
    zenoh: ZenohSection = field(default_factory=ZenohSection)
    modbus: ModbusSection = field(default_factory=ModbusSection)
    buses: tuple[BusConfig, ...] = ()
    web: WebSection = field(default_factory=WebSection)
    history: HistorySection = field(default_factory=HistorySection)
    opcua: OpcuaSection = field(default_factory=OpcuaSection)
    users: tuple[User, ...] = ()
    audit: AuditSection = field(default_factory=AuditSection)

    @property
    def drives(self) -> tuple[DriveConfig, ...]:
        return tuple(d for b in self.buses for d in b.drives)

    def with_overrides(
        self,
        zenoh_endpoint: str | None = None,
        modbus_bind: str | None = None,
        web_bind: str | None = None,
    ) -> Config:
        """The command line's --zenoh-endpoint, --modbus-bind and --web-bind."""
        from dataclasses import replace

        cfg = self
        if zenoh_endpoint is not None:
            problem = _endpoint_problem(zenoh_endpoint)
            if problem:
                raise ConfigError("--zenoh-endpoint", "", problem)
            cfg = replace(cfg, zenoh=replace(cfg.zenoh, listen=(zenoh_endpoint,)))
        if modbus_bind is not None:
            host, port = parse_host_port(modbus_bind, "--modbus-bind", "--modbus-bind")
            cfg = replace(cfg, modbus=replace(cfg.modbus, host=host, port=port))
        if web_bind is not None:
            cfg = replace(cfg, web=_web_bind(cfg.web, web_bind))
        return cfg


def parse_host_port(text: str, file: str, key: str) -> tuple[str, int]:
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]")
    digits = port_text.isascii() and port_text.isdigit()
    if not sep or not host or not digits or not 0 <= int(port_text) <= 65535:
        raise ConfigError(file, key, f"{text!r} is not HOST:PORT")
    return host, int(port_text)


# ------------------------------------------------------------------ sections


def _gateway_section(t: Table) -> GatewaySection:
    d = GatewaySection()
    section = GatewaySection(
        name=t.string("name", d.name),
        log_level=t.string("log_level", d.log_level, choices=LOG_LEVELS),
        library_log_level=t.string("library_log_level", d.library_log_level, choices=LOG_LEVELS),
        shutdown_timeout=t.number(
            "shutdown_timeout", d.shutdown_timeout, minimum=0.0, maximum=300.0
        ),
        tick=t.number("tick", d.tick, minimum=0.001, maximum=1.0),
    )
    return section


ZENOH_PROTOCOLS = frozenset(
    ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream", "unixpipe", "serial", "vsock")
)
"""The link protocols a Zenoh endpoint may name (``proto/address[?config][#metadata]``)."""
_HOST_PORT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")


def _endpoint_problem(ep: str) -> str | None:
    proto, sep, rest = ep.partition("/")
    if not sep or not proto or not rest:
        return f"{ep!r} is not a Zenoh endpoint (like tcp/127.0.0.1:7447)"
    if proto not in ZENOH_PROTOCOLS:
        known = ", ".join(sorted(ZENOH_PROTOCOLS))
        return f"{ep!r}: {proto!r} is not a Zenoh link protocol ({known})"
    address = rest.partition("#")[0].partition("?")[0]
    if proto in _HOST_PORT_PROTOCOLS:
        try:
            parse_host_port(address, "", "")
        except ConfigError:
            return f"{ep!r}: {address!r} is not HOST:PORT (like tcp/127.0.0.1:7447)"
    return None


def _endpoint_list(t: Table, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
    endpoints: tuple[str, ...] = t.str_list(key, default)
    for i, ep in enumerate(endpoints):
        problem = _endpoint_problem(ep)
        if problem:
            t.errors.append(t.error(f"{key}[{i}]", problem))
            return default
    return endpoints


def _zenoh_section(t: Table, base: Path) -> ZenohSection:
    d = ZenohSection()
    config_file = t.string("config_file", None)
    path = text = None
    if config_file is not None:
        path = Path(os.path.abspath(base / config_file))
        try:
            text = read_zenoh_config_file(path, config_file)
        except ConfigError as exc:
            t.errors.append(t.error("config_file", f"{config_file!r} {exc.reason}"))
    section = ZenohSection(
        enabled=t.boolean("enabled", d.enabled),
        prefix=_prefix(t),
        mode=t.string("mode", d.mode, choices=("peer", "client")),
        listen=_endpoint_list(t, "listen", d.listen),
        connect=_endpoint_list(t, "connect", d.connect),
        multicast_scouting=t.boolean("multicast_scouting", d.multicast_scouting),
        heartbeat=t.number("heartbeat", d.heartbeat, minimum=0.05, maximum=3600.0),
        recovery_cache=t.integer("recovery_cache", d.recovery_cache, minimum=0, maximum=100_000),
        config_file=path,
        config_text=text,
    )
    return section


def _prefix(t: Table) -> str:
    prefix: str = t.string("prefix", ZenohSection().prefix)
    bad = set("*$?#") & set(prefix)
    if not prefix or prefix.startswith("/") or prefix.endswith("/") or "//" in prefix or bad:
        t.errors.append(t.error("prefix", f"{prefix!r} is not a valid Zenoh key prefix"))
    return prefix


def _history_section(t: Table, base: Path) -> HistorySection:
    d = HistorySection()
    path_text = t.string("path", str(d.path))
    if not path_text or "\0" in path_text:
        t.errors.append(t.error("path", f"{path_text!r} is not a file path"))
        path_text = str(d.path)
    return HistorySection(
        enabled=t.boolean("enabled", d.enabled),
        path=Path(os.path.abspath(base / os.path.expanduser(path_text))),
        period=t.number("period", d.period, minimum=0.05, maximum=3600.0),
        batch_interval=t.number("batch_interval", d.batch_interval, minimum=0.05, maximum=60.0),
        max_age=t.number("max_age", d.max_age, minimum=60.0, maximum=10 * 366 * 86400.0),
        max_size_mb=t.number("max_size_mb", d.max_size_mb, minimum=1.0, maximum=1024.0 * 1024),
    )


def _modbus_section(t: Table) -> ModbusSection:
    d = ModbusSection()
    bind = t.string("bind", f"{d.host}:{d.port}")
    try:
        host, port = parse_host_port(bind, t.file, t.key("bind"))
    except ConfigError as exc:
        t.errors.append(exc)
        host, port = d.host, d.port
    allow: list[IpNetwork] = []
    for i, text in enumerate(t.str_list("allow", ())):
        try:
            allow.append(ipaddress.ip_network(text, strict=False))
        except ValueError:
            t.errors.append(t.error(f"allow[{i}]", f"{text!r} is not an address or CIDR network"))
    section = ModbusSection(
        enabled=t.boolean("enabled", d.enabled),
        host=host,
        port=port,
        allow=tuple(allow),
        read_only=t.boolean("read_only", d.read_only),
        gateway_unit=t.integer("gateway_unit", d.gateway_unit, minimum=0, maximum=255),
        frame_timeout=_frame_timeout(t, d.frame_timeout),
        max_connections=t.integer("max_connections", d.max_connections, minimum=1, maximum=1000),
        idle_timeout=t.number("idle_timeout", d.idle_timeout, minimum=0.0, maximum=86400.0),
    )
    return replace(
        section,
        max_connections_per_peer=_per_peer(t, section.max_connections),
        peers=_modbus_peers(t),
    )


MODBUS_RIGHTS = {"read": False, "command": True}


def _modbus_peers(t: Table) -> tuple[tuple[IpNetwork, bool], ...]:
    out: list[tuple[IpNetwork, bool]] = []
    try:
        tables = t.table_list("peers")
    except ConfigError as exc:
        t.errors.append(exc)
        return ()
    for pt in tables:
        text: str | None = _read(pt, lambda pt: pt.string("address"), finish=False)
        rights: str | None = _read(pt, lambda pt: pt.string("rights"))
        if text is None or rights is None:
            continue
        if rights not in MODBUS_RIGHTS:
            t.errors.append(pt.error("rights", f'{rights!r} is not "read" or "command"'))
            continue
        try:
            out.append((ipaddress.ip_network(text, strict=False), MODBUS_RIGHTS[rights]))
        except ValueError:
            t.errors.append(pt.error("address", f"{text!r} is not an address or CIDR network"))
    return tuple(out)


def _per_peer(t: Table, max_connections: int) -> int:
    """``modbus.max_connections_per_peer``: 0 (no limit of its own) up to max_connections."""
    value: int = t.integer(
        "max_connections_per_peer", ModbusSection().max_connections_per_peer, minimum=0
    )
    if value > max_connections:
        t.errors.append(
            t.error(
                "max_connections_per_peer",
                f"{value} is above modbus.max_connections ({max_connections}): it would limit"
                " nothing; 0 means no limit per address",
            )
        )
        return 0
    return value


def _frame_timeout(t: Table, default: float) -> float:
    value: float = t.number("frame_timeout", default, maximum=3600.0)
    if value <= 0:
        t.errors.append(t.error("frame_timeout", f"must be above 0, not {value:g}"))
        return default
    return value


# ---------------------------------------------------------------- adapters

ADAPTERS: dict[str, str] = {
    "profibus": "adapters.profibus.adapter:ProfibusAdapter",
    "devicenet": "adapters.devicenet.adapter:DeviceNetAdapter",
    "canopen": "adapters.canopen.adapter:CanOpenAdapter",
}
"""Adapter name (the ``adapter`` key of a bus table) -> "module:Class"."""

ENTRY_POINT_GROUP = "drive_gateway.adapters"
"""Where installed third-party adapters declare themselves (name = "module:Class")."""

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")


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
        return load_target(target)
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


# ---------------------------------------------------------------- buses


def _drive(t: Table, bus: str, cls: Any) -> DriveConfig:
    device_names = [d.value for d in sorted(cls.devices, key=lambda d: d.value)]
    drive_id = _drive_id(t)
    device = Device(t.string("device", choices=device_names))
    lo, hi = cls.address_range
    command_timeout = t.number("command_timeout", 0.0, minimum=0.0, maximum=3600.0)
    drive = DriveConfig(
        id=drive_id,
        bus=bus,
        device=device,
        address=t.integer("address", minimum=lo, maximum=hi),
        modbus_unit=t.integer("modbus_unit", None, minimum=1, maximum=247),
        control=t.enum("control", ControlMode, ControlMode.ANY),
        command_timeout=command_timeout or None,
        on_command_timeout=t.enum("on_command_timeout", StopAction, StopAction.RAMP_STOP),
        on_shutdown=t.enum("on_shutdown", StopAction, StopAction.RAMP_STOP),
        require_failsafe=t.boolean("require_failsafe", False),
    )
    numbers, entries = writable_params(t)
    drive = replace(drive, writable_params=numbers, writable_entries=entries)
    return replace(drive, options=cls.parse_drive_options(t, drive))


def parse_param_ref(text: str) -> tuple[int, int | None]:
    """A parameter as a config or a command line gives it: ``100``, ``P0100``, ``0x6083``
    (a CANopen object index, every subindex) or ``0x2000:1`` (that subindex only).
    ValueError naming what is wrong."""
    head, sep, tail = text.strip().partition(":")
    digits = head[1:] if head[:1] in ("P", "p") else head
    try:
        number = int(head, 16) if head.lower().startswith("0x") else int(digits, 10)
        subindex = int(tail, 0) if sep else None
    except ValueError:
        raise ValueError(f"{text!r} is not a parameter: 100, P0100, 0x6083 or 0x2000:1") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"{text!r}: parameter number beyond 0..65535")
    if subindex is not None and not 0 <= subindex <= 255:
        raise ValueError(f"{text!r}: subindex beyond 0..255")
    return number, subindex


def writable_params(t: Table) -> tuple[frozenset[int], frozenset[tuple[int, int]]]:
    """``writable_params``: numbers (ints, or strings ``"P0100"``, ``"0x6083"``: every
    subindex) and entries (``"0x2000:1"``: that subindex only)."""
    if not t.has("writable_params"):
        t.raw("writable_params", [])  # a known key, even when absent
        return frozenset(), frozenset()
    value = t.raw("writable_params")
    if not isinstance(value, list):
        raise t.error("writable_params", "must be an array of parameter numbers")
    numbers: set[int] = set()
    entries: set[tuple[int, int]] = set()
    for i, item in enumerate(value):
        key = f"writable_params[{i}]"
        if isinstance(item, bool) or not isinstance(item, int | str):
            raise t.error(
                key, f"must be a parameter number or a string such as '0x2000:1', not {item!r}"
            )
        if isinstance(item, int):
            if not 0 <= item <= 65535:
                raise t.error(key, f"{item} is outside 0..65535")
            numbers.add(item)
            continue
        try:
            number, subindex = parse_param_ref(item)
        except ValueError as exc:
            raise t.error(key, str(exc)) from None
        if subindex is None:
            numbers.add(number)
        else:
            entries.add((number, subindex))
    return frozenset(numbers), frozenset(entries)


def _valid_id(value: Any) -> bool:
    return (
        isinstance(value, str)
        and 0 < len(value) <= 64
        and all(c.isascii() and (c.isalnum() or c in "-_") for c in value)
    )


def _drive_id(t: Table) -> str:
    drive_id: str = t.string("id")
    if not _valid_id(drive_id):
        raise t.error("id", f"{drive_id!r} must be letters, digits, '-' or '_' (it is a key)")
    return drive_id


def _named_by_id(t: Table) -> Table:
    """``buses.l.drives[0]`` becomes ``buses.l.drives[cfw11]`` once the id is known."""
    drive_id = t.data.get("id")
    if _valid_id(drive_id):
        t.path = f"{t.path.rpartition('[')[0]}[{drive_id}]"
    return t


def _bus(name: str, t: Table) -> BusConfig:
    adapter_name = t.string("adapter")
    try:
        cls = load_adapter(adapter_name)
    except AdapterError as exc:
        raise t.error("adapter", str(exc)) from None
    options = _read(t, cls.parse_bus_options, finish=False)
    drives = [
        drive
        for dt in _drive_tables(t)
        if (drive := _read(_named_by_id(dt), lambda dt: _drive(dt, name, cls))) is not None
    ]
    if options is not None:  # the bus table's unknown keys, once its options were read:
        _read(t, lambda t: None)  # a table the adapter gave up on was never read to the end
    owners = [(d.address, d.id) for d in drives]
    _check_unique(t, "drives", "address", owners)
    check_bus = getattr(cls, "check_bus", None)  # optional: a rule across the bus's drives
    if options is not None and callable(check_bus):
        _read(t, lambda t: check_bus(t, options, [d.options for d in drives]), finish=False)
    # the adapter's options checked ``simulate`` (a key it does not know is refused above)
    simulate = t.data.get("simulate") is True
    return BusConfig(
        name=name, adapter=adapter_name, options=options, drives=tuple(drives), simulate=simulate
    )


def _drive_tables(t: Table) -> list[Table]:
    try:
        return t.table_list("drives")
    except ConfigError as exc:
        t.errors.append(exc)
        return []


def _check_unique(t: Table, key: str, what: str, owners: Iterable[tuple[Any, str]]) -> None:
    """One error per value given to more than one owner, naming every owner."""
    by_value: dict[Any, list[str]] = {}
    for value, owner in owners:
        if value is not None:
            by_value.setdefault(value, []).append(owner)
    for value, names in by_value.items():
        if len(names) > 1:
            listed = ", ".join(names[:-1]) + f" and {names[-1]}"
            t.errors.append(t.error(key, f"{what} {value} is used by {listed}"))


def _read(t: Table, reader: Callable[[Table], T], *, finish: bool = True) -> T | None:
    """``reader(t)`` and then ``t.finish()``; every error goes to ``t.errors`` and
    None is returned when the table could not be read (the rest of the file is)."""
    try:
        result = reader(t)
        if finish:
            t.finish()
    except (ConfigErrors, ConfigError) as exc:
        for error in exc.errors if isinstance(exc, ConfigErrors) else [exc]:
            _add_once(t.errors, error)
        return None
    return result


def _add_once(errors: list[ConfigError], error: ConfigError) -> None:
    """One error per key: a check that fails on the default a bad value was replaced with
    (``max_rpm`` bad, then "max_rpm is required") would only repeat the first."""
    if not any(e.file == error.file and e.key == error.key for e in errors):
        errors.append(error)


def _section(root: Table, key: str, reader: Callable[[Table], T]) -> T | None:
    """One of the top-level sections, read with ``reader`` (None if it cannot be)."""
    try:
        table = root.table(key)
    except ConfigError as exc:
        root.errors.append(exc)
        return None
    return _read(table, reader)


# ---------------------------------------------------------------- loading


def parse(data: dict[str, Any], file: str, base: Path | None = None) -> Config:
    """Validate a parsed TOML document; raises ConfigErrors with every problem found."""
    root = Table(data, file, collect=True)
    base = base or Path(file).resolve().parent
    gateway = _section(root, "gateway", _gateway_section)
    zenoh = _section(root, "zenoh", lambda t: _zenoh_section(t, base))
    modbus = _section(root, "modbus", _modbus_section)
    web = _section(root, "web", lambda t: read_web_section(t, base))
    history = _section(root, "history", lambda t: _history_section(t, base))
    opcua = _section(root, "opcua", lambda t: read_opcua_section(t, base))
    users = read_users(root)
    audit = _section(root, "audit", lambda t: read_audit_section(t, base))
    buses: list[BusConfig] = []
    for name, table in (_read(root, lambda r: r.tables("buses"), finish=False) or {}).items():
        bus = _read(table, partial(_bus, name), finish=False)
        if bus is not None:
            buses.append(bus)
    _read(root, lambda r: None)  # unknown top-level keys
    drives = [d for b in buses for d in b.drives]
    places = [(repr(d.id), f"buses.{d.bus} address {d.address}") for d in drives]
    _check_unique(root, "buses", "drive id", places)
    _check_unique(root, "buses", "modbus_unit", [(d.modbus_unit, d.id) for d in drives])
    if modbus is not None:
        for d in drives:
            if d.modbus_unit is not None and d.modbus_unit == modbus.gateway_unit:
                root.errors.append(
                    root.error(
                        "modbus.gateway_unit",
                        f"{modbus.gateway_unit} is also the modbus_unit of drive {d.id!r}",
                    )
                )
    if web is not None:
        _check_web_users(root, web, users)
    if root.errors or gateway is None or zenoh is None or modbus is None or web is None:
        raise ConfigErrors(root.errors)
    if opcua is None or audit is None:
        raise ConfigErrors(root.errors)
    return Config(
        file=file,
        gateway=gateway,
        zenoh=zenoh,
        modbus=modbus,
        buses=tuple(buses),
        web=web,
        history=history or HistorySection(),
        opcua=opcua,
        users=users,
        audit=audit,
    )


def _check_web_users(root: Table, web: WebSection, users: tuple[User, ...]) -> None:
    """Commands on the page need users who log in (docs/operations.md, "Users and
    roles"); only a page on this machine alone may stand on the shared token."""
    if web.token_sha256 is not None and not web.loopback_only:
        root.errors.append(
            root.error(
                "web.token_sha256",
                "a shared token names no one: it is for a page on this machine only (web.allow "
                "loopback); give each user or script a [[users]] entry with its own "
                "token_sha256 (drive-gateway users token)",
            )
        )
        return
    if not web.commands or users:
        return
    if not web.loopback_only:
        root.errors.append(
            root.error(
                "web.commands",
                "commands = true on a page other machines reach needs [[users]]: each person "
                "a name, a role and a password hash (drive-gateway users hash); or set "
                "commands = false",
            )
        )
    elif web.token_sha256 is None:
        root.errors.append(
            root.error(
                "web.commands",
                "commands = true needs [[users]] (drive-gateway users hash), or, for a page "
                "on this machine only, token_sha256",
            )
        )


def _depth(data: Any) -> int:
    """How deep tables and arrays nest in ``data`` (without recursion)."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(data, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict | list):
            deepest = max(deepest, depth + 1)
            if deepest > MAX_DEPTH:
                return deepest
            items = value.values() if isinstance(value, dict) else value
            stack.extend((v, depth + 1) for v in items)
    return deepest


def _file_kind(mode: int) -> str:
    kinds = {
        stat.S_ISDIR: "a directory",
        stat.S_ISCHR: "a character device",
        stat.S_ISBLK: "a block device",
        stat.S_ISFIFO: "a named pipe",
        stat.S_ISSOCK: "a socket",
    }
    return next((name for test, name in kinds.items() if test(mode)), "not a regular file")


def read_text_file(path: Path, shown: str, what: str, limit: int = MAX_FILE_BYTES) -> str:
    """A regular file's UTF-8 text, at most ``limit`` bytes; ConfigError(shown, "", reason)
    naming the real reason otherwise (missing, a device, too large, unreadable...)."""

    def fail(reason: str) -> ConfigError:
        return ConfigError(shown, "", reason)

    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise fail("does not exist") from None
    except NotADirectoryError:
        raise fail("does not exist (a part of its path is not a directory)") from None
    except OSError as exc:
        raise fail(f"cannot be read: {(exc.strerror or str(exc)).lower()}") from None
    except ValueError as exc:  # an embedded NUL
        raise fail(f"is not a usable path: {exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise fail(f"is {_file_kind(info.st_mode)}, not a regular file ({what})")
    if info.st_size > limit:
        raise fail(f"is {info.st_size} bytes; {what} may have at most {limit}")
    try:
        with open(path, "rb") as f:
            raw = f.read(limit + 1)
    except OSError as exc:
        raise fail(f"cannot be read: {(exc.strerror or str(exc)).lower()}") from None
    if len(raw) > limit:
        raise fail(f"is more than {limit} bytes; {what} may have at most {limit}")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise fail(f"is not UTF-8 text (byte {exc.start})") from None


def read_zenoh_config_file(path: Path, shown: str | None = None) -> str:
    """The text of a ``zenoh.config_file`` once it is known safe to give Zenoh: a regular
    file, at most :data:`MAX_FILE_BYTES`, one JSON5 object nested at most
    :data:`gateway.json5check.MAX_DEPTH` deep (Zenoh's parser overflows its stack on
    deep nesting and kills the process). Raises ConfigError with the reason."""
    shown = shown or str(path)
    text = read_text_file(path, shown, "a Zenoh config file")
    if path.suffix.lower() in (".yaml", ".yml"):
        raise ConfigError(shown, "", "is YAML; the gateway takes a Zenoh config in JSON5")
    try:
        check_json5(text, top="{")
    except Json5Error as exc:
        raise ConfigError(shown, "", f"is not a Zenoh JSON5 config: {exc}") from None
    return text


def load(path: str | Path) -> Config:
    """Read and validate a config file."""
    path = Path(path)
    file = str(path)
    try:
        text = read_text_file(path, file, "a config file")
    except ConfigError as exc:
        reason = "file not found" if exc.reason == "does not exist" else exc.reason
        raise ConfigErrors([ConfigError(file, "", reason)]) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigErrors([ConfigError(file, "", f"not valid TOML: {exc}")]) from None
    except RecursionError:
        raise ConfigErrors([ConfigError(file, "", "not valid TOML: nested too deep")]) from None
    if _depth(data) > MAX_DEPTH:
        reason = f"tables and arrays nest deeper than {MAX_DEPTH} levels"
        raise ConfigErrors([ConfigError(file, "", reason)])
    return parse(data, file, path.resolve().parent)
