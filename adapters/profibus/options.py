"""The keys of a Profibus bus table and of its drives (docs/devices.md lists them).

Bus (``[buses.<name>]`` with ``adapter = "profibus"``)::

    port = "/dev/ttyUSB0"        device path or pyserial URL (rfc2217://, socket://)
    simulate = false             true: a pty pair with the drives simulated in-process
    baudrate = 500000            9600, 19200, 45450, 93750, 187500, 500000, 1500000, ...
    rs485 = "auto"               kernel RS-485 mode (RTS drives the transmitter): "auto"
                                 asks and tolerates a driver without it, "on" insists,
                                 "off" leaves RTS alone (link.py)
    master_address = 2           0-125, never a drive's address
    tsl = <per baud rate>        slot time, bit times (fact sheet 1.1 table)
    min_tsdr = 11                bit times
    max_tsdr = <per baud rate>   bit times
    retries = 1                  1-15
    watchdog = 0.5               s, DP watchdog sent in Set_Prm (0 = off)
    acyclic_timeout = 1.0        s, bound of one DP-V1 read or write
    clear_on_lost_control = false  Global_Control Clear while a drive's command watchdog fired
    latency = 0.01               s added to every reply wait (converter and OS delay)
    cycle_time = 0.01            s, a bus cycle starts at most this often (0 = back to back)
    absent_retry = 1.0           s between probes of an absent slave
    fault_retry = 2.0            s before a slave with a Cfg/Prm fault is started up again
    live_list_period = 1.0       s between FDL status probes of unconfigured addresses (0 = off)
    ring_priority = 0            SCHED_FIFO priority of the line's steady rings (1-99; 0 = the
                                 thread's own scheduling; docs/decisions/0104)

Drive: the profile's keys (delegated to its ``parse_options``) plus ``watchdog`` (s, this
slave's own DP watchdog instead of the bus's), and what the slave is sent at start-up::

    gsd = "TEST_CFW11.gsd"       a GSD file (relative to the config file's directory)
    module = "<module name>"     the GSD module (a compact station), or
    modules = ["<name>", ...]    the modules of a modular station, in slot order
    prm = { "<name>" = value }   ExtUserPrmData values by name (a number or a PrmText text)

or, without a GSD, explicit values instead of the profile's built-in ones::

    cfg = [0xF1]                 Chk_Cfg identifier bytes
    ident_number = 0x0C11        Ident_Number (also a profile key)
    user_prm = [...]             Set_Prm user data (after the DP-V1 status bytes)

The I/O sizes these give must be the ones the profile's telegram has (``words``, ``frame``,
the MCD 600 ``mode``): a difference is a config error saying both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final

from adapters.profibus.codec.chkcfg import decode_identifiers, total_input_bytes, total_output_bytes
from adapters.profibus.codec.gsd import Gsd, GsdError, GsdSetupError, build_setup, decode
from adapters.profibus.contract import BUILTIN_TELEGRAM
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.link import URL_SCHEMES, Rs485, is_url
from adapters.profibus.master.timing import BAUD_RATES, BusParams, bus_problems, defaults_for
from gateway.config import DriveConfig
from gateway.errors import ConfigError
from gateway.model import Device
from gateway.schema import Table
from gateway.vendorfile import VendorFileError, read_vendor_file

WATCHDOG_MIN: Final = 0.01  # 1.6: 10 ms base x 1 x 1
WATCHDOG_MAX: Final = 650.25  # 1.6: 10 ms x 255 x 255


@dataclass(frozen=True)
class BusOptions:
    """A Profibus line's settings (defaults: see the module docstring)."""

    port: str | None = None
    simulate: bool = False
    baudrate: int = 500000
    rs485: Rs485 = Rs485.AUTO
    master_address: int = 2
    tsl: int = 200
    min_tsdr: int = 11
    max_tsdr: int = 100
    retries: int = 1
    watchdog: float = 0.5
    acyclic_timeout: float = 1.0
    clear_on_lost_control: bool = False
    latency: float = 0.01
    cycle_time: float = 0.01
    absent_retry: float = 1.0
    fault_retry: float = 2.0
    live_list_period: float = 1.0
    ring_priority: int = 0

    def bus_params(self) -> BusParams:
        return BusParams(
            baudrate=self.baudrate,
            master_address=self.master_address,
            tsl=self.tsl,
            min_tsdr=self.min_tsdr,
            max_tsdr=self.max_tsdr,
            retries=self.retries,
            latency=self.latency,
            cycle_time=self.cycle_time,
            absent_retry=self.absent_retry,
            fault_retry=self.fault_retry,
            acyclic_timeout=self.acyclic_timeout,
            live_list_period=self.live_list_period,
        )


