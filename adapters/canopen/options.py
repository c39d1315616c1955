"""The CANopen bus table and its drives' keys (read with gateway.schema.Table).

Bus keys: interface, channel, bitrate, simulate, nmt_master, sync_period, pdo_period,
sdo_timeout, heartbeat_factor, boot_timeout, retry, node_id and heartbeat (the gateway's
own heartbeat, which the drives consume). Drive keys: eds, mode, max_rpm, speed_scale,
rated_current, heartbeat, comm_loss_option, quick_stop_option, reset_if_operational,
startup_sdo and the simulator's sim_ramp_time, sim_max_rpm, sim_boot_operational. See
docs/devices.md, "CiA 402 drives (CANopen)".

Every object the configuration needs must be in the drive's EDS: one it lacks is an
error naming the file and the object, found when the config is read. So is a file that
is not a regular file or is over 4 MiB (:mod:`gateway.vendorfile`), and a DefaultValue
out of its LowLimit..HighLimit or DataType (:func:`adapters.canopen.codec.od.value_problems`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from adapters.can.bits import frame_bits
from adapters.canopen.codec import cia402
from adapters.canopen.codec.od import Dictionary, Variable, obj_name, parse_object
from adapters.canopen.errors import EdsError
from adapters.link.can import REFUSED_INTERFACES
from gateway.config import DriveConfig, shipped_file
from gateway.schema import Table
from gateway.vendorfile import VendorFileError, read_vendor_file

BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)  # CiA 301
# The shortest SYNC period taken whatever the line: CiA 301 0x1006 (communication cycle
# period) counts in us, and a loop of the gateway's needs some 100 us per pass.
SYNC_FLOOR = 100e-6  # s


class Mode(Enum):
    """The CiA 402 mode the drive runs in (0x6060)."""

    VELOCITY = "velocity"  # vl: 0x6042 target, 0x6044 actual, INTEGER16 rpm
    PROFILE_VELOCITY = "profile_velocity"  # pv: 0x60FF target, 0x606C actual, INTEGER32

    @property
    def code(self) -> int:
        return cia402.MODE_VELOCITY if self is Mode.VELOCITY else cia402.MODE_PROFILE_VELOCITY

    @property
    def objects(self) -> tuple[int, int]:
        """(target, actual) indexes."""
        if self is Mode.VELOCITY:
            return cia402.VL_TARGET_VELOCITY, cia402.VL_VELOCITY_ACTUAL
        return cia402.TARGET_VELOCITY, cia402.VELOCITY_ACTUAL


@dataclass(frozen=True, slots=True)
class BusOptions:
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int = 500_000
    simulate: bool = False
    nmt_master: bool = True
    sync_period: float = 0.05  # s; 0: no SYNC (RPDOs every pdo_period)
    pdo_period: float = 0.05  # s, without SYNC
    sdo_timeout: float = 0.5
    heartbeat_factor: float = 3.0
    boot_timeout: float = 2.0
    retry: float = 1.0
    node_id: int = 127  # the gateway's own node id (its heartbeat)
    heartbeat: int = 100  # ms, the gateway's heartbeat producer time; 0: none

    @property
    def cycle(self) -> float:
        return self.sync_period if self.sync_period > 0 else self.pdo_period


@dataclass(frozen=True, slots=True)
class StartupWrite:
    """One ``startup_sdo`` entry: written at every connect and read back."""

    variable: Variable
    value: int | float
    data: bytes


@dataclass(frozen=True, slots=True)
class SimOptions:
    ramp_time: float = 2.0
    max_rpm: float | None = None  # default: the drive's max_rpm
    boot_operational: bool = False  # a self-starting node (goes operational after boot)


@dataclass(frozen=True, slots=True)
class DriveOptions:
    eds: Dictionary
    eds_path: Path
    mode: Mode
    max_rpm: float
    speed_scale: float  # raw velocity units per rpm
    rated_current: float | None  # A; 0x6078 is per mille of it
    heartbeat_ms: int
    comm_loss_option: int | None
    quick_stop_option: int | None
    reset_if_operational: bool
    startup_sdo: tuple[StartupWrite, ...]
    controlword: Variable
    statusword: Variable
    target: Variable
    actual: Variable
    extras: tuple[Variable, ...]  # 0x6078 current, 0x6077 torque: mapped where they fit
    has_error_code: bool  # 0x603F
    has_quick_stop_option: bool
    has_consumer_heartbeat: bool  # 0x1016:1
    sim: SimOptions = SimOptions()

    @property
    def rpdo1_bytes(self) -> int:
        """RPDO1's data length: controlword and target."""
        return (self.controlword.bits + self.target.bits) // 8

    @property
    def tpdo1_bytes(self) -> int:
        """TPDO1's data length: statusword, actual velocity and the extras mapped."""
        bits = self.statusword.bits + self.actual.bits + sum(v.bits for v in self.extras)
        return bits // 8


