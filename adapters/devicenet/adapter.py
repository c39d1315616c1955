"""The DeviceNet adapter: python-can link + scanner engine + device profiles, as a DriveAdapter.

Each drive has the :class:`~adapters.devicenet.profile.DnProfile` its device registers
(``adapters.devicenet.profile.PROFILES``); the adapter names no device. Per drive, once
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
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar

from adapters.devicenet.datatypes import AttributeValue
from adapters.devicenet.eds import Param
from adapters.devicenet.errors import DeviceNetDecodeError
from adapters.devicenet.explicit import Request, Response
from adapters.devicenet.frame import CanFrame
from adapters.devicenet.link import (
    DeviceNetBus,
    Link,
    LinkConfig,
    LinkEvent,
    RxFrame,
)
from adapters.devicenet.objects import INACTIVITY_EPR_FACTOR
from adapters.devicenet.options import ADR_MAC, BusOptions, DriveOptions, parse_bus
from adapters.devicenet.profile import (
    RESET_OFFLINE_WINDOW,
    DnProfile,
    NotConfigured,
    load_profile,
)
from adapters.devicenet.scanner import (
    Action,
    BadFrame,
    BusErrorIn,
    Event,
    ExplicitResult,
    FrameIn,
    IdentityCheck,
    InputData,
    IoConflict,
    LineFault,
    LineOnline,
    LinkDown,
    NodeConfig,
    NodeDown,
    NodeUnavailable,
    NodeUp,
    Phase,
    Report,
    ReportKind,
    Scanner,
    ScannerConfig,
    Send,
    TxFailed,
)
from adapters.devicenet.scanner.probe import (
    Finished,
    LineProbe,
    NodeInfo,
    ProbeAction,
    ProbeConfig,
    Progress,
)
from adapters.link.can import CanLinks
from adapters.link.candriver import CanDriver
from adapters.link.canline import CanLine, LinkEvents, leave_line
from adapters.link.config import missing_options, unsimulated
from gateway.adapter import (
    EventKind,
    HubPort,
    ParamInfo,
    ParamTable,
    ParamValue,
    param_table,
)
from gateway.config import BusConfig, DriveConfig
from gateway.devices import devices_of
from gateway.errors import (
    AdapterError,
    DriveOffline,
    GatewayTimeout,
    LineHeld,
    ParameterError,
)
from gateway.model import CommState, DesiredCommand, Device
from gateway.schema import Table

log = logging.getLogger(__name__)

LEAVE_BOUND = 1.0  # s: the shortest bound on the wait for Release answers on shutdown
LEAVE_WAIT = 0.02  # s: the longest wait between two steps while leaving
SCANNER_SERIAL_BASE = 0x44470000  # our Duplicate MAC ID check serial ("DG" + MAC)
ADR_INTERVAL = 1.0  # s between two looks at MAC 63 while an adr drive is missing
IDLE = "idle"
# Doubtful readings (issue 32 item 12): a drive whose poll responses conflicted is doubtful
# until this many of its inputs in a row came without a conflict (at least this many poll
# cycles: a forger answering each poll keeps it doubtful); a reconnect does not clear it.
DOUBT_CLEAN_INPUTS = 50
CONFLICT_EVENT_INTERVAL = 10.0  # s: at most one conflict event per drive this often

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
class _Drive:
    cfg: DriveConfig
    opts: DriveOptions
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
    def id(self) -> str:
        return self.cfg.id

    @property
    def mac(self) -> int:
        return self.cfg.address

    @property
    def values(self) -> dict[str, float | int]:
        return self.profile.values


@dataclass(frozen=True, slots=True)
class _Port:
    """One drive as its profile sees it (adapters.devicenet.profile.DrivePort)."""

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
        self.adapter._publish_capabilities(self.drive)

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


class DeviceNetAdapter:
    """One DeviceNet line scanned by the gateway, with the drives of :data:`PROFILES`."""

    devices: ClassVar[frozenset[Device]] = devices_of("devicenet")  # the registry's
    address_range: ClassVar[tuple[int, int]] = (0, 63)

    @classmethod
    def parse_bus_options(cls, table: Table) -> BusOptions:
        return parse_bus(table)

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> DriveOptions:
        """The drive's keys, as the profile of its device reads them."""
        return load_profile(drive.device).parse_options(table, drive)

    def __init__(
        self,
        bus: BusConfig,
        *,
        links: CanLinks[CanFrame] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``links``: the line, as the composition root chose it (a simulated line for
        ``simulate = true``); None: the configured interface and channel."""
        self.bus = bus
        self.name = bus.name
        if not isinstance(bus.options, BusOptions):
            raise missing_options(bus.name)
        self.options: BusOptions = bus.options
        o = self.options
        self.links: CanLinks[CanFrame] | None = links
        """None for ``simulate = true`` without a simulated line: refused when it runs."""
        if links is None and not o.simulate:
            self.links = DeviceNetBus(LinkConfig(o.interface, o.channel, o.bitrate))
        self.clock = clock
        self.drives: dict[int, _Drive] = {}
        self._by_id: dict[str, _Drive] = {}
        for d in bus.drives:
            if d.address == self.options.mac:
                raise AdapterError(
                    f"drive {d.id} has the scanner's MAC ID {d.address} (bus key 'mac')"
                )
            opts: DriveOptions = d.options
            drive = _Drive(d, opts, load_profile(d.device)(d.id, opts))
            self.drives[d.address] = drive
            self._by_id[d.id] = drive
        self.engine: Scanner | None = None
        self.link: Link | None = None
        self._driver: CanDriver[CanFrame, Event, Action] | None = None
        self._next_refresh = 0.0
        self._refreshed_cycle = -1  # the poll cycles counted at the last refresh
        self._hub: HubPort | None = None
        self._pending: dict[int, asyncio.Future[ExplicitResult]] = {}
        self._adr: LineProbe | None = None
        self._adr_next = 0.0
        self._missing_since: dict[int, float] = {}
        self.claimed = asyncio.Event()
        """Set once the scanner passed its Duplicate MAC ID check (the daemon's READY)."""
        self._handlers: dict[type, Callable[[float, Any], None]] = {
            LineOnline: self._on_line_online,
            LineFault: self._on_line_fault,
            NodeUp: self._on_node_up,
            NodeDown: self._on_node_down,
            InputData: self._on_input,
            IoConflict: self._on_conflict,
            ExplicitResult: self._on_result,
            Report: self._on_report,
        }

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
        links = self.links
        if links is None:
            raise unsimulated(self.name)
        self._hub = hub
        for d in self.drives.values():
            hub.update(d.id, comm=CommState.OFFLINE)
            self._publish_capabilities(d)
        link = links.link()
        engine = Scanner(self.scanner_config(), self.node_configs())
        self._next_refresh = 0.0
        self._refreshed_cycle = -1
        async with link:
            self.link, self.engine = link, engine
            driver = self._driver = CanDriver(engine, link, _Line(self), self.clock)
            try:
                await links.start()
                await driver.run()
            finally:
                try:
                    await self._leave(link, engine, driver)
                    await self._stop_tasks()
                finally:
                    await links.stop()  # a simulated line's devices, after the Release
                for d in self.drives.values():
                    hub.update(d.id, comm=CommState.OFFLINE, running=False, at_reference=False)
                self.link = self.engine = self._driver = None

    async def _stop_tasks(self) -> None:
        tasks = [t for d in self.drives.values() for t in (d.setup, d.status) if t is not None]
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for fut in self._pending.values():
            fut.cancel()
        self._pending.clear()

    def _before_step(self, now: float) -> None:
        """Desired commands reach the outputs once per poll: every ``poll_interval``, and
        no more than once per poll cycle (a cycle longer than the interval polls each node
        once; refreshing the outputs meanwhile would cost a pass over every drive, every
        interval, for nothing)."""
        if now >= self._next_refresh and self._refresh_due():
            self._refresh_outputs(now)
            self._next_refresh = now + self.options.poll_interval
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

    def _wake_at(self) -> float | None:
        adr = self._adr.next_deadline() if self._adr is not None else None
        # mid-cycle the refresh waits for the cycle's end: an event (its last poll reply,
        # or the scanner's own poll timeout), which steps the driver anyway
        refresh = self._next_refresh if self._refresh_due() else None
        times = [t for t in (refresh, adr) if t is not None]
        return min(times) if times else None

    def _received(self, now: float, event: LinkEvent) -> None:
        if self._adr is not None and isinstance(event, RxFrame):
            self._adr_actions(now, self._adr.step(now, event.frame))

    async def _leave(
        self, link: Link, engine: Scanner, driver: CanDriver[CanFrame, Event, Action]
    ) -> None:
        """Release every node (fact sheet 2.10 step 8), bounded."""
        if not link.is_open or not engine.online:
            return
        # the Releases go out request_spacing apart, each answered within explicit_timeout
        spread = len(engine.nodes) * engine.config.request_spacing
        bound = max(LEAVE_BOUND, spread + self.options.explicit_timeout)
        await leave_line(
            driver, engine.leave, lambda: engine.left, bound=bound, longest_wait=LEAVE_WAIT
        )

    # ------------------------------------------------------------ actions

    def _handle(self, now: float, action: Action) -> None:
        self._handlers[type(action)](now, action)

    def _hub_port(self) -> HubPort:
        if self._hub is None:
            raise AdapterError("the adapter is not running")
        return self._hub

    def _on_line_online(self, now: float, action: LineOnline) -> None:
        log.info("DeviceNet %s: scanner MAC %d online", self.name, self.options.mac)
        self.claimed.set()
        for d in self.drives.values():
            self._hub_port().update(d.id, comm=CommState.CONNECTING)

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

    def _on_node_up(self, now: float, action: NodeUp) -> None:
        d = self.drives[action.mac]
        self._disarm(d)
        self._hub_port().update(d.id, comm=CommState.CONNECTING)
        if d.setup is not None:
            d.setup.cancel()
        d.setup = asyncio.get_running_loop().create_task(
            self._configure(d), name=f"devicenet-setup-{d.id}"
        )

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

    def _on_input(self, now: float, action: InputData) -> None:
        d = self.drives[action.mac]
        if d.doubtful:
            self._count_clean(d)
        if not d.configured or not d.profile.ready:
            return
        hub = self._hub_port()
        desired = hub.desired(d.id)
        key = (action.data, desired, d.doubtful)
        if key == d.input_key:
            return  # the same reading for the same command: nothing new to publish
        d.input_key = key
        try:
            changes = d.profile.inputs(action.data, desired)
        except DeviceNetDecodeError:
            d.bad_inputs += 1
            return
        changes["values"] = d.values  # the I/O words with the parameters read
        changes["doubtful"] = d.doubtful
        hub.update(d.id, comm=CommState.ONLINE, **changes)

    def _count_clean(self, d: _Drive) -> None:
        d.clean_inputs += 1
        if d.clean_inputs >= DOUBT_CLEAN_INPUTS:
            d.doubtful = False
            self._hub_port().update(d.id, doubtful=False)

    def _on_conflict(self, now: float, action: IoConflict) -> None:
        """Two answers to one poll (issue 32 item 12): the drive's readings are doubtful
        until :data:`DOUBT_CLEAN_INPUTS` clean inputs in a row; one event when it starts,
        then at most one per :data:`CONFLICT_EVENT_INTERVAL` with the count since."""
        d = self.drives[action.mac]
        d.clean_inputs = 0
        d.conflicts_unsaid += 1
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

    def _on_result(self, now: float, action: ExplicitResult) -> None:
        fut = self._pending.pop(action.token, None)
        if fut is not None and not fut.done():
            fut.set_result(action)

    def _on_report(self, now: float, action: Report) -> None:
        kind = REPORT_EVENTS[action.kind]
        hub = self._hub_port()
        targets = [self.drives[action.mac]] if action.mac in self.drives else self.drives.values()
        for d in targets:
            hub.event(d.id, kind, action.text, **action.data)

    # ------------------------------------------------------------ Automatic Device Replacement

    def _adr_drives(self, engine: Scanner) -> list[_Drive]:
        """Drives with ``adr = true`` (none while a configured drive holds MAC 63)."""
        if ADR_MAC in self.drives or not engine.online:
            return []
        return [d for d in self.drives.values() if d.opts.adr]

    def _tick_adr(self, now: float, engine: Scanner) -> None:
        """Seed 6.1: while an ``adr`` drive is missing, look at MAC 63 for a drive with its
        identity (every ``ADR_INTERVAL``); one found is re-addressed and reset, then comes
        up at the missing drive's MAC ID and is reprogrammed at connect (startup_params)."""
        drives = self._adr_drives(engine)
        for d in drives:
            if engine.nodes[d.mac].phase is Phase.ONLINE:
                self._missing_since.pop(d.mac, None)
            else:
                self._missing_since.setdefault(d.mac, now)
        if self._adr is None:
            if not self._missing(now) or now < self._adr_next:
                return
            o = self.options
            config = ProbeConfig(
                mac=o.mac, macs=(ADR_MAC,), timeout=o.explicit_timeout, claim=False, window=1
            )
            self._adr = LineProbe(config, self._adr_target)
        self._adr_actions(now, self._adr.step(now))

    def _missing(self, now: float) -> list[_Drive]:
        """``adr`` drives missing long enough to be replaced (not merely slow to start)."""
        after = 2 * (self.options.explicit_timeout + self.options.dupmac_timeout)
        return [
            self.drives[mac] for mac, since in self._missing_since.items() if now - since >= after
        ]

    def _adr_target(self, info: NodeInfo) -> int | None:
        now = self.clock()
        matches = [d for d in self._missing(now) if _same_identity(d.opts, info)]
        if len(matches) == 1:
            return matches[0].mac
        if len(matches) > 1:
            names = ", ".join(d.id for d in matches)
            text = (
                f"ADR: the drive at MAC {ADR_MAC} (serial {info.serial_number}) matches "
                f"several missing drives ({names}): not re-addressed"
            )
            for d in matches:
                self._hub_port().event(d.id, EventKind.CONFIG, text)
        return None

    def _adr_actions(self, now: float, actions: list[ProbeAction]) -> None:
        for action in actions:
            if isinstance(action, CanFrame):
                if self._driver is not None:
                    self._driver.queue(action)
            elif isinstance(action, Finished):
                self._adr = None
                self._adr_next = now + ADR_INTERVAL
            elif isinstance(action, Progress) and action.found is not None:
                self._adr_found(action.found)

    def _adr_found(self, info: NodeInfo) -> None:
        target = info.readdressed
        d = self.drives.get(target) if target is not None else None
        if d is None:
            if info.problem is not None:
                log.info("DeviceNet %s: ADR at MAC %d: %s", self.name, ADR_MAC, info.problem)
            return
        self._missing_since.pop(d.mac, None)
        self._hub_port().event(
            d.id,
            EventKind.CONFIG,
            f"ADR: a drive with the identity of {d.id} (serial {info.serial_number}) appeared "
            f"at MAC {ADR_MAC}: set to MAC {d.mac} and reset (seed 6.1); it is reprogrammed "
            "when it connects (startup_params)",
            serial_number=info.serial_number,
        )

    # ------------------------------------------------------------ outputs

    def _refresh_outputs(self, now: float) -> None:
        engine, hub = self.engine, self._hub
        if engine is None or hub is None:
            return
        for d in self.drives.values():
            if engine.nodes[d.mac].phase is not Phase.ONLINE:
                continue
            if not d.configured or not d.profile.ready:
                if d.output_key != IDLE:
                    engine.set_output(d.mac, None)  # idle: the master is not driving it
                    d.output_key = IDLE
                continue
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

    # ------------------------------------------------------------ parameters

    def _drive(self, drive_id: str) -> _Drive:
        d = self._by_id.get(drive_id)
        if d is None:
            raise DriveOffline(f"drive {drive_id} is not on bus {self.name}")
        return d

    async def _request(self, d: _Drive, body: Request) -> Response:
        engine, link = self.engine, self.link
        if engine is None or link is None:
            raise DriveOffline(f"drive {d.id}: bus {self.name} is not running")
        try:
            token = engine.submit(d.mac, body)
        except NodeUnavailable as exc:
            raise DriveOffline(f"drive {d.id} is not online ({exc})") from None
        fut: asyncio.Future[ExplicitResult] = asyncio.get_running_loop().create_future()
        self._pending[token] = fut
        link.wake()
        bound = 4 * self.options.explicit_timeout + 1.0
        try:
            async with asyncio.timeout(bound):  # not wait_for: it can swallow a cancellation
                result = await fut
        except TimeoutError:
            raise GatewayTimeout(f"drive {d.id}: no answer within {bound:g} s") from None
        finally:
            self._pending.pop(token, None)
        if result.response is not None:
            return result.response
        if result.timed_out:
            raise GatewayTimeout(f"drive {d.id}: {result.error}")
        raise DriveOffline(f"drive {d.id}: {result.error}")

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

    def _publish_capabilities(self, d: _Drive) -> None:
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

    def diagnostics(self) -> dict[str, Any]:
        o = self.options
        line: dict[str, Any] = {
            "interface": o.interface,
            "channel": o.channel,
            "bitrate_expected": o.bitrate,
            "mac": o.mac,
            "simulated": o.simulate,
            "running": self.engine is not None,
        }
        engine, link = self.engine, self.link
        if engine is not None:
            line.update(engine.line_diagnostics())
        if link is not None:
            line.update(link.diagnostics())
        drives: dict[str, Any] = {}
        for d in self.drives.values():
            entry: dict[str, Any] = {
                "mac": d.mac,
                "connection": d.opts.connection.value,
                "configured": d.configured,
                "problem": d.problem,
                "bad_inputs": d.bad_inputs,
                **d.profile.diagnostics(),
            }
            if engine is not None:
                entry.update(engine.node_diagnostics(d.mac))
            drives[d.id] = entry
        line["drives"] = drives
        return line


# ---------------------------------------------------------------- helpers


def motion_free(desired: DesiredCommand) -> DesiredCommand:
    """``desired`` without run, jog or speed: a ramp stop (a quick or coast stop kept)."""
    return replace(desired, run=False, jog=False, speed_rpm=None, speed_pct=None)


def _same_identity(opts: DriveOptions, info: NodeInfo) -> bool:
    """The node at MAC 63 shows what this drive's config (or EDS) expects of it."""
    revision_ok = opts.revision is None or (
        info.revision is not None
        and info.revision[0] == opts.revision[0]
        and info.revision[1] >= opts.revision[1]
    )
    return (
        info.vendor_id == opts.vendor_id
        and (opts.product_code is None or info.product_code == opts.product_code)
        and (not opts.product_name or info.product_name == opts.product_name)
        and (opts.product_type is None or info.product_type == opts.product_type)
        and revision_ok
    )


LINK_EVENTS: LinkEvents[CanFrame, Event] = LinkEvents(
    FrameIn, BusErrorIn, BadFrame, LinkDown, TxFailed
)
"""The scanner's events for what the CAN link reports (:mod:`adapters.link.canline`)."""


class _Line(CanLine[CanFrame, Event, Action]):
    """The scanner's line as the CAN driver loop sees it (:mod:`adapters.link.candriver`):
    the link's events as the scanner's (:class:`~adapters.link.canline.CanLine`), its
    frames and reports, the poll-time output refresh and the ADR probe."""

    def __init__(self, adapter: DeviceNetAdapter) -> None:
        super().__init__(LINK_EVENTS)
        self.adapter = adapter

    def frame(self, action: Action) -> CanFrame | None:
        return action.frame if isinstance(action, Send) else None

    def handle(self, now: float, action: Action) -> None:
        self.adapter._handle(now, action)

    def before_step(self, now: float) -> None:
        self.adapter._before_step(now)

    def after_step(self, now: float) -> None:
        engine = self.adapter.engine
        if engine is not None:
            self.adapter._tick_adr(now, engine)

    def wake_at(self) -> float | None:
        return self.adapter._wake_at()

    def received(self, now: float, event: LinkEvent) -> None:
        self.adapter._received(now, event)

    def hold_until(self, now: float) -> float | None:
        engine = self.adapter.engine
        return engine.hold_until(now) if engine is not None else None
