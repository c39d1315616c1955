"""The CFW-08's drive keys (read with gateway.schema.Table): the DeviceNet node keys
(:class:`~adapters.devicenet.contract.NodeOptions`: connection, identity, EDS, ADR) and the
drive's own.

Drive keys: assembly, connection, ack, eds, check_identity, vendor_id, product_code,
product_name, adr, max_rpm, max_rpm_param, weg_speed_scale, at_reference_rpm,
startup_params, and the simulator's sim_p313, sim_p710, sim_p710_stored, sim_ramp_time,
sim_max_rpm. See docs/devices.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from adapters.devicenet.cfw08.assemblies import (
    ASSEMBLY_SIZE,
    DEFAULT_AT_REFERENCE_RPM,
    DEFAULT_WEG_SPEED_SCALE,
    MAX_PARAMETER,
    SPEED_REF_MAX_RPM,
    AssemblyPair,
    parameter_of,
)
from adapters.devicenet.codec import objects
from adapters.devicenet.codec.eds import ConnectionType, Eds, Param
from adapters.devicenet.codec.ids import ADR_MAC
from adapters.devicenet.errors import DeviceNetDecodeError, EdsError
from adapters.devicenet.options import load_eds
from adapters.devicenet.scanner import IoKind
from gateway.config import DriveConfig
from gateway.schema import Table

WEG_VENDOR_ID = 0x355  # seed table 8


@dataclass(frozen=True, slots=True)
class SimOptions:
    p313: int = 2
    p710: int | None = None  # default: the one matching ``assembly``
    p710_stored: int | None = None  # P710 changed but not yet applied by a reset
    ramp_time: float = 2.0
    max_rpm: float | None = None  # default: the drive's max_rpm, else 1800


@dataclass(frozen=True, slots=True)
class DriveOptions:
    assembly: AssemblyPair = AssemblyPair.EXTENDED
    connection: IoKind = IoKind.POLLED
    ack: bool = True
    check_identity: bool = True
    vendor_id: int = WEG_VENDOR_ID
    product_code: int | None = None
    product_name: str | None = "CFW-08"
    max_rpm: float | None = None
    max_rpm_param: int | None = None
    weg_speed_scale: int = DEFAULT_WEG_SPEED_SCALE
    at_reference_rpm: float = DEFAULT_AT_REFERENCE_RPM
    startup_params: tuple[tuple[int, int], ...] = ()
    sim: SimOptions = SimOptions()
    eds: Eds | None = None
    product_type: int | None = None  # from the EDS (ProdType)
    revision: tuple[int, int] | None = None  # from the EDS (MajRev, MinRev)
    io_sizes: tuple[int, int] = (ASSEMBLY_SIZE, ASSEMBLY_SIZE)  # (produced, consumed)
    params: Mapping[int, Param] = field(default_factory=dict)  # P number -> EDS ParamN
    adr: bool = False  # Automatic Device Replacement from MAC 63 (seed 6.1)


def _startup_params(t: Table) -> tuple[tuple[int, int], ...]:
    sub = t.table("startup_params")
    out: list[tuple[int, int]] = []
    for key in sub.data:
        text = key[1:] if key[:1] in ("P", "p") else key
        if not text.isdigit() or not 0 <= int(text) <= MAX_PARAMETER:
            raise sub.error(key, "is not a CFW-08 parameter number (P000-P799)")
        out.append((int(text), sub.integer(key, minimum=-32768, maximum=65535)))
    return tuple(out)


def _sim(t: Table) -> SimOptions:
    d = SimOptions()
    return SimOptions(
        p313=t.integer("sim_p313", d.p313, minimum=0, maximum=3),
        p710=t.integer("sim_p710", d.p710, minimum=0, maximum=2),
        p710_stored=t.integer("sim_p710_stored", d.p710_stored, minimum=0, maximum=2),
        ramp_time=t.number("sim_ramp_time", d.ramp_time, minimum=0.1, maximum=999.0),
        max_rpm=t.number("sim_max_rpm", d.max_rpm, minimum=1.0, maximum=SPEED_REF_MAX_RPM),
    )


def parse_drive(t: Table, drive: DriveConfig) -> DriveOptions:
    d = DriveOptions()
    assembly = t.integer(
        "assembly", int(d.assembly), allowed=[int(p) for p in AssemblyPair], what="an assembly"
    )
    max_rpm = t.number("max_rpm", None, minimum=1.0, maximum=SPEED_REF_MAX_RPM)
    max_rpm_param = t.integer("max_rpm_param", None, minimum=0, maximum=MAX_PARAMETER)
    if max_rpm is None and max_rpm_param is None:
        raise t.error("max_rpm", "is required (or max_rpm_param to read it at connect)")
    if max_rpm is not None and max_rpm_param is not None:
        raise t.error("max_rpm_param", "give max_rpm or max_rpm_param, not both")
    connection = t.enum("connection", IoKind, d.connection)
    ack = t.boolean("ack", d.ack)
    if not ack and connection is IoKind.POLLED:
        raise t.error("ack", "false needs connection = 'cos' or 'cyclic'")
    product_code = t.integer("product_code", None, minimum=0, maximum=0xFFFF)
    vendor_id = t.integer("vendor_id", d.vendor_id, minimum=0, maximum=0xFFFF)
    product_name = t.string("product_name", d.product_name)
    eds = _load_eds(t)
    adr = t.boolean("adr", d.adr)
    if adr and drive.address == ADR_MAC:
        raise t.error("adr", f"a drive at MAC {ADR_MAC} cannot be replaced from MAC {ADR_MAC}")
    product_type: int | None = None
    revision: tuple[int, int] | None = None
    io_sizes = d.io_sizes
    params: Mapping[int, Param] = {}
    if eds is not None:
        dev = eds.device
        for key, mine, theirs in (
            ("vendor_id", vendor_id, dev.vendor_code),
            ("product_code", product_code, dev.product_code),
            ("product_name", product_name, dev.product_name),
        ):
            if t.has(key) and mine != theirs:
                raise t.error(key, f"{mine!r} differs from the EDS ({eds.file}: {theirs!r})")
        vendor_id, product_code, product_name = dev.vendor_code, dev.product_code, dev.product_name
        product_type, revision = dev.product_type, (dev.major_rev, dev.minor_rev)
        io_sizes = _eds_sizes(t, eds, connection)
        params = eds_parameters(eds)
    return DriveOptions(
        assembly=AssemblyPair(assembly),
        connection=connection,
        ack=ack,
        check_identity=t.boolean("check_identity", d.check_identity),
        vendor_id=vendor_id,
        product_code=product_code,
        product_name=product_name,
        adr=adr,
        max_rpm=max_rpm,
        max_rpm_param=max_rpm_param,
        weg_speed_scale=t.integer("weg_speed_scale", d.weg_speed_scale, minimum=1, maximum=0xFFFF),
        at_reference_rpm=t.number(
            "at_reference_rpm", d.at_reference_rpm, minimum=0.0, maximum=SPEED_REF_MAX_RPM
        ),
        startup_params=_startup_params(t),
        sim=_sim(t),
        eds=eds,
        product_type=product_type,
        revision=revision,
        io_sizes=io_sizes,
        params=params,
    )


_EDS_CONNECTION = {
    IoKind.POLLED: ConnectionType.POLL,
    IoKind.COS: ConnectionType.COS,
    IoKind.CYCLIC: ConnectionType.CYCLIC,
}


def _load_eds(t: Table) -> Eds | None:
    text = t.string("eds", None)
    if text is None:
        return None
    path = Path(text)
    if not path.is_absolute() and Path(t.file).is_file():
        path = Path(t.file).resolve().parent / path  # relative to the config file
    try:
        return load_eds(path)
    except EdsError as exc:
        raise t.error("eds", str(exc)) from None


def _eds_sizes(t: Table, eds: Eds, connection: IoKind) -> tuple[int, int]:
    """The EDS's I/O sizes for the configured connection, checked against the assemblies
    in use (every CFW-08 assembly is 4 bytes, seed table 11)."""
    kind = _EDS_CONNECTION[connection]
    sizes = eds.io.sizes(kind)
    if sizes is None:
        raise t.error("eds", f"{eds.file} has no {kind.name} connection in [IO_Info]")
    if sizes != (ASSEMBLY_SIZE, ASSEMBLY_SIZE):
        raise t.error(
            "eds",
            f"{eds.file}: the {kind.name} connection is {sizes[0]} bytes in, {sizes[1]} "
            f"bytes out; the CFW-08 assemblies in use are {ASSEMBLY_SIZE} and {ASSEMBLY_SIZE} "
            "(seed table 11)",
        )
    return sizes


def eds_parameters(eds: Eds) -> dict[int, Param]:
    """The EDS parameters that name a CFW-08 parameter by their link path (seed 5.10)."""
    out: dict[int, Param] = {}
    for param in eds.params.values():
        try:
            path = objects.decode_path(param.path)
        except DeviceNetDecodeError:
            continue
        if path.class_id is None or path.attribute_id is None or path.instance_id != 1:
            continue
        number = parameter_of(path.class_id, path.attribute_id)
        if number is not None:
            out[number] = param
    return out