def parse_bus(t: Table) -> BusOptions:
    d = BusOptions()
    interface = t.string("interface", d.interface)
    if not interface:
        raise t.error("interface", "must name a python-can interface")
    refused = REFUSED_INTERFACES.get(interface)
    if refused is not None:
        raise t.error("interface", refused)
    simulate = t.boolean("simulate", d.simulate)
    if simulate and interface != "virtual":
        raise t.error(
            "simulate",
            f"needs interface = 'virtual' (simulated drives run in-process), not {interface!r}",
        )
    sync_period = t.number("sync_period", d.sync_period, minimum=0.0, maximum=10.0)
    if 0 < sync_period < SYNC_FLOOR:
        raise t.error(
            "sync_period", f"must be 0 (no SYNC) or at least {SYNC_FLOOR * 1e6:g} us (0.0001 s)"
        )
    heartbeat_factor = t.number("heartbeat_factor", d.heartbeat_factor, minimum=1.5, maximum=20.0)
    return BusOptions(
        interface=interface,
        channel=t.string("channel", d.channel),
        bitrate=t.integer("bitrate", d.bitrate, allowed=BITRATES, what="a CANopen bit rate"),
        simulate=simulate,
        nmt_master=t.boolean("nmt_master", d.nmt_master),
        sync_period=sync_period,
        pdo_period=t.number("pdo_period", d.pdo_period, minimum=0.001, maximum=10.0),
        sdo_timeout=t.number("sdo_timeout", d.sdo_timeout, minimum=0.01, maximum=30.0),
        heartbeat_factor=heartbeat_factor,
        boot_timeout=t.number("boot_timeout", d.boot_timeout, minimum=0.1, maximum=60.0),
        retry=t.number("retry", d.retry, minimum=0.05, maximum=3600.0),
        node_id=t.integer("node_id", d.node_id, minimum=1, maximum=127),
        heartbeat=t.integer("heartbeat", d.heartbeat, minimum=0, maximum=65535),
    )


def _eds_path(t: Table) -> Path:
    text = t.string("eds")
    path = Path(text)
    if not path.is_absolute():
        beside = Path(t.file).resolve().parent / path if Path(t.file).is_file() else path
        shipped = shipped_file(text)
        path = beside if beside.is_file() or not shipped.is_file() else shipped
    return path


def read_eds(path: Path) -> bytes:
    """The bytes of a drive's EDS/DCF read as a vendor file (:mod:`gateway.vendorfile`: a
    regular file of at most 4 MiB, read within a time bound); EdsError naming the file and
    the reason otherwise."""
    try:
        return read_vendor_file(path, "an EDS file")
    except VendorFileError as exc:
        raise EdsError(exc.file, "", exc.reason) from None