@dataclass(frozen=True)
class SetupOverride:
    """What replaces the profile's built-in start-up values (None: the profile's)."""

    ident_number: int | None = None
    cfg: bytes | None = None
    user_prm: bytes | None = None  # after the DP-V1 status bytes (as SlaveSetup carries it)
    dpv1: bool | None = None
    origin: str = ""  # "GSD <file>, module '...'" or "cfg/ident_number/user_prm of the config"
    gsd: Gsd | None = None
    modules: tuple[str, ...] = ()


@dataclass(frozen=True)
class DriveOptions:
    """A drive's options: its profile's own, and the master's per-slave settings."""

    profile: Any = None
    watchdog: float | None = None  # None: the bus's watchdog
    setup: SetupOverride | None = None  # None: the profile's built-in setup
    device: Device | None = None  # the drive's device (bus-wide rules: check_bus)
    drive_id: str = ""


def profile_config(drive: DriveConfig) -> tuple[DriveConfig, SetupOverride | None]:
    """``drive`` as its profile (and its simulator) sees it, with its profile's own options,
    and what its config sets up instead of the profile's built-in values."""
    options = drive.options if isinstance(drive.options, DriveOptions) else None
    if options is None:
        return drive, None
    return replace(drive, options=options.profile), options.setup


def parse_bus_options(t: Table) -> BusOptions:
    d = BusOptions()
    baudrate: int = t.integer(
        "baudrate", d.baudrate, allowed=BAUD_RATES, what="a Profibus DP baud rate"
    )
    defaults = defaults_for(baudrate)
    simulate: bool = t.boolean("simulate", d.simulate)
    options = BusOptions(
        port=_port(t, simulate),
        simulate=simulate,
        baudrate=baudrate,
        rs485=t.enum("rs485", Rs485, d.rs485),
        master_address=t.integer("master_address", d.master_address, minimum=0, maximum=125),
        tsl=t.integer("tsl", defaults.tsl, minimum=1, maximum=16383),
        min_tsdr=t.integer("min_tsdr", defaults.min_tsdr, minimum=0, maximum=255),
        max_tsdr=t.integer("max_tsdr", defaults.max_tsdr, minimum=1, maximum=16383),
        retries=t.integer("retries", d.retries, minimum=1, maximum=15),
        watchdog=_watchdog(t, "watchdog", d.watchdog),
        acyclic_timeout=t.number("acyclic_timeout", d.acyclic_timeout, minimum=0.01, maximum=60.0),
        clear_on_lost_control=t.boolean("clear_on_lost_control", d.clear_on_lost_control),
        latency=t.number("latency", d.latency, minimum=0.0, maximum=1.0),
        cycle_time=t.number("cycle_time", d.cycle_time, minimum=0.0, maximum=10.0),
        absent_retry=t.number("absent_retry", d.absent_retry, minimum=0.01, maximum=3600.0),
        fault_retry=t.number("fault_retry", d.fault_retry, minimum=0.01, maximum=3600.0),
        live_list_period=t.number(
            "live_list_period", d.live_list_period, minimum=0.0, maximum=3600.0
        ),
        ring_priority=t.integer("ring_priority", d.ring_priority, minimum=0, maximum=99),
    )
    for key, reason in bus_problems(options.bus_params()):
        raise t.error(key, reason)
    _check_addresses(t, options.master_address)
    _check_gsd_bus(t, options)
    return options


