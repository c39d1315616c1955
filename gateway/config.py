"""The gateway's configuration: one TOML file read into frozen dataclasses.

Layout (see config/site.example.toml for every key)::

    [gateway]            name, log_level, shutdown_timeout, tick
    [zenoh]              prefix, mode, listen, connect, multicast_scouting, heartbeat, config_file
    [modbus]             bind, allow, read_only, gateway_unit, frame_timeout, max_connections,
                         idle_timeout
    [buses.<name>]       adapter = "profibus" | "devicenet" | "module:Class",
                         plus the adapter's keys
    [[buses.<name>.drives]]  id, device, address, modbus_unit, control, command_timeout,
                         on_command_timeout, on_shutdown, writable_params, plus the adapter's keys

Every error names the file, the key path and what is wrong; unknown keys are
errors; duplicate drive ids, Modbus units and bus addresses are errors.
"""

from __future__ import annotations

import ipaddress
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway.adapter import load_adapter
from gateway.errors import AdapterError, ConfigError, ConfigErrors
from gateway.model import ControlMode, Device, StopAction
from gateway.schema import Table

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "config" / "demo.toml"
LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network


@dataclass(frozen=True, slots=True)
class GatewaySection:
    name: str = "drive-gateway"
    log_level: str = "INFO"
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
    config_file: Path | None = None


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
    idle_timeout: float = 60.0  # s with no complete request before a connection is closed; 0: never


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
    writable_params: frozenset[int] = frozenset()
    options: Any = None


@dataclass(frozen=True, slots=True)
class BusConfig:
    name: str
    adapter: str
    options: Any = None
    drives: tuple[DriveConfig, ...] = ()


@dataclass(frozen=True, slots=True)
class Config:
    file: str
    gateway: GatewaySection = field(default_factory=GatewaySection)
    zenoh: ZenohSection = field(default_factory=ZenohSection)
    modbus: ModbusSection = field(default_factory=ModbusSection)
    buses: tuple[BusConfig, ...] = ()

    @property
    def drives(self) -> tuple[DriveConfig, ...]:
        return tuple(d for b in self.buses for d in b.drives)

    def with_overrides(
        self, zenoh_endpoint: str | None = None, modbus_bind: str | None = None
    ) -> Config:
        """The command line's --zenoh-endpoint and --modbus-bind."""
        from dataclasses import replace

        cfg = self
        if zenoh_endpoint is not None:
            cfg = replace(cfg, zenoh=replace(cfg.zenoh, listen=(zenoh_endpoint,)))
        if modbus_bind is not None:
            host, port = parse_host_port(modbus_bind, "--modbus-bind", "--modbus-bind")
            cfg = replace(cfg, modbus=replace(cfg.modbus, host=host, port=port))
        return cfg


def parse_host_port(text: str, file: str, key: str) -> tuple[str, int]:
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ConfigError(file, key, f"{text!r} is not HOST:PORT")
    return host, int(port_text)


# ------------------------------------------------------------------ sections


def _gateway_section(t: Table) -> GatewaySection:
    d = GatewaySection()
    section = GatewaySection(
        name=t.string("name", d.name),
        log_level=t.string("log_level", d.log_level, choices=LOG_LEVELS),
        shutdown_timeout=t.number(
            "shutdown_timeout", d.shutdown_timeout, minimum=0.0, maximum=300.0
        ),
        tick=t.number("tick", d.tick, minimum=0.001, maximum=1.0),
    )
    t.finish()
    return section