def _load(t: Table, drive: DriveConfig) -> tuple[Dictionary, Path]:
    """The drive's dictionary: its EDS read safely, parsed, and its values in their ranges
    (the one check ``check-config`` and ``run`` make alike)."""
    path = _eds_path(t)
    try:
        return Dictionary(path, drive.address, read_eds(path)), path
    except EdsError as exc:
        raise t.error("eds", str(exc)) from None


def _need(t: Table, eds: Dictionary, key: str, index: int, sub: int, *, why: str) -> Variable:
    try:
        return eds.variable(index, sub, why=why)
    except EdsError as exc:
        raise t.error(key, str(exc)) from None


def _option(t: Table, eds: Dictionary, key: str, index: int, texts: dict[int, str]) -> int | None:
    value = t.integer(key, None, minimum=-32768, maximum=32767)
    if value is None:
        return None
    _need(t, eds, key, index, 0, why=key)
    if value >= 0 and value not in texts:
        raise t.error(key, f"{value} is not a CiA 402 option code ({min(texts)}-{max(texts)})")
    return int(value)


def _startup(t: Table, eds: Dictionary) -> tuple[StartupWrite, ...]:
    sub = t.table("startup_sdo")
    out: list[StartupWrite] = []
    for key in list(sub.data):
        value = sub.raw(key)
        try:
            index, subindex = parse_object(key)
        except ValueError as exc:
            raise sub.error(key, str(exc)) from None
        var = _need(sub, eds, key, index, subindex or 0, why="startup_sdo")
        if not var.writable:
            raise sub.error(key, f"{eds.file}: {obj_name(index, subindex)} is not writable")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise sub.error(key, f"must be a number, not {value!r}")
        if (var.minimum is not None and value < var.minimum) or (
            var.maximum is not None and value > var.maximum
        ):
            raise sub.error(
                key,
                f"{value} is outside {var.minimum}..{var.maximum} ({eds.file}: "
                f"{obj_name(index, subindex)} {var.name})",
            )
        try:
            data = var.encode(value)
        except (ValueError, OverflowError, TypeError) as exc:
            raise sub.error(
                key, f"{value} does not fit {obj_name(index, subindex)}: {exc}"
            ) from None
        out.append(StartupWrite(var, value, data))
    return tuple(out)


