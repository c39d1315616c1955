"""The CANopen adapter: python-can link + master engine + CiA 402 profile, as a DriveAdapter.

The engine (:mod:`adapters.canopen.master`) runs on the shared CAN driver loop
(:mod:`adapters.link.candriver`) in the event loop's thread: no canopen library network,
no notifier thread of its own, no blocking SDO call
(docs/decisions/0045-canopen-master-own-engine.md). The canopen library reads each drive's
EDS and encodes and decodes object values (:mod:`adapters.canopen.codec.od`).

Per drive: ``connecting`` once the node answers SDO; the bring-up writes (each read back)
then NMT start; ``online`` with its first TPDO. Until then the drive gets no PDO. A lost
heartbeat, a boot-up or a node leaving operational makes it ``offline``; it is brought
up again, and the hub clears any run command when it comes back online (safety rule 1):
it comes back stopped. A fault reset is one edge of controlword bit 7 (rule 2).

One master per line (issue 32 item 12): the engine listens for
:func:`~adapters.canopen.plan.listen_time` before its first frame; another master heard
then (a SYNC, an NMT command, a heartbeat with the gateway's node id, an RPDO to one of
its drives) refuses the line
(:class:`~gateway.errors.LineHeld`, the daemon does not start). Heard later, it is an
event on every drive of the line and their readings are doubtful. Frames that
contradict each other for one drive (a second TPDO1 in a SYNC cycle, an SDO answer no
request asked for) make that drive doubtful (``doubtful`` in the state, the hub refuses
run commands) until :data:`DOUBT_HOLD` s pass without another; the events naming the
node come at most every :data:`CONFLICT_EVENT_EVERY` s per drive, with the count.
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from adapters.can.adapter import BusSpec, CanAdapter, Drive, handles
from adapters.canopen.codec import cia402
from adapters.canopen.codec.codes import abort_message, emcy_text, error_register_texts
from adapters.canopen.codec.frames import CanFrame
from adapters.canopen.codec.od import obj_name
from adapters.canopen.drive import readings, want
from adapters.canopen.link import CanOpenBus
from adapters.canopen.master import (
    Action,
    Configured,
    Conflict,
    EmcyIn,
    Event,
    FaultInfo,
    Inputs,
    LineClaimed,
    Master,
    MasterConfig,
    MasterHeard,
    NodeDown,
    NodeProblem,
    NodeSeen,
    NodeUp,
    Report,
    SdoDone,
)
from adapters.canopen.options import (
    BusOptions,
    DriveOptions,
    check_sync_period,
    parse_bus,
    parse_drive,
)
from adapters.canopen.plan import master_config, node_config
from adapters.link.candriver import CanDriver
from adapters.link.canline import act_quietly, leave_line
from gateway.adapter import (
    Capabilities,
    EventKind,
    HubPort,
    ParamInfo,
    ParamTable,
    ParamValue,
    param_table,
)
from gateway.config import DriveConfig
from gateway.devices import devices_of
from gateway.errors import AdapterError, DriveOffline, GatewayTimeout, LineHeld, ParameterError
from gateway.model import CommState, DesiredCommand, DriveStatus, SpeedScale
from gateway.schema import Table

log = logging.getLogger(__name__)

LEAVE_WAIT = 0.05  # s given to the last frames on shutdown
LEAVE_MARGIN = 0.1  # s: beyond the SDO timeout, the bound on the release writes on leaving
DOUBT_HOLD = 10.0  # s without a conflicting frame before a drive's readings are trusted again
CONFLICT_EVENT_EVERY = 5.0  # s: at most one conflict event per drive this often
# s: every drive's desired command read again at least this often, told of a change or
# not (the line's fast path reads it when the hub says it changed: docs/decisions/0098)
COMMAND_SWEEP = 0.1
# 0x6007 values that stop the drive when the master is lost (CiA 402-2 §6.4.5: 1 fault,
# 2 disable voltage, 3 quick stop; 0 no action; negative: the manufacturer's, unknown)
FAILSAFE_OPTIONS = frozenset({1, 2, 3})


@dataclass(slots=True)
class _Drive(Drive):
    opts: DriveOptions
    up: bool = False  # NMT operational (NodeUp) since it was last lost
    online: bool = False  # reported online to the hub (first TPDO)
    reset_seen: int = 0
    fault_code: int | None = None
    was_faulted: bool = False
    emcy_code: int | None = None
    problem: str | None = None
    quick_stop_option: int | None = None
    input_key: object = None
    stale: bool = True  # the desired command is to be read again before the next cycle
    want_from: object = None  # the desired command the engine's wish was made of
    want_made: object = None  # that wish
    doubtful: bool = False  # conflicting frames heard (reported to the hub)
    doubt_until: float = 0.0  # trusted again from then on, unless another conflict comes
    conflicts: int = 0  # conflicts since the last conflict event
    conflict_event_at: float = -math.inf  # when the last conflict event went out

    @property
    def node(self) -> int:
        return self.cfg.address


def eds_param_table(opts: DriveOptions) -> ParamTable:
    """The EDS objects by index (the parameter number of a CANopen drive is the object
    index, its subindex the subindex): name and unit for the front ends."""
    eds = opts.eds
    out: list[ParamInfo] = []
    for index in eds.indexes():
        subs = eds.subindexes(index)
        sub = 0 if subs == (0,) else None
        entry = eds.od[index]
        out.append(
            ParamInfo(
                number=index,
                name=str(entry.name),
                unit=eds.variable(index).unit if sub == 0 else "",
                code=f"0x{index:04X}",
            )
        )
    return param_table(out)


class CanOpenAdapter(CanAdapter[CanFrame, Event, Action, Master, _Drive, BusOptions, SdoDone]):
    """One CANopen line mastered by the gateway, with its CiA 402 drives."""

    spec = BusSpec(BusOptions, parse_bus, CanOpenBus, SdoDone)
    devices = devices_of("canopen")
    address_range = (1, 127)
    fast_path: ClassVar[bool] = True
    """The steady fast path (docs/decisions/0098): a drive's unchanged TPDO1 not handled
    while nothing else changed, its desired command read when the hub says it changed
    (and every :data:`COMMAND_SWEEP` s). False: every TPDO1 handled, every command read
    before every cycle (the general path, which the fast path's frames must equal)."""

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> DriveOptions:
        return parse_drive(table, drive)

    @classmethod
    def check_bus(cls, table: Table, options: BusOptions, drives: list[DriveOptions]) -> None:
        """The SYNC period against the bus time of one cycle of these drives."""
        check_sync_period(table, options, drives)

    def new_drive(self, cfg: DriveConfig) -> _Drive:
        o = self.options
        if o.heartbeat > 0 and cfg.address == o.node_id:
            raise AdapterError(
                f"drive {cfg.id} has the gateway's own node id {cfg.address} (bus key 'node_id')"
            )
        return _Drive(cfg, cfg.options)

    def setup(self) -> None:
        o = self.options
        self.node_configs = [node_config(d.node, d.opts, o) for d in self.drives.values()]
        self._next_refresh = 0.0
        self._sweep_at = 0.0

    async def run(self, hub: HubPort) -> None:
        """The line's run (:meth:`CanAdapter.run`), told of every new desired command."""
        off = hub.on_command(self._on_command) if self.fast_path else None
        try:
            await super().run(hub)
        finally:
            if off is not None:
                off()

    def master_config(self) -> MasterConfig:
        return master_config(self.options)

    # ------------------------------------------------------------ run

    def make_engine(self) -> Master:
        self._sweep_at = 0.0
        for d in self.drives.values():
            d.stale = True
        return Master(self.master_config(), self.node_configs)

    def drive_left(self, d: _Drive) -> None:
        d.up = d.online = False

    async def leave(self, engine: Master, driver: CanDriver[CanFrame, Event, Action]) -> None:
        """Leave the line cleanly (docs/devices.md, "Leaving the line"): each drive's
        consumer of the gateway's heartbeat switched off by SDO, bounded by the SDO
        timeout, while SYNC, RPDOs (the shutdown stop: the wishes refreshed each pass) and
        the heartbeat go on; then the last RPDOs, a SYNC and NMT enter pre-operational."""
        await leave_line(
            driver,
            engine.release,
            lambda: engine.released,
            bound=self.options.sdo_timeout + LEAVE_MARGIN,
            longest_wait=LEAVE_WAIT,
            before_step=self._refresh,
        )
        now = self.clock()
        self._refresh(now)
        act_quietly(driver, now, engine.leave(now))
        driver.flush(now)
        await asyncio.sleep(LEAVE_WAIT)

    def publish_capabilities(self, d: _Drive) -> None:
        self._hub_port().set_capabilities(d.id, self._capabilities(d))

    def _capabilities(self, d: _Drive) -> Capabilities:
        return Capabilities(
            speed_scale=SpeedScale(d.opts.max_rpm, 100.0, "max_rpm"),
            unsupported={"jog": "CiA 402 velocity modes have no jog"},
            params=eds_param_table(d.opts),
        )

    # ------------------------------------------------------------ outputs

    def before_step(self, now: float) -> None:
        if now >= self._next_refresh:
            self._refresh(now)
            self._next_refresh = now + self.options.cycle

    def after_step(self, now: float) -> None:
        """The next refresh comes with the engine's next cycle (SYNC and RPDOs): the
        wishes are made just before the cycle that sends them, in the same pass of the
        driver, so the refresh costs no wake-up of its own."""
        engine = self.engine
        if engine is not None:
            cycle_at = engine.next_cycle
            if cycle_at is not None and cycle_at < self._next_refresh:
                self._next_refresh = cycle_at

    def wake_at(self) -> float | None:
        engine = self.engine
        if engine is None or engine.next_cycle is None:
            return None  # listening (or left): no cycle, no wish to refresh for it
        return self._next_refresh

    def _refresh(self, now: float) -> None:
        """The hub's desired commands into the engine's wishes, once per cycle. A drive
        not reported online is wished stopped whatever the hub holds (it goes online
        first, which clears a run: rule 1); a new reset request is one edge.

        The fast path reads a drive's command only when it may have changed: the hub said
        so (:meth:`_on_command`), the line reported a change of the drive (the port may
        hold a run back until the hub applied it), the engine replaced the wish (the node
        was lost), and every :data:`COMMAND_SWEEP` s."""
        engine, hub = self.engine, self._hub
        if engine is None or hub is None:
            return
        sweep = not self.fast_path or now >= self._sweep_at
        if sweep:
            self._sweep_at = now + COMMAND_SWEEP
        for d in self.drives.values():
            if d.doubtful and now >= d.doubt_until:
                self._trust(d)
            if not d.online:
                engine.set_want(d.node, want(_STOPPED_DESIRED, d.opts))
                d.want_from = None
                d.stale = True
                continue
            if sweep or d.stale or engine.wish(d.node) is not d.want_made:
                d.stale = False
                self._command(d, hub.desired(d.id), engine, now)

    def _command(self, d: _Drive, desired: DesiredCommand, engine: Master, now: float) -> None:
        """An online drive's desired command into the engine's wish; a new reset request
        is one edge (:meth:`Master.fault_reset`, only from a cycle's refresh)."""
        # the hub's commands are frozen: the same object is the same command, and the
        # wish made of it is still the engine's (unless the engine replaced it)
        if desired is not d.want_from or engine.wish(d.node) is not d.want_made:
            d.want_made = want(desired, d.opts)
            engine.set_want(d.node, d.want_made)
            if desired != d.want_from:
                engine.quiet_inputs(d.node, False)  # its readings show the command
            d.want_from = desired
        if desired.fault_reset_seq != d.reset_seen:
            d.reset_seen = desired.fault_reset_seq
            if engine.fault_reset(d.node, now):
                self._hub_port().event(
                    d.id, EventKind.FAULT, "fault reset sent (controlword bit 7 edge)"
                )

    def _on_command(self, drive_id: str) -> None:
        """The hub's desired command of a drive changed (on the line's loop): the new wish
        is the engine's at once, so the next cycle's RPDO1 carries it, and the drive's next
        TPDO1 is handled (its readings show the command). A reset request waits for the
        cycle's refresh (the pulse is timed from a cycle)."""
        d = self._by_id.get(drive_id)
        engine, hub = self.engine, self._hub
        if d is None or engine is None or hub is None:
            return
        d.stale = True
        if not d.online:
            return
        engine.quiet_inputs(d.node, False)
        desired = hub.desired(d.id)
        if desired is not d.want_from or engine.wish(d.node) is not d.want_made:
            d.want_made = want(desired, d.opts)
            engine.set_want(d.node, d.want_made)
            d.want_from = desired

    # ------------------------------------------------------------ actions

    @handles(LineClaimed)
    def _on_claimed(self, now: float, action: LineClaimed) -> None:
        log.info("CANopen %s: no other master heard: the line is the gateway's", self.name)
        self.claimed.set()

    @handles(MasterHeard)
    def _on_master_heard(self, now: float, action: MasterHeard) -> None:
        """Another master on the line (CiA 301: one NMT master, one SYNC producer). Before
        the first frame: the line is refused, nothing was sent. Later: reported on every
        drive of the line (rate-limited), whose readings become doubtful."""
        o = self.options
        line = f"CANopen {o.interface} channel {o.channel}"
        hub = self._hub_port()
        if not action.claimed:
            text = f"{line}: {action.text}: another master is on this line"
            for d in self.drives.values():
                hub.event(d.id, EventKind.BUS, f"{text}; the gateway does not start on it")
            raise LineHeld(f"{text}: stop it (one master per line)")
        for d in self.drives.values():
            self._doubt(d, now, f"another master on the line: {action.text}")

    @handles(Conflict)
    def _on_conflict(self, now: float, action: Conflict) -> None:
        d = self.drives[action.node]
        self._doubt(d, now, f"node {d.node}: {action.what}")

    def _doubt(self, d: _Drive, now: float, text: str) -> None:
        """Frames that contradict each other: the readings may be forged (CAN carries no
        authentication): doubtful until DOUBT_HOLD s pass without another."""
        d.doubt_until = now + DOUBT_HOLD
        d.conflicts += 1
        hub = self._hub_port()
        if not d.doubtful:
            d.doubtful = True
            hub.update(d.id, doubtful=True)
        if now - d.conflict_event_at >= CONFLICT_EVENT_EVERY:
            count, d.conflicts = d.conflicts, 0
            d.conflict_event_at = now
            log.warning("CANopen %s: drive %s: %s (%d)", self.name, d.id, text, count)
            hub.event(
                d.id,
                EventKind.BUS,
                f"{text}; readings doubtful ({count} conflicting frame(s) since the last "
                "such event)",
                node=d.node,
                conflicts=count,
            )

    def _trust(self, d: _Drive) -> None:
        d.doubtful = False
        d.conflicts = 0
        hub = self._hub_port()
        hub.update(d.id, doubtful=False)
        hub.event(
            d.id,
            EventKind.BUS,
            f"node {d.node}: no conflicting frame for {DOUBT_HOLD:g} s: readings trusted again",
            node=d.node,
        )

    @handles(NodeSeen)
    def _on_seen(self, now: float, action: NodeSeen) -> None:
        d = self.drives[action.node]
        self._hub_port().update(d.id, comm=CommState.CONNECTING)

    @handles(Configured)
    def _on_configured(self, now: float, action: Configured) -> None:
        d = self.drives[action.node]
        d.problem = None
        o = d.opts
        text = f"configured: node {d.node}, mode {o.mode.value}, heartbeat {o.heartbeat_ms} ms"
        raw = action.reports.get((cia402.QUICK_STOP_OPTION, 0))
        if raw:
            d.quick_stop_option = int.from_bytes(raw, "little", signed=True)
            option = d.quick_stop_option
            text += (
                f"; quick stop option 0x605A = {option} ({cia402.quick_stop_option_text(option)})"
            )
        raw = action.reports.get((cia402.ABORT_CONNECTION_OPTION, 0))
        comm_loss = d.opts.comm_loss_option
        if raw:
            comm_loss = int.from_bytes(raw, "little", signed=True)
        if comm_loss is not None:
            text += (
                f"; abort connection option 0x6007 = {comm_loss} "
                f"({cia402.abort_connection_option_text(comm_loss)})"
            )
        hub = self._hub_port()
        hub.event(d.id, EventKind.CONFIG, text, quick_stop_option=d.quick_stop_option)
        failsafe, failsafe_text = failsafe_of(comm_loss, self._consumer_text(d))
        hub.update(d.id, failsafe=failsafe, failsafe_text=failsafe_text)

    def _consumer_text(self, d: _Drive) -> str | None:
        """What the bring-up set the drive to watch (0x1016:1), None when nothing."""
        o = self.options
        if o.heartbeat <= 0 or not d.opts.has_consumer_heartbeat:
            return None
        ms = min(0xFFFF, math.ceil(o.heartbeat * o.heartbeat_factor))
        return f"0x1016:1 watches node {o.node_id}'s heartbeat ({ms} ms)"

    def _loud(self, d: _Drive) -> None:
        """The drive's next TPDO1 is handled whatever its bytes (something besides them
        changed its readings)."""
        d.input_key = None
        engine = self.engine
        if engine is not None:
            engine.quiet_inputs(d.node, False)

    @handles(NodeUp)
    def _on_up(self, now: float, action: NodeUp) -> None:
        d = self.drives[action.node]
        d.up = True
        self._loud(d)
        d.reset_seen = self._hub_port().desired(d.id).fault_reset_seq

    @handles(NodeDown)
    def _on_down(self, now: float, action: NodeDown) -> None:
        d = self.drives[action.node]
        d.up = d.online = False
        self._loud(d)
        hub = self._hub_port()
        hub.update(d.id, comm=CommState.OFFLINE, running=False, at_reference=False)
        hub.event(d.id, EventKind.COMM, f"drive offline: {action.reason}", node=d.node)

    @handles(NodeProblem)
    def _on_problem(self, now: float, action: NodeProblem) -> None:
        d = self.drives[action.node]
        text = f"not configured: node {d.node}: {action.text}; the drive is not started"
        if text != d.problem:
            log.warning("CANopen %s: drive %s %s", self.name, d.id, text)
            data: dict[str, Any] = {"node": d.node}
            if action.abort_code is not None:
                data["abort_code"] = action.abort_code
            self._hub_port().event(d.id, EventKind.CONFIG, text, **data)
        d.problem = text
        d.up = d.online = False
        self._hub_port().update(d.id, comm=CommState.OFFLINE, running=False)

    @handles(Inputs)
    def _on_inputs(self, now: float, action: Inputs) -> None:
        d = self.drives[action.node]
        if not d.up:
            return
        hub = self._hub_port()
        desired = hub.desired(d.id)
        key = (action.statusword, action.values, desired, d.fault_code)
        if key == d.input_key and d.online:
            # nothing new: its repeats need not come (the line's fast path)
            if self.fast_path and self.engine is not None:
                self.engine.quiet_inputs(d.node, True)
            return
        d.input_key = key
        d.stale = True  # the port may hold a run back until the hub took the change
        changes = readings(action.statusword, action.values, desired, d.opts, d.fault_code)
        faulted = changes["status"] is DriveStatus.FAULTED
        if d.was_faulted and not faulted:
            d.fault_code = None  # the fault ended: the next one brings its own code
        d.was_faulted = faulted
        if not d.online:
            d.online = True
            hub.update(d.id, comm=CommState.ONLINE, **changes)  # clears a run (rule 1)
            return
        hub.update(d.id, **changes)

    @handles(EmcyIn)
    def _on_emcy(self, now: float, action: EmcyIn) -> None:
        d = self.drives[action.node]
        emcy = action.emcy
        hub = self._hub_port()
        if emcy.error_code == 0:
            d.emcy_code = None
            hub.event(d.id, EventKind.FAULT, "EMCY error reset (no error)", node=d.node)
            return
        d.emcy_code = d.fault_code = emcy.error_code
        self._loud(d)
        register = ", ".join(error_register_texts(emcy.error_register)) or "none"
        hub.event(
            d.id,
            EventKind.FAULT,
            f"EMCY 0x{emcy.error_code:04X} {emcy_text(emcy.error_code)} "
            f"(error register 0x{emcy.error_register:02X}: {register})",
            code=emcy.error_code,
            error_register=emcy.error_register,
            node=d.node,
        )

    @handles(FaultInfo)
    def _on_fault_info(self, now: float, action: FaultInfo) -> None:
        d = self.drives[action.node]
        raw = action.reads.get((cia402.ERROR_CODE, 0))
        register = action.reads.get((0x1001, 0))
        code = int.from_bytes(raw, "little") if raw else None
        if code:
            d.fault_code = code
            self._loud(d)
        parts = []
        if code is not None:
            parts.append(f"0x603F = 0x{code:04X} {emcy_text(code)}")
        if register:
            value = register[0]
            names = ", ".join(error_register_texts(value)) or "none"
            parts.append(f"0x1001 = 0x{value:02X} ({names})")
        if parts:
            self._hub_port().event(
                d.id, EventKind.FAULT, "fault read: " + "; ".join(parts), code=code, node=d.node
            )

    @handles(Report)
    def _on_report(self, now: float, action: Report) -> None:
        log.info("CANopen %s: %s", self.name, action.text)
        targets = [self.drives[action.node]] if action.node in self.drives else []
        for d in targets:
            self._hub_port().event(d.id, EventKind.BUS, action.text)

    # ------------------------------------------------------------ parameters

    async def sdo(self, drive_id: str, index: int, subindex: int, write: bytes | None) -> bytes:
        """One SDO transfer with a drive; the bytes read (empty for a write). An abort is
        a ParameterError with the CiA 301 code and text."""
        d = self._drive(drive_id)
        bound = 4 * self.options.sdo_timeout + 1.0
        done = await self.exchange(
            d, lambda engine: engine.submit(d.node, index, subindex, write), bound, "SDO answer"
        )
        if done.result is None:
            raise DriveOffline(f"drive {d.id}: {done.error}")
        result = done.result
        what = f"{'write' if write is not None else 'read'} {obj_name(index, subindex or None)}"
        if result.abort_code is not None:
            if not result.by_server and result.abort_code == 0x05040000:
                raise GatewayTimeout(f"drive {d.id}: {what}: no SDO answer")
            raise ParameterError(f"{abort_message(result.abort_code)} ({what})", result.abort_code)
        return result.data

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        d = self._drive(drive_id)
        eds = d.opts.eds
        data = await self.sdo(drive_id, number, subindex, None)
        if not eds.has(number, subindex):
            return int.from_bytes(data, "little")
        var = eds.variable(number, subindex)
        try:
            return var.decode(data)
        except (ValueError, TypeError) as exc:
            raise ParameterError(f"{obj_name(number, subindex)}: {exc}") from None

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        d = self._drive(drive_id)
        eds = d.opts.eds
        where = obj_name(number, subindex or None)
        if not eds.has(number, subindex):
            raise ParameterError(f"{eds.file}: the EDS has no object {where}; nothing written")
        var = eds.variable(number, subindex)
        if not var.writable:
            raise ParameterError(f"{where} ({var.name}) is read-only in {eds.file}")
        if var.integer and (not math.isfinite(value) or value != int(value)):
            raise ParameterError(f"{where} ({var.name}) takes an integer, not {value!r}")
        if (var.minimum is not None and value < var.minimum) or (
            var.maximum is not None and value > var.maximum
        ):
            raise ParameterError(
                f"{value} is outside {var.minimum}..{var.maximum} for {where} ({var.name}, "
                f"{eds.file}); nothing written"
            )
        try:
            data = var.encode(value)
        except (ValueError, OverflowError, TypeError) as exc:
            raise ParameterError(f"{value} does not fit {where} ({var.name}): {exc}") from None
        await self.sdo(drive_id, number, subindex, data)

    def param_info(self, drive_id: str, number: int, raw: ParamValue) -> dict[str, Any]:
        eds = self._drive(drive_id).opts.eds
        if not eds.has(number):
            return {}
        var = eds.variable(number)
        return {"name": var.name, "unit": var.unit}

    # ------------------------------------------------------------ diagnostics

    def line_diagnostics(self, engine: Master | None) -> dict[str, Any]:
        o = self.options
        line: dict[str, Any] = {
            "node_id": o.node_id,
            "nmt_master": o.nmt_master,
            "sync_period": o.sync_period,
        }
        if engine is not None:
            line.update(engine.figures)
        return line

    def drive_diagnostics(self, d: _Drive) -> dict[str, Any]:
        return {
            "node": d.node,
            "eds": d.opts.eds.file,
            "mode": d.opts.mode.value,
            "online": d.online,
            "problem": d.problem,
            "quick_stop_option": d.quick_stop_option,
        }


_STOPPED_DESIRED = DesiredCommand()


def failsafe_of(option: int | None, consumer: str | None) -> tuple[bool | None, str]:
    """The drive's own reaction to a lost master (issue 32 item 5): its heartbeat consumer
    (CiA 301 §7.2.8.3.2, 0x1016:1) and what 0x6007 does then (CiA 402-2 §6.4.5).

    True: it stops or faults; False: it keeps running; None: not known."""
    if consumer is None:
        return False, (
            "no heartbeat consumer set (bus heartbeat = 0, or the EDS has no 0x1016:1): the "
            "drive does not notice a lost master and keeps running"
        )
    if option is None:
        return None, f"{consumer}; 0x6007 not known (not in the EDS, not configured)"
    text = f"{consumer}, then 0x6007 = {option} ({cia402.abort_connection_option_text(option)})"
    if option in FAILSAFE_OPTIONS:
        return True, text
    if option == 0:
        return False, text + ": the drive keeps running"
    return None, text + ": its effect is not known"
