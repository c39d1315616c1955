"""What the engine is given: the master's config from the bus keys (:func:`master_config`)
and each drive's bring-up plan, the SDO writes the engine makes at every connect, built
from the drive's config and its object dictionary (sizes from the EDS).

First a Shutdown written to the controlword by SDO: a drive found running when the
gateway (re)starts stops before it is configured (safety rule 1).

CiA 301 §7.5.2.35-38 (PDO parameters) gives the order of a PDO re-mapping: disable the
PDO (COB-ID bit 31), set the number of entries to 0, write the entries, set the number,
then the transmission type, then enable the PDO. Each write is read back (a COB-ID on
its valid bit and 11-bit id only). Then the heartbeats (0x1017 producer; 0x1016:1
consumer of the gateway's heartbeat), the drive's reaction to a lost connection (0x6007),
the quick stop option (0x605A), the mode (0x6060) and the ``startup_sdo`` writes.

Every other PDO the EDS has (0x1401-0x15FF, 0x1801-0x19FF with a sub-index 1) is
switched off: its COB-ID written with bit 31 set (PDO not valid, CiA 301 §7.5.2.35/36),
read back on that bit. The gateway owns the PDO configuration: a PDO it does not use
would load the line beyond what the SYNC period floor counts. A node that refuses it
(a read-only COB-ID) is reported and still brought up (``SdoStep.optional``).
"""

from __future__ import annotations

import math

from adapters.canopen.codec import cia402, frames
from adapters.canopen.codec.cia402 import Cw
from adapters.canopen.codec.frames import MappingEntry
from adapters.canopen.codec.od import Dictionary, Variable, obj_name
from adapters.canopen.master.control import VL_OPERATION_BITS
from adapters.canopen.master.events import MasterConfig, NodeConfig, PdoField, SdoStep
from adapters.canopen.options import BusOptions, DriveOptions, Mode

COB_MASK = 0x800007FF  # valid bit and the 11-bit id (bits 29-30 are the node's)
TRANSMISSION_SYNC = 1  # synchronous: every SYNC (CiA 301 table 70)
TRANSMISSION_EVENT = 255  # event-driven (device profile), with the event timer
LISTEN_MIN = 0.3  # s: the shortest listening before the first frame (one master per line)


def listen_time(options: BusOptions) -> float:
    """How long the engine listens before its first frame: long enough to hear two of the
    gateway's own SYNCs and heartbeats, as another instance of it would send them."""
    return max(LISTEN_MIN, 3 * options.cycle, 2 * options.heartbeat / 1000.0)


def master_config(o: BusOptions) -> MasterConfig:
    """The gateway's own node behaviour on the line, from the bus keys."""
    return MasterConfig(
        nmt_master=o.nmt_master,
        sync_period=o.sync_period,
        pdo_period=o.pdo_period,
        sdo_timeout=o.sdo_timeout,
        heartbeat_factor=o.heartbeat_factor,
        boot_timeout=o.boot_timeout,
        retry=o.retry,
        own_node_id=o.node_id,
        own_heartbeat=o.heartbeat / 1000.0,
        listen=listen_time(o),
    )


def _field(var: Variable) -> PdoField:
    return PdoField(MappingEntry(var.index, var.subindex, var.bits), var.signed)


def _write(
    eds: Dictionary, index: int, sub: int, value: int, what: str, *, mask: int = -1
) -> SdoStep:
    var = eds.variable(index, sub, why=what)
    full = (1 << var.bits) - 1 if var.bits < 64 else (1 << 64) - 1
    return SdoStep(index, sub, var.encode(value), what, mask & full)


def _pdo_steps(
    eds: Dictionary,
    comm: int,
    *,
    mapping: int,
    cob_id: int,
    fields: tuple[PdoField, ...],
    transmission: int,
    event_timer_ms: int | None,
) -> list[SdoStep]:
    name = ("RPDO" if comm < 0x1800 else "TPDO") + str((comm & 0x1FF) + 1)
    steps = [
        _write(
            eds,
            comm,
            1,
            frames.PDO_COB_INVALID | cob_id,
            f"{name} disabled for mapping",
            mask=COB_MASK,
        ),
        _write(eds, mapping, 0, 0, f"{name} mapping cleared"),
    ]
    for i, f in enumerate(fields, start=1):
        e = f.entry
        what = f"{name} mapping {obj_name(mapping, i)} = {obj_name(e.index, e.subindex or None)}"
        steps.append(_write(eds, mapping, i, e.encode(), what))
    steps.append(_write(eds, mapping, 0, len(fields), f"{name} mapping of {len(fields)} objects"))
    steps.append(_write(eds, comm, 2, transmission, f"{name} transmission type"))
    if event_timer_ms is not None and eds.has(comm, 5):
        steps.append(_write(eds, comm, 5, event_timer_ms, f"{name} event timer"))
    steps.append(_write(eds, comm, 1, cob_id, f"{name} enabled", mask=COB_MASK))
    return steps


PDO_VALID_MASK = frames.PDO_COB_INVALID  # an unused PDO's read-back: its valid bit only
UNUSED_RPDOS = range(0x1401, 0x1600)  # RPDO2-512 communication parameters
UNUSED_TPDOS = range(0x1801, 0x1A00)  # TPDO2-512