def _endpoint_list(t: Table, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
    endpoints: tuple[str, ...] = t.str_list(key, default)
    for i, ep in enumerate(endpoints):
        proto, sep, rest = ep.partition("/")
        if not sep or not proto or not rest:
            raise t.error(
                f"{key}[{i}]", f"{ep!r} is not a Zenoh endpoint (like tcp/127.0.0.1:7447)"
            )
    return endpoints


def _zenoh_section(t: Table, base: Path) -> ZenohSection:
    d = ZenohSection()
    config_file = t.string("config_file", None)
    path = None
    if config_file is not None:
        path = (base / config_file).resolve()
        if not path.is_file():
            raise t.error("config_file", f"{config_file!r} does not exist")
    section = ZenohSection(
        enabled=t.boolean("enabled", d.enabled),
        prefix=_prefix(t),
        mode=t.string("mode", d.mode, choices=("peer", "client")),
        listen=_endpoint_list(t, "listen", d.listen),
        connect=_endpoint_list(t, "connect", d.connect),
        multicast_scouting=t.boolean("multicast_scouting", d.multicast_scouting),
        heartbeat=t.number("heartbeat", d.heartbeat, minimum=0.05, maximum=3600.0),
        config_file=path,
    )
    t.finish()
    return section


def _prefix(t: Table) -> str:
    prefix: str = t.string("prefix", ZenohSection().prefix)
    bad = set("*$?#") & set(prefix)
    if not prefix or prefix.startswith("/") or prefix.endswith("/") or "//" in prefix or bad:
        raise t.error("prefix", f"{prefix!r} is not a valid Zenoh key prefix")
    return prefix


def _modbus_section(t: Table) -> ModbusSection:
    d = ModbusSection()
    bind = t.string("bind", f"{d.host}:{d.port}")
    host, port = parse_host_port(bind, t.file, t.key("bind"))
    allow: list[IpNetwork] = []
    for i, text in enumerate(t.str_list("allow", ())):
        try:
            allow.append(ipaddress.ip_network(text, strict=False))
        except ValueError:
            raise t.error(f"allow[{i}]", f"{text!r} is not an address or CIDR network") from None
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
    t.finish()
    return section


def _frame_timeout(t: Table, default: float) -> float:
    value: float = t.number("frame_timeout", default, maximum=3600.0)
    if value <= 0:
        raise t.error("frame_timeout", f"must be above 0, not {value:g}")
    return value


# ---------------------------------------------------------------- buses


def _drive(t: Table, bus: str, cls: Any) -> DriveConfig:
    device_names = [d.value for d in sorted(cls.devices, key=lambda d: d.value)]
    device = Device(t.string("device", choices=device_names))
    lo, hi = cls.address_range
    command_timeout = t.number("command_timeout", 0.0, minimum=0.0, maximum=3600.0)
    drive = DriveConfig(
        id=_drive_id(t),
        bus=bus,
        device=device,
        address=t.integer("address", minimum=lo, maximum=hi),
        modbus_unit=t.integer("modbus_unit", None, minimum=1, maximum=247),
        control=t.enum("control", ControlMode, ControlMode.ANY),
        command_timeout=command_timeout or None,
        on_command_timeout=t.enum("on_command_timeout", StopAction, StopAction.RAMP_STOP),
        on_shutdown=t.enum("on_shutdown", StopAction, StopAction.RAMP_STOP),
        writable_params=frozenset(t.int_list("writable_params", (), minimum=0, maximum=65535)),
    )
    from dataclasses import replace

    drive = replace(drive, options=cls.parse_drive_options(t, drive))
    t.finish()
    return drive


def _drive_id(t: Table) -> str:
    drive_id: str = t.string("id")
    if not drive_id or not all(c.isalnum() or c in "-_" for c in drive_id):
        raise t.error("id", f"{drive_id!r} must be letters, digits, '-' or '_' (it is a key)")
    return drive_id


def _bus(name: str, t: Table, errors: list[ConfigError]) -> BusConfig | None:
    adapter_name = t.string("adapter")
    try:
        cls = load_adapter(adapter_name)
    except AdapterError as exc:
        raise t.error("adapter", str(exc)) from None
    options = cls.parse_bus_options(t)
    drives: list[DriveConfig] = []
    for dt in t.table_list("drives"):
        try:
            drives.append(_drive(dt, name, cls))
        except ConfigError as exc:
            errors.append(exc)
    t.finish()
    _check_unique(t, "drives", [(d.address, f"address {d.address}") for d in drives], errors)
    return BusConfig(name=name, adapter=adapter_name, options=options, drives=tuple(drives))


def _check_unique(
    t: Table, key: str, items: Iterable[tuple[Any, str]], errors: list[ConfigError]
) -> None:
    seen: set[Any] = set()
    for value, label in items:
        if value is None:
            continue
        if value in seen:
            errors.append(t.error(key, f"duplicate {label}"))
        seen.add(value)


# ---------------------------------------------------------------- loading


def parse(data: dict[str, Any], file: str, base: Path | None = None) -> Config:
    """Validate a parsed TOML document; raises ConfigErrors with every problem found."""
    root = Table(data, file)
    errors: list[ConfigError] = []
    base = base or Path(file).resolve().parent
    sections: dict[str, Any] = {}
    readers = {
        "gateway": _gateway_section,
        "zenoh": lambda t: _zenoh_section(t, base),
        "modbus": _modbus_section,
    }
    for key, reader in readers.items():
        try:
            sections[key] = reader(root.table(key))
        except ConfigError as exc:
            errors.append(exc)
    buses: list[BusConfig] = []
    try:
        bus_tables = root.tables("buses")
    except ConfigError as exc:
        errors.append(exc)
        bus_tables = {}
    for name, table in bus_tables.items():
        try:
            bus = _bus(name, table, errors)
        except ConfigError as exc:
            errors.append(exc)
            continue
        if bus is not None:
            buses.append(bus)
    try:
        root.finish()
    except ConfigError as exc:
        errors.append(exc)
    drives = [d for b in buses for d in b.drives]
    _check_unique(root, "buses", [(d.id, f"drive id {d.id!r}") for d in drives], errors)
    units = [(d.modbus_unit, f"modbus_unit {d.modbus_unit} ({d.id})") for d in drives]
    _check_unique(root, "buses", units, errors)
    modbus = sections.get("modbus")
    if modbus is not None:
        for d in drives:
            if d.modbus_unit is not None and d.modbus_unit == modbus.gateway_unit:
                errors.append(
                    root.error(
                        "modbus.gateway_unit",
                        f"{modbus.gateway_unit} is also the modbus_unit of drive {d.id!r}",
                    )
                )
    if errors:
        raise ConfigErrors(errors)
    return Config(file=file, buses=tuple(buses), **sections)


def load(path: str | Path) -> Config:
    """Read and validate a config file."""
    path = Path(path)
    file = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigErrors([ConfigError(file, "", "file not found")]) from None
    except OSError as exc:
        raise ConfigErrors([ConfigError(file, "", f"cannot read: {exc.strerror}")]) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigErrors([ConfigError(file, "", f"not valid TOML: {exc}")]) from None
    return parse(data, file, path.resolve().parent)
