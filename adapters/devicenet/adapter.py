"""The DeviceNet adapter: python-can link + scanner engine + device profiles, as a DriveAdapter.

Each drive has the :class:`~adapters.devicenet.contract.DnProfile` its device registers
(``adapters.devicenet.contract.PROFILES``); the adapter names no device. Per drive, once
the scanner has it online (allocated, identity and sizes checked, EPR set), the profile
configures it through explicit messages (:meth:`DnProfile.on_connect`). Until that
succeeds the scanner sends idle (zero-length) I/O and the drive stays ``connecting``: it
never runs half-set. Then I/O carries the desired command and the readings make the
drive ``online``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from adapters.can.adapter import BusSpec, CanAdapter, Drive, handles
from adapters.devicenet.adr import AdrWatch
from adapters.devicenet.codec.datatypes import AttributeValue
from adapters.devicenet.codec.eds import Param
from adapters.devicenet.codec.explicit import Request, Response
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.objects import INACTIVITY_EPR_FACTOR
from adapters.devicenet.contract import (
    RESET_OFFLINE_WINDOW,
    DnProfile,
    NodeOptions,
    NotConfigured,
    load_profile,
)
from adapters.devicenet.errors import DeviceNetDecodeError
from adapters.devicenet.link import DeviceNetBus, LinkEvent, RxFrame
from adapters.devicenet.options import BusOptions, parse_bus
from adapters.devicenet.scanner import (
    Action,
    Event,
    ExplicitResult,
    IdentityCheck,
    InputData,
    IoConflict,
    LineFault,
    LineOnline,
    NodeConfig,
    NodeDown,
    NodeUp,
    Phase,
    Report,
    ReportKind,
    Scanner,
    ScannerConfig,
)
from adapters.link.candriver import CanDriver
from adapters.link.canline import leave_line
from gateway.adapter import (
    EventKind,
    HubPort,
    ParamInfo,
    ParamTable,
    ParamValue,
    param_table,
)
from gateway.config import DriveConfig
from gateway.devices import devices_of
from gateway.errors import (
    AdapterError,
    DriveOffline,
    GatewayTimeout,
    LineHeld,
    ParameterError,
)
from gateway.model import CommState, DesiredCommand
from gateway.schema import Table

log = logging.getLogger(__name__)

LEAVE_BOUND = 1.0  # s: the shortest bound on the wait for Release answers on shutdown
LEAVE_WAIT = 0.02  # s: the longest wait between two steps while leaving
SCANNER_SERIAL_BASE = 0x44470000  # our Duplicate MAC ID check serial ("DG" + MAC)
IDLE = "idle"
# Doubtful readings (issue 32 item 12): a drive whose poll responses conflicted is doubtful
# until this many of its inputs in a row came without a conflict (at least this many poll
# cycles: a forger answering each poll keeps it doubtful); a reconnect does not clear it.
DOUBT_CLEAN_INPUTS = 50
CONFLICT_EVENT_INTERVAL = 10.0  # s: at most one conflict event per drive this often
# A quiet drive's outputs are refreshed from the hub at least this often besides its
# command changes (docs/decisions/0097); the scanner reports its unchanged inputs as often.
INPUTS_REFRESH = 0.1  # s

REPORT_EVENTS: dict[ReportKind, EventKind] = {
    ReportKind.ALLOCATION: EventKind.COMM,
    ReportKind.IDENTITY: EventKind.CONFIG,
    ReportKind.SIZE: EventKind.CONFIG,
    ReportKind.TIMEOUT: EventKind.COMM,
    ReportKind.DUPLICATE_MAC: EventKind.BUS,
    ReportKind.BUS: EventKind.BUS,
    ReportKind.PROTOCOL: EventKind.COMM,
}


@dataclass(slots=True)
class _Drive(Drive):
    opts: NodeOptions
    profile: DnProfile
    configured: bool = False
    setup: asyncio.Task[None] | None = None
    status: asyncio.Task[None] | None = None
    reset_seen: int = 0
    reset_until: float = 0.0
    reset_sent_at: float | None = None
    problem: str | None = None
    bad_inputs: int = 0
    output_key: object = None  # what the current output was computed from
    input_key: object = None  # the last input data and desired command mapped
    # Rule 1 (issue 32 item 1): after every (re)connection the outputs carry no run and no
    # jog until the hub's desired command is one without them, or one given since (not
    # the object held when the drive was lost or configured): a run from before the loss
    # is never sent, whatever the hub still holds.
    armed: bool = False
    held: object = None  # the desired command when the drive was (re)connected
    doubtful: bool = False
    clean_inputs: int = 0  # inputs in a row without a conflict, while doubtful
    conflicts_unsaid: int = 0  # conflicts since the last conflict event
    conflict_said_at: float | None = None

    @property
    def mac(self) -> int:
        return self.cfg.address

    @property
    def values(self) -> dict[str, float | int]:
        return self.profile.values


@dataclass(frozen=True, slots=True)
class _Port:
    """One drive as its profile sees it (adapters.devicenet.contract.DrivePort)."""

    adapter: DeviceNetAdapter
    drive: _Drive

    @property
    def bitrate(self) -> int:
        return self.adapter.options.bitrate

    @property
    def io_timeout(self) -> float:
        return INACTIVITY_EPR_FACTOR * self.adapter.options.expected_packet_rate

    async def request(self, body: Request) -> Response:
        return await self.adapter._request(self.drive, body)

    def event(self, kind: EventKind, text: str, **data: Any) -> None:
        self.adapter._hub_port().event(self.drive.id, kind, text, **data)

    def capabilities_changed(self) -> None:
        self.adapter.publish_capabilities(self.drive)

    def values_changed(self) -> None:
        d = self.drive
        self.adapter._hub_port().update(d.id, values=d.values)


def eds_param_table(params: Mapping[int, Param]) -> ParamTable:
    """The EDS parameters (P number -> ParamN) as the drive's parameter table: name, units,
    limits and the EDS scaling ((raw + offset) x multiplier x base / divisor / 10^decimals)."""
    return param_table(
        ParamInfo(
            number=number,
            name=p.name,
            unit=p.units,
            decimals=p.decimals,
            minimum=None if p.minimum is None else p.scale(p.minimum),
            maximum=None if p.maximum is None else p.scale(p.maximum),
            code=f"P{number}",
            multiplier=p.multiplier * p.base / p.divisor,
            offset=p.offset,
        )
        for number, p in sorted(params.items())
    )


class DeviceNetAdapter(
    CanAdapter[CanFrame, Event, Action, Scanner, _Drive, BusOptions, ExplicitResult]
):
    """One DeviceNet line scanned by the gateway, with the drives of :data:`PROFILES`."""

    spec = BusSpec(BusOptions, parse_bus, DeviceNetBus, ExplicitResult)
    devices = devices_of("devicenet")  # the registry's
    address_range = (0, 63)

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> NodeOptions:
        """The drive's keys, as the profile of its device reads them."""
        return load_profile(drive.device).parse_options(table, drive)

    def new_drive(self, cfg: DriveConfig) -> _Drive:
        if cfg.address == self.options.mac:
            raise AdapterError(
                f"drive {cfg.id} has the scanner's MAC ID {cfg.address} (bus key 'mac')"
            )
        opts: NodeOptions = cfg.options
        return _Drive(cfg, opts, load_profile(cfg.device)(cfg.id, opts))

    def setup(self) -> None:
        self._next_refresh = self._next_full = 0.0
        self._loud = True  # a drive online is not quiet (the last refresh found one)
        self._refreshed_cycle = -1  # the poll cycles counted at the last refresh
        self.adr = AdrWatch(
            self.name,
            self.options,
            self.drives,
            clock=self.clock,
            hub=self._hub_port,
            queue=lambda frame: self._driver.queue(frame) if self._driver is not None else None,
        )
        """Automatic Device Replacement of the ``adr`` drives."""

    # ------------------------------------------------------------ configuration

    def scanner_config(self) -> ScannerConfig:
        o = self.options
        return ScannerConfig(
            mac=o.mac,
            vendor_id=o.vendor_id,
            serial_number=SCANNER_SERIAL_BASE + o.mac,
            poll_interval=o.poll_interval,
            response_timeout=o.response_timeout,
            explicit_timeout=o.explicit_timeout,
            explicit_epr=o.explicit_epr,
            dupmac_timeout=o.dupmac_timeout,
            allocate_timeout=o.explicit_timeout,
            retry_min=min(0.5, o.retry_max),
            retry_max=o.retry_max,
            bitrate=o.bitrate,
        )

    def node_configs(self) -> list[NodeConfig]:
        out = []
        for d in self.drives.values():
            o = d.opts
            identity = IdentityCheck()
            if o.check_identity:
                identity = IdentityCheck(
                    o.vendor_id,
                    o.product_code,
                    o.product_name or None,
                    product_type=o.product_type,
                    revision=o.revision,
                )
            out.append(
                NodeConfig(
                    mac=d.mac,
                    io=o.connection,
                    ack=o.ack,
                    # the sizes of the device's assemblies; an EDS's sizes are checked
                    # against them when the config is read (options.py)
                    produced_size=o.io_sizes[0],
                    consumed_size=o.io_sizes[1],
                    epr=self.options.expected_packet_rate,
                    identity=identity,
                )
            )
        return out

    # ------------------------------------------------------------ run

    async def run(self, hub: HubPort) -> None:
        """The line's run (:meth:`CanAdapter.run`), told of every new desired command
        (docs/decisions/0097)."""
        off = hub.on_command(self._on_command)
        try:
            await super().run(hub)
        finally:
            off()

    def make_engine(self) -> Scanner:
        self._next_refresh = self._next_full = 0.0
        self._refreshed_cycle = -1
        return Scanner(self.scanner_config(), self.node_configs())

    async def stop_work(self) -> None:
        tasks = [t for d in self.drives.values() for t in (d.setup, d.status) if t is not None]
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task

    def before_step(self, now: float) -> None:
        """Desired commands reach the outputs once per poll: every ``poll_interval``, and
        no more than once per poll cycle (a cycle longer than the interval polls each node
        once; refreshing the outputs meanwhile would cost a pass over every drive, every
        interval, for nothing). A quiet drive (docs/decisions/0097) is refreshed when its
        command changes (:meth:`_on_command`) and in a full pass every
        :data:`INPUTS_REFRESH` s; with every drive quiet, nothing is refreshed between."""
        if now >= self._next_refresh and self._refresh_due():
            self._refresh_outputs(now)
            if self._loud:
                self._next_refresh = now + self.options.poll_interval
            else:
                self._next_refresh = min(now + INPUTS_REFRESH, self._next_full)
            if self.engine is not None:
                self._refreshed_cycle = self.engine.line.cycles

    def _refresh_due(self) -> bool:
        """No poll cycle under way, or one ended since the last refresh."""
        engine = self.engine
        return (
            engine is None
            or engine.schedule.cycle_started is None
            or engine.line.cycles != self._refreshed_cycle
        )

    def wake_at(self) -> float | None:
        adr = self.adr.deadline()
        # mid-cycle the refresh waits for the cycle's end: an event (its last poll reply,
        # or the scanner's own poll timeout), which steps the driver anyway
        refresh = self._next_refresh if self._refresh_due() else None
        if adr is None:
            return refresh
        return adr if refresh is None or adr < refresh else refresh

    def after_step(self, now: float) -> None:
        engine = self.engine
        if engine is not None:
            self.adr.tick(now, engine)

    def received(self, now: float, event: LinkEvent) -> None:
        if self.adr.probe is not None and isinstance(event, RxFrame):
            self.adr.received(now, event.frame)

    async def leave(self, engine: Scanner, driver: CanDriver[CanFrame, Event, Action]) -> None:
        """Release every node (fact sheet 2.10 step 8), bounded."""
        if not engine.online:
            return
        # the Releases go out request_spacing apart, each answered within explicit_timeout
        spread = len(engine.nodes) * engine.config.request_spacing
        bound = max(LEAVE_BOUND, spread + self.options.explicit_timeout)
        await leave_line(
            driver, engine.leave, lambda: engine.left, bound=bound, longest_wait=LEAVE_WAIT
        )

    # ------------------------------------------------------------ actions

    @handles(LineOnline)
    def _on_line_online(self, now: float, action: LineOnline) -> None:
        log.info("DeviceNet %s: scanner MAC %d online", self.name, self.options.mac)
        self.claimed.set()
        for d in self.drives.values():
            self._hub_port().update(d.id, comm=CommState.CONNECTING)

    @handles(LineFault)
    def _on_line_fault(self, now: float, action: LineFault) -> None:
        """The scanner's MAC ID is answered on the line: another master is there (fact
        sheet 2.3: a device failing its check stays off the line). Nothing but the two
        check requests went out; the gateway does not start on this line."""
        hub = self._hub_port()
        for d in self.drives.values():
            hub.event(d.id, EventKind.BUS, action.text)
        o = self.options
        raise LineHeld(
            f"DeviceNet {o.interface} channel {o.channel}: {action.text}; another master is "
            "on this line: stop it (one master per line)"
        )

    @handles(NodeUp)
    def _on_node_up(self, now: float, action: NodeUp) -> None:
        d = self.drives[action.mac]
        self._disarm(d)
        self._hub_port().update(d.id, comm=CommState.CONNECTING)
        if d.setup is not None:
            d.setup.cancel()
        d.setup = asyncio.get_running_loop().create_task(
            self._configure(d), name=f"devicenet-setup-{d.id}"
        )

    @handles(NodeDown)
    def _on_node_down(self, now: float, action: NodeDown) -> None:
        d = self.drives[action.mac]
        for task in (d.setup, d.status):
            if task is not None:
                task.cancel()
        d.setup = d.status = None
        d.configured = False
        self._disarm(d)
        d.input_key = d.output_key = None
        text = f"drive offline: {action.reason}"
        note = d.profile.reset_note
        offline_note = d.profile.offline_note()
        recent = d.reset_sent_at is not None and now - d.reset_sent_at < RESET_OFFLINE_WINDOW
        if note is not None and recent:
            text += f" after a fault reset ({note})"
            d.reset_sent_at = None
        elif offline_note is not None:
            text += f"; {offline_note}"
        hub = self._hub_port()
        hub.update(d.id, comm=CommState.OFFLINE, running=False, at_reference=False)
        hub.event(d.id, EventKind.COMM, text, mac=d.mac)

    @handles(InputData)
    def _on_input(self, now: float, action: InputData) -> None:
        d = self.drives[action.mac]
        if d.doubtful:
            self._count_clean(d)
        if not d.configured or not d.profile.ready:
            return
        hub = self._hub_port()
        desired = hub.desired(d.id)
        key = (action.data, desired, d.doubtful)
        if key != d.input_key:  # else the same reading for the same command: nothing new
            d.input_key = key
            try:
                changes = d.profile.inputs(action.data, desired)
            except DeviceNetDecodeError:
                d.bad_inputs += 1
                return
            changes["values"] = d.values  # the I/O words with the parameters read
            changes["doubtful"] = d.doubtful
            hub.update(d.id, comm=CommState.ONLINE, **changes)
            engine = self.engine  # what the readings change of the command (rule 1), now
            if engine is not None and engine.nodes[d.mac].phase is Phase.ONLINE:
                self._refresh_drive(engine, hub, d, now)
        self._quiet(d, now)

    # ------------------------------------------------------------ the steady case (0097)

    def _quiet(self, d: _Drive, now: float) -> None:
        """Tell the scanner whether the drive's unchanged inputs tell the adapter nothing:
        configured, readings not doubtful (every input counts then), no fault reset pulse
        running, its outputs computed from the command in force (docs/decisions/0097)."""
        engine = self.engine
        if engine is not None:
            quiet = (
                d.configured
                and not d.doubtful
                and now >= d.reset_until
                and d.output_key is not None
                and d.output_key != IDLE
            )
            engine.quiet_inputs(d.mac, quiet)

    def _want(self, d: _Drive) -> None:
        """Something besides the inputs changed for the drive: its next input is handled,
        and the next refresh looks at it."""
        engine = self.engine
        if engine is not None:
            engine.quiet_inputs(d.mac, False)
        self._next_refresh = 0.0

    def _on_command(self, drive_id: str) -> None:
        """The hub's desired command changed: the drive's outputs now (a stop goes with
        its next poll), and its next input handled."""
        d = self._by_id.get(drive_id)
        engine, hub = self.engine, self._hub
        if d is None or engine is None or hub is None:
            return
        self._want(d)
        if engine.nodes[d.mac].phase is Phase.ONLINE:
            self._refresh_drive(engine, hub, d, self.clock())

    def _count_clean(self, d: _Drive) -> None:
        d.clean_inputs += 1
        if d.clean_inputs >= DOUBT_CLEAN_INPUTS:
            d.doubtful = False
            self._hub_port().update(d.id, doubtful=False)

    @handles(IoConflict)
    def _on_conflict(self, now: float, action: IoConflict) -> None:
        """Two answers to one poll (issue 32 item 12): the drive's readings are doubtful
        until :data:`DOUBT_CLEAN_INPUTS` clean inputs in a row; one event when it starts,
        then at most one per :data:`CONFLICT_EVENT_INTERVAL` with the count since."""
        d = self.drives[action.mac]
        d.clean_inputs = 0
        d.conflicts_unsaid += 1
        self._want(d)
        hub = self._hub_port()
        if not d.doubtful:
            d.doubtful = True
            hub.update(d.id, doubtful=True)
        said = d.conflict_said_at
        if said is not None and now - said < CONFLICT_EVENT_INTERVAL:
            return
        hub.event(
            d.id,
            EventKind.BUS,
            f"node {d.mac}: {d.conflicts_unsaid} poll response(s) beyond one per poll "
            f"({action.count} in all; the last {action.data.hex(' ')}): another station "
            f"sends with MAC {d.mac}'s identifier; the drive's readings are doubtful",
            mac=d.mac,
            conflicts=action.count,
        )
        d.conflict_said_at, d.conflicts_unsaid = now, 0

    @handles(Report)
    def _on_report(self, now: float, action: Report) -> None:
        kind = REPORT_EVENTS[action.kind]
        hub = self._hub_port()
        targets = [self.drives[action.mac]] if action.mac in self.drives else self.drives.values()
        for d in targets:
            hub.event(d.id, kind, action.text, **action.data)

    # ------------------------------------------------------------ outputs

    def _refresh_outputs(self, now: float) -> None:
        """The outputs of the online drives not quiet, and every :data:`INPUTS_REFRESH` s
        of all of them (docs/decisions/0097); ``_loud``: whether any drive online is not
        quiet (the next refresh is then a poll interval away)."""
        engine, hub = self.engine, self._hub
        self._loud = True
        if engine is None or hub is None:
            return
        everyone = now >= self._next_full
        if everyone:
            self._next_full = now + INPUTS_REFRESH
        loud = False
        for d in self.drives.values():
            node = engine.nodes[d.mac]
            if node.phase is not Phase.ONLINE:
                continue
            if node.quiet and not everyone:
                continue
            loud = loud or not node.quiet
            self._refresh_drive(engine, hub, d, now)
        self._loud = loud

    def _refresh_drive(self, engine: Scanner, hub: HubPort, d: _Drive, now: float) -> None:
        """One online drive's outputs from the hub's desired command (rule 1: a run only
        once armed; the reset bit for its pulse)."""
        if not d.configured or not d.profile.ready:
            if d.output_key != IDLE:
                engine.set_output(d.mac, None)  # idle: the master is not driving it
                d.output_key = IDLE
            return
        desired = hub.desired(d.id)
        if desired.fault_reset_seq != d.reset_seen:
            d.reset_seen = desired.fault_reset_seq
            d.reset_until = now + self._reset_pulse()
            d.reset_sent_at = now
            note = d.profile.reset_note
            hub.event(
                d.id,
                EventKind.FAULT,
                "fault reset sent" if note is None else f"fault reset sent ({note})",
            )
        if d.output_key is not None:  # the first output after (re)configuration: a stop
            d.armed = d.armed or desired is not d.held or not (desired.run or desired.jog)
        command = desired if d.armed else motion_free(desired)
        key = (command, now < d.reset_until)
        if key != d.output_key:
            d.output_key = key
            engine.set_output(d.mac, d.profile.outputs(command, key[1]))
            engine.quiet_inputs(d.mac, False)  # the readings of the new command: next input

    def _disarm(self, d: _Drive) -> None:
        """No run or jog reaches the drive until a command given from now on (rule 1)."""
        d.armed = False
        d.held = self._hub_port().desired(d.id)

    def _reset_pulse(self) -> float:
        """Long enough for at least one production with the bit set (edge, seed 3.1.2)."""
        return max(2 * self.options.poll_interval, 1.5 * self.options.expected_packet_rate)

    # ------------------------------------------------------------ configure at connect

    async def _configure(self, d: _Drive) -> None:
        pause = min(1.0, self.options.retry_max)
        while True:
            try:
                await self._try_configure(d)
                return
            except NotConfigured as exc:
                problem = str(exc)
                if problem != d.problem:  # the drive's own setup is wrong: a warning
                    log.warning("DeviceNet %s: drive %s not configured: %s", self.name, d.id, exc)
            except (GatewayTimeout, DriveOffline) as exc:
                problem = f"no answer while configuring: {exc}"
            if problem != d.problem:
                self._hub_port().event(
                    d.id,
                    EventKind.CONFIG,
                    f"not configured: {problem}; the drive gets no commands (idle I/O)",
                )
            d.problem = problem
            await asyncio.sleep(pause)
            pause = min(2 * pause, self.options.retry_max)

    async def _try_configure(self, d: _Drive) -> None:
        await d.profile.on_connect(_Port(self, d))
        hub = self._hub_port()
        d.reset_seen = hub.desired(d.id).fault_reset_seq
        d.configured, d.problem = True, None
        self._disarm(d)  # the first output after (re)configuration is a stop, built fresh
        d.input_key = d.output_key = None
        self._want(d)  # its first outputs at the next pass, its next input handled
        hub.event(d.id, EventKind.CONFIG, d.profile.configured_text())
        d.status = asyncio.get_running_loop().create_task(
            self._watch_status(d), name=f"devicenet-status-{d.id}"
        )

    async def _watch_status(self, d: _Drive) -> None:
        port = _Port(self, d)
        while True:
            await asyncio.sleep(self.options.status_interval)
            with contextlib.suppress(GatewayTimeout, DriveOffline, ParameterError):
                await d.profile.poll_status(port)
            d.input_key = None  # the readings of the parameters read: mapped again
            self._want(d)

    # ------------------------------------------------------------ parameters

    async def _request(self, d: _Drive, body: Request) -> Response:
        result = await self.exchange(
            d, lambda engine: engine.submit(d.mac, body), self._answer_bound(), "answer"
        )
        if result.response is not None:
            return result.response
        if result.timed_out:
            raise GatewayTimeout(f"drive {d.id}: {result.error}")
        raise DriveOffline(f"drive {d.id}: {result.error}")

    def _answer_bound(self) -> float:
        """How long an explicit request may take before the adapter gives up on it: its
        own retries (the scanner ends every request it started within them) and its turn
        behind the requests already on the line, ``explicit_window`` at a time (63 drives
        configuring at once wait that long on a busy host)."""
        engine = self.engine
        ahead = 0 if engine is None else engine.explicit_turns_ahead()
        return (4 + ahead) * self.options.explicit_timeout + 1.0

    async def explicit(self, drive_id: str, body: Request) -> Response:
        """Any explicit request to a drive (tools, tests); the reply as it came."""
        return await self._request(self._drive(drive_id), body)

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        d = self._drive(drive_id)
        return await d.profile.read_param(_Port(self, d), number, subindex)

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        d = self._drive(drive_id)
        await d.profile.write_param(_Port(self, d), number, subindex, value)

    def publish_capabilities(self, d: _Drive) -> None:
        """The profile's capabilities, once it has them, with the parameter table of the
        drive's EDS (the lookup the front ends name parameter values with,
        gateway.adapter.ParamInfo); without an EDS, the profile's own table."""
        caps = d.profile.capabilities()
        if caps is not None:
            if d.opts.params:  # without an EDS: the profile's own table
                caps = replace(caps, params=eds_param_table(d.opts.params))
            self._hub_port().set_capabilities(d.id, caps)

    def param_info(self, drive_id: str, number: int, raw: ParamValue) -> dict[str, Any]:
        """What the drive's EDS says of parameter P<number>: its ``name``, ``unit`` and the
        ``scaled`` engineering value of ``raw`` (EDS scaling); {} when the drive has no EDS
        or the EDS does not name that parameter. The params services add these beside
        the raw value."""
        param = self._drive(drive_id).opts.params.get(number)
        if param is None:
            return {}
        return {"name": param.name, "unit": param.units, "scaled": param.scale(int(raw))}

    # ------------------------------------------------------------ standard objects

    async def read_object(
        self, drive_id: str, class_id: int, instance_id: int, attribute_id: int
    ) -> AttributeValue:
        """Get_Attribute_Single on a standard object the drive's profile lists."""
        d = self._drive(drive_id)
        return await d.profile.read_object(_Port(self, d), class_id, instance_id, attribute_id)

    async def write_object(
        self,
        drive_id: str,
        class_id: int,
        instance_id: int,
        attribute_id: int,
        value: AttributeValue,
    ) -> None:
        """Set_Attribute_Single on a standard object the drive's profile lists; the
        profile refuses the attributes that command the drive (rule 1)."""
        d = self._drive(drive_id)
        port = _Port(self, d)
        await d.profile.write_object(port, class_id, instance_id, attribute_id, value)

    # ------------------------------------------------------------ diagnostics

    def line_diagnostics(self, engine: Scanner | None) -> dict[str, Any]:
        return {"mac": self.options.mac} if engine is None else engine.line_diagnostics()

    def drive_diagnostics(self, d: _Drive) -> dict[str, Any]:
        return {
            "mac": d.mac,
            "connection": d.opts.connection.value,
            "configured": d.configured,
            "problem": d.problem,
            "bad_inputs": d.bad_inputs,
            **d.profile.diagnostics(),
        }


# ---------------------------------------------------------------- helpers


def motion_free(desired: DesiredCommand) -> DesiredCommand:
    """``desired`` without run, jog or speed: a ramp stop (a quick or coast stop kept)."""
    return replace(desired, run=False, jog=False, speed_rpm=None, speed_pct=None)