def _check_gsd_bus(t: Table, options: BusOptions) -> None:
    """Each drive's GSD must support the line's baud rate, and its MaxTsdr at that rate
    must fit the line's max_tsdr (the master waits that long for a reply)."""
    drives = t.data.get("drives", [])
    if not isinstance(drives, list):
        return
    for i, drive in enumerate(drives):
        name = drive.get("gsd") if isinstance(drive, Mapping) else None
        if not isinstance(name, str):
            continue
        try:
            gsd = load_gsd(_gsd_path(t, name))
        except GsdError:
            continue  # the drive's own keys report it
        key = f"{t.key('drives')}[{i}].gsd"
        if not gsd.supports(options.baudrate):
            rates = ", ".join(str(b) for b, _ in gsd.baud_rates) or "none"
            raise ConfigError(
                t.file, key, f"{gsd.path} does not support {options.baudrate} baud "
                f"(its *_supp keys: {rates})",
            )  # fmt: skip
        tsdr = gsd.max_tsdr(options.baudrate)
        if tsdr is not None and tsdr > options.max_tsdr:
            raise ConfigError(
                t.file, key, f"{gsd.path} gives MaxTsdr = {tsdr} bit times at "
                f"{options.baudrate} baud, above the line's max_tsdr = {options.max_tsdr}",
            )  # fmt: skip


def load_gsd(path: Path) -> Gsd:
    """A GSD file read as a vendor file (:mod:`gateway.vendorfile`: a regular file of at
    most 4 MiB, read within a time bound) and parsed; GsdError naming the file and the
    reason otherwise."""
    try:
        raw = read_vendor_file(path, "a GSD file")
    except VendorFileError as exc:
        raise GsdError(exc.file, 0, "", exc.reason) from None
    return decode(raw, str(path))


def find_in_dir(directory: str | Path, ident_number: int) -> list[Gsd]:
    """The GSD files of ``directory`` (``*.gsd``, ``*.gs?``) whose Ident_Number matches;
    a file that is refused or does not parse is passed over."""
    found: list[Gsd] = []
    for path in sorted(Path(directory).iterdir()):
        if not path.suffix.lower().startswith(".gs"):
            continue
        try:
            gsd = load_gsd(path)
        except GsdError:
            continue
        if gsd.ident_number == ident_number:
            found.append(gsd)
    return found


def _gsd_path(t: Table, name: str) -> Path:
    path = Path(name)
    return path if path.is_absolute() else Path(t.file).parent / path


def _port(t: Table, simulate: bool) -> str | None:
    if simulate:
        if t.has("port"):
            t.raw("port")
            raise t.error("port", "not used with simulate = true (the gateway makes a pty)")
        return None
    port: str = t.string("port")
    if is_url(port):
        scheme = port.partition("://")[0]
        if scheme not in URL_SCHEMES:
            raise t.error(
                "port", f"{port!r}: unknown pyserial URL scheme (known: {', '.join(URL_SCHEMES)})"
            )
    elif not port.startswith("/"):
        raise t.error(
            "port",
            f"{port!r} is not a device path (/dev/ttyUSB0) or a pyserial URL "
            "(rfc2217://host:port, socket://host:port)",
        )
    return port


def _watchdog(t: Table, key: str, default: float | None) -> Any:
    value = t.number(key, default, minimum=0.0, maximum=WATCHDOG_MAX)
    if value is not None and 0 < value < WATCHDOG_MIN:
        raise t.error(key, f"{value} is below the minimum {WATCHDOG_MIN} (0 turns it off)")
    return value


def _check_addresses(t: Table, master_address: int) -> None:
    """No drive may sit at the master's own address (its tables are read later)."""
    drives = t.data.get("drives", [])
    if not isinstance(drives, list):
        return
    for i, drive in enumerate(drives):
        if isinstance(drive, Mapping) and drive.get("address") == master_address:
            raise ConfigError(
                t.file,
                f"{t.key('drives')}[{i}].address",
                f"{master_address} is the master's own address (master_address)",
            )


def parse_drive_options(
    t: Table,
    drive: DriveConfig,
    profile_options: Any,
    builtin: Any = None,
    telegram: str = BUILTIN_TELEGRAM,
) -> DriveOptions:
    """The master's per-drive keys; ``profile_options`` come from the profile's parser.

    ``builtin`` is the profile's own :class:`~adapters.profibus.contract.SlaveSetup` (its
    ``input_len`` and ``output_len`` are checked against a GSD module or ``cfg``);
    ``telegram`` says which of the profile's settings fixes that telegram (its
    ``telegram_text``), for the error when they differ.
    """
    setup = _gsd_setup(t) if t.has("gsd") else _explicit_setup(t)
    if setup is not None and builtin is not None and setup.cfg is not None:
        _check_sizes(t, setup, builtin, telegram)
    return DriveOptions(
        profile=profile_options,
        watchdog=_watchdog(t, "watchdog", None),
        setup=setup,
        device=drive.device,
        drive_id=drive.id,
    )