def parse_drive(t: Table, drive: DriveConfig) -> DriveOptions:
    eds, path = _load(t, drive)
    mode = t.enum("mode", Mode, Mode.VELOCITY)
    target_index, actual_index = mode.objects
    why = f"mode {mode.value}"
    controlword = _need(t, eds, "eds", cia402.CONTROLWORD, 0, why="controlword")
    statusword = _need(t, eds, "eds", cia402.STATUSWORD, 0, why="statusword")
    target = _need(t, eds, "mode", target_index, 0, why=why)
    actual = _need(t, eds, "mode", actual_index, 0, why=why)
    _need(t, eds, "mode", cia402.MODES_OF_OPERATION, 0, why=why)
    for index in (0x1017, 0x1400, 0x1600, 0x1800, 0x1A00):
        _need(t, eds, "eds", index, 0 if index == 0x1017 else 1, why="bring-up")
    for var in (controlword, target):
        if not var.mappable:
            raise t.error("eds", f"{eds.file}: {obj_name(var.index)} is not RPDO-mappable")
    for var in (statusword, actual):
        if not var.mappable:
            raise t.error("eds", f"{eds.file}: {obj_name(var.index)} is not TPDO-mappable")
    max_rpm = t.number("max_rpm", None, minimum=1.0, maximum=100_000.0)
    if max_rpm is None:
        max_rpm = _eds_max_rpm(eds)
        if max_rpm is None:
            raise t.error("max_rpm", f"is required ({eds.file} gives no 0x6046:2 default)")
    rated = t.number("rated_current", None, minimum=0.001, maximum=100_000.0)
    if rated is None and eds.has(0x6075):
        default = eds.variable(0x6075).default
        if isinstance(default, int) and default > 0:
            rated = default / 1000.0  # 0x6075 motor rated current, mA (CiA 402-2)
    extras = tuple(
        eds.variable(index)
        for index in (cia402.CURRENT_ACTUAL, cia402.TORQUE_ACTUAL)
        if eds.has(index) and eds.variable(index).mappable
    )
    bits = statusword.bits + actual.bits
    fitting: list[Variable] = []
    for var in extras:
        if bits + var.bits <= 64:
            fitting.append(var)
            bits += var.bits
    d = SimOptions()
    return DriveOptions(
        eds=eds,
        eds_path=path,
        mode=mode,
        max_rpm=float(max_rpm),
        speed_scale=t.number("speed_scale", 1.0, minimum=1e-6, maximum=1e9),
        rated_current=rated,
        heartbeat_ms=t.integer("heartbeat", 100, minimum=10, maximum=65535),
        comm_loss_option=_option(
            t,
            eds,
            "comm_loss_option",
            cia402.ABORT_CONNECTION_OPTION,
            cia402.ABORT_CONNECTION_OPTIONS,
        ),
        quick_stop_option=_option(
            t, eds, "quick_stop_option", cia402.QUICK_STOP_OPTION, cia402.QUICK_STOP_OPTIONS
        ),
        reset_if_operational=t.boolean("reset_if_operational", False),
        startup_sdo=_startup(t, eds),
        controlword=controlword,
        statusword=statusword,
        target=target,
        actual=actual,
        extras=tuple(fitting),
        has_error_code=eds.has(cia402.ERROR_CODE),
        has_quick_stop_option=eds.has(cia402.QUICK_STOP_OPTION),
        has_consumer_heartbeat=eds.has(0x1016, 1),
        sim=SimOptions(
            ramp_time=t.number("sim_ramp_time", d.ramp_time, minimum=0.1, maximum=999.0),
            max_rpm=t.number("sim_max_rpm", d.max_rpm, minimum=1.0, maximum=100_000.0),
            boot_operational=t.boolean("sim_boot_operational", d.boot_operational),
        ),
    )


def _eds_max_rpm(eds: Dictionary) -> float | None:
    if not eds.has(0x6046, 2):
        return None
    default = eds.variable(0x6046, 2).default
    return float(default) if isinstance(default, int | float) and default > 0 else None


# ---------------------------------------------------------------- bus time


def cycle_bits(drives: list[DriveOptions] | tuple[DriveOptions, ...]) -> int:
    """The bits one SYNC cycle puts on the line: SYNC (no data) and every drive's RPDO1
    and TPDO1, each at its worst-case stuffed length."""
    return frame_bits(0) + sum(
        frame_bits(d.rpdo1_bytes) + frame_bits(d.tpdo1_bytes) for d in drives
    )


def min_sync_period(bitrate: int, drives: list[DriveOptions] | tuple[DriveOptions, ...]) -> float:
    """The shortest SYNC period (s) the line carries at ``bitrate``: one cycle's bus time,
    and never under :data:`SYNC_FLOOR`."""
    return max(SYNC_FLOOR, cycle_bits(drives) / bitrate)


def check_sync_period(t: Table, bus: BusOptions, drives: list[DriveOptions]) -> None:
    """A SYNC period shorter than one cycle's bus time is a configuration error: the
    frames of one cycle would not fit between two SYNCs."""
    if bus.sync_period <= 0 or not drives:
        return
    bits = cycle_bits(drives)
    shortest = bits / bus.bitrate
    if bus.sync_period < shortest:
        raise t.error(
            "sync_period",
            f"{bus.sync_period * 1e6:g} us is shorter than one cycle on the line: at "
            f"{bus.bitrate} bit/s the SYNC and the RPDO1 and TPDO1 of {len(drives)} "
            f"drive(s) take {bits} bits, at least {shortest * 1e6:.0f} us "
            f"(worst-case bit stuffing)",
        )