def _unused_pdo_steps(eds: Dictionary, node_id: int) -> list[SdoStep]:
    """Bit 31 of sub 1 set for every RPDO/TPDO but the first that the EDS has; the rest
    of the COB-ID as the EDS gives it (its default for this node), else the predefined
    connection set's id (PDOs 2-4, CiA 301 §7.3.5), else 0."""
    steps: list[SdoStep] = []
    for comm in (*UNUSED_RPDOS, *UNUSED_TPDOS):
        if not eds.has(comm, 1):
            continue
        var = eds.variable(comm, 1)
        rx = comm < 0x1800
        number = (comm & 0x1FF) + 1
        name = ("RPDO" if rx else "TPDO") + str(number)
        default = var.default
        if isinstance(default, int) and not isinstance(default, bool):
            cob = default & ~frames.PDO_COB_INVALID
        elif number <= 4:
            cob = (frames.rpdo_id if rx else frames.tpdo_id)(number, node_id)
        else:
            cob = 0
        steps.append(
            SdoStep(
                comm,
                1,
                var.encode(frames.PDO_COB_INVALID | (cob & 0xFFFFFFFF)),
                f"{name} switched off (not used): 0x{comm:04X}:1 bit 31",
                PDO_VALID_MASK,
                optional=True,
            )
        )
    return steps


def node_config(node_id: int, opts: DriveOptions, bus: BusOptions) -> NodeConfig:
    """The engine's view of one drive (see the module docstring)."""
    eds = opts.eds
    sync = bus.sync_period > 0
    # A drive found running (a gateway restart) stops before anything else: Shutdown by
    # SDO (CiA 402-2 transition 8, its 0x605B reaction); harmless in every other state.
    stop = SdoStep(
        cia402.CONTROLWORD,
        0,
        int(Cw.SHUTDOWN).to_bytes(opts.controlword.bits // 8, "little"),
        "controlword 0x6040 = Shutdown (a running drive stops first)",
        read_back=False,
    )
    steps = [stop, _write(eds, 0x1017, 0, opts.heartbeat_ms, "producer heartbeat time 0x1017")]
    release: tuple[SdoStep, ...] = ()
    if bus.heartbeat > 0 and opts.has_consumer_heartbeat:
        # a clean leave switches the consumer off first (node id 0, time 0: the entry is
        # not used, CiA 301 §7.2.8.3.2.1), so only a real loss of the gateway trips 0x6007
        release = (_write(eds, 0x1016, 1, 0, "consumer heartbeat time 0x1016:1 off (leaving)"),)
        consumer_ms = min(0xFFFF, math.ceil(bus.heartbeat * bus.heartbeat_factor))
        steps.append(
            _write(
                eds,
                0x1016,
                1,
                (bus.node_id << 16) | consumer_ms,
                f"consumer heartbeat time 0x1016:1 (node {bus.node_id}, {consumer_ms} ms)",
            )
        )
    rpdo = (_field(opts.controlword), _field(opts.target))
    tpdo = (_field(opts.statusword), _field(opts.actual), *(_field(v) for v in opts.extras))
    steps += _pdo_steps(
        eds,
        0x1400,
        mapping=0x1600,
        cob_id=frames.rpdo_id(1, node_id),
        fields=rpdo,
        transmission=TRANSMISSION_SYNC if sync else TRANSMISSION_EVENT,
        event_timer_ms=None,
    )
    timer = None if sync else max(1, round(bus.pdo_period * 1000))
    steps += _pdo_steps(
        eds,
        0x1800,
        mapping=0x1A00,
        cob_id=frames.tpdo_id(1, node_id),
        fields=tpdo,
        transmission=TRANSMISSION_SYNC if sync else TRANSMISSION_EVENT,
        event_timer_ms=timer,
    )
    steps += _unused_pdo_steps(eds, node_id)
    if opts.comm_loss_option is not None:
        value = opts.comm_loss_option
        text = cia402.abort_connection_option_text(value)
        steps.append(
            _write(
                eds,
                cia402.ABORT_CONNECTION_OPTION,
                0,
                value,
                f"abort connection option 0x6007 ({text})",
            )
        )
    if opts.quick_stop_option is not None:
        value = opts.quick_stop_option
        text = cia402.quick_stop_option_text(value)
        steps.append(
            _write(eds, cia402.QUICK_STOP_OPTION, 0, value, f"quick stop option 0x605A ({text})")
        )
    code = opts.mode.code
    mode_text = f"modes of operation 0x6060 = {code} ({cia402.MODES_OF_OPERATION_TEXT[code]})"
    steps.append(_write(eds, cia402.MODES_OF_OPERATION, 0, code, mode_text))
    for w in opts.startup_sdo:
        v = w.variable
        steps.append(
            SdoStep(
                v.index,
                v.subindex,
                w.data,
                f"startup_sdo {obj_name(v.index, v.subindex)} = {w.value}",
            )
        )
    reports: tuple[tuple[int, int], ...] = (
        ((cia402.QUICK_STOP_OPTION, 0),) if opts.has_quick_stop_option else ()
    )
    if eds.has(cia402.ABORT_CONNECTION_OPTION):
        # the drive's reaction to a lost master as it has it (the failsafe report)
        reports += ((cia402.ABORT_CONNECTION_OPTION, 0),)
    fault_reads = ((0x1001, 0),) + (((cia402.ERROR_CODE, 0),) if opts.has_error_code else ())
    return NodeConfig(
        node_id=node_id,
        heartbeat_ms=opts.heartbeat_ms,
        steps=tuple(steps),
        rpdo=rpdo,
        tpdo=tpdo,
        reports=reports,
        fault_reads=fault_reads,
        reset_if_operational=opts.reset_if_operational,
        mode_bits=VL_OPERATION_BITS if opts.mode is Mode.VELOCITY else 0,
        release=release,
    )