_GSD_ONLY: Final = ("module", "modules", "prm")
_NOT_WITH_GSD: Final = ("cfg", "user_prm", "ident_number")


def _gsd_setup(t: Table) -> SetupOverride:
    path = _gsd_path(t, t.string("gsd"))
    for key in _NOT_WITH_GSD:
        if t.has(key):
            t.raw(key)
            raise t.error(key, f"the GSD file gives it (gsd = {t.data['gsd']!r}): remove {key}")
    try:
        gsd = load_gsd(path)
    except GsdError as exc:
        raise t.error("gsd", str(exc)) from None
    modules = _modules(t, gsd)
    prm = t.table("prm")
    values: dict[str, int | str] = {}
    for name in prm.data:
        value = prm.raw(name)
        if isinstance(value, bool) or not isinstance(value, int | str):
            raise prm.error(name, "must be a number or a PrmText text")
        values[name] = value
    try:
        built = build_setup(gsd, modules, values)
    except GsdSetupError as exc:
        raise t.error(exc.key, exc.reason) from None
    return SetupOverride(
        ident_number=built.ident_number,
        cfg=built.cfg,
        user_prm=built.user_prm_after_dpv1,
        dpv1=built.dpv1,
        origin=built.origin,
        gsd=gsd,
        modules=tuple(modules),
    )


def _modules(t: Table, gsd: Gsd) -> list[str]:
    if t.has("module") and t.has("modules"):
        t.raw("modules")
        raise t.error("modules", "give module (one) or modules (a list), not both")
    if t.has("module"):
        return [t.string("module")]
    if t.has("modules"):
        names: list[str] = list(t.str_list("modules"))
        return names
    known = ", ".join(repr(m.name) for m in gsd.modules)
    raise t.error("module", f"is required with gsd (the modules of {gsd.path}: {known})")


def _explicit_setup(t: Table) -> SetupOverride | None:
    for key in _GSD_ONLY:
        if t.has(key):
            t.raw(key)
            raise t.error(key, 'needs gsd = "<file>" (the GSD file it names)')
    cfg = t.int_list("cfg", None, minimum=0, maximum=255)
    user_prm = t.int_list("user_prm", None, minimum=0, maximum=255)
    if cfg is None and user_prm is None and not t.has("ident_number"):
        return None
    ident = t.integer("ident_number", None, minimum=0, maximum=0xFFFF)
    if cfg is not None:
        try:
            decode_identifiers(bytes(cfg))
        except ProfibusDecodeError as exc:
            raise t.error("cfg", f"not Chk_Cfg identifiers: {exc.message}") from None
        if not cfg:
            raise t.error("cfg", "is empty (give at least one identifier)")
    given = [k for k in ("cfg", "ident_number", "user_prm") if t.has(k)]
    return SetupOverride(
        ident_number=ident,
        cfg=None if cfg is None else bytes(cfg),
        user_prm=None if user_prm is None else bytes(user_prm),
        origin=f"{' and '.join(given)} of the drive's config",
    )


def _check_sizes(t: Table, setup: SetupOverride, builtin: Any, telegram: str) -> None:
    """The module's (or cfg's) I/O bytes must be the profile telegram's, both ways."""
    ids = decode_identifiers(setup.cfg or b"")
    have = (total_input_bytes(ids), total_output_bytes(ids))
    want = (int(builtin.input_len), int(builtin.output_len))
    if have == want:
        return
    key = "cfg" if setup.gsd is None else ("modules" if t.has("modules") else "module")
    what = setup.origin if setup.gsd is not None else f"cfg = [{_hex(setup.cfg or b'')}]"
    raise t.error(
        key,
        f"{what} gives {have[0]} bytes in and {have[1]} out; the drive's profile "
        f"({telegram}) has {want[0]} in and {want[1]} out",
    )


def _hex(data: bytes) -> str:
    return ", ".join(f"0x{b:02X}" for b in data)
