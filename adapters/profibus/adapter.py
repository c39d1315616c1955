"""The Profibus DP line as a :class:`gateway.adapter.DriveAdapter` ("profibus").

One master engine (:mod:`.master`) on one serial link (:mod:`.link`, :mod:`.driver`), one
device profile per drive (:data:`adapters.profibus.contract.PROFILES`). Per drive:

* start-up states -> comm "connecting"; absent -> "offline" (one event);
* data exchange reached -> outputs at a safe value (the profile's ``unconfigured_outputs``
  where it has that hook: the WEG drives' stop in both data profiles; else its outputs for
  a stopped command), then ``profile.on_connect`` (scales, start-up parameters) through a
  DP-V1 :class:`RecordChannel` (:mod:`.channel`); a failure leaves the drive "not
  configured" (comm connecting, an event, retried with back-off, the same safe outputs),
  success sets the capabilities and makes it configured. An ``on_connect`` failure whose
  exception has ``reparameterise = True`` (a parameter the slave takes only without cyclic
  data was written) takes the slave out of data exchange and parameterises it again;
* a profile with ``failsafe_needs_watchdog = True`` (the drive's reaction to a lost master
  relies on the DP watchdog) is published ``failsafe`` false while its watchdog is 0 (off);
  ``safety_warnings`` (``check-config``) asks the profile's hook of the same name;
* configured: every cycle inputs -> ``profile.inputs`` -> ``hub.update(comm=online, ...)``
  and ``profile.outputs(hub.desired(id))`` -> the next Data_Exchange;
* extended diagnosis (changed) -> ``profile.on_ext_diag`` -> hub events (every read, empty
  ones included, for a profile with ``sees_every_diag = True``: it keeps its own memory);
* a profile whose ``wants_codes`` is true (the WEG drives: fault and alarm codes not mapped
  in the telegram) gets them read over DP-V1 by its ``read_codes(channel)``;
* leaving data exchange -> ``profile.on_comm_lost()`` and comm "offline".

The port disappearing never crashes the gateway: drives go offline and the port is
reopened with back-off. One master per line: a port another process holds when the
adapter first opens it ends the run with :class:`PortHeld` (the daemon does not start);
held when it comes back after a loss, it is retried like a missing one, the holder named.
On cancellation the master sends Global_Control Clear to every slave and closes the port.
The port is opened through the link factory the composition root gives the adapter
(:class:`adapters.link.serial.SerialLinks`): the configured port, or for ``simulate =
true`` a simulated line (:mod:`adapters.profibus.sim.simulated`: the drives' simulated
devices on the other end of a pty pair, in-process). This module imports no simulator.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, ClassVar, Final

from adapters.link.config import missing_options, unsimulated
from adapters.profibus import options as opts
from adapters.profibus.channel import Channel, RecordJobs
from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.contract import (
    BUS,
    PROFILES,
    SET_SLAVE_ADD_DEFAULT,
    DiagKind,
    DpProfile,
    EventSink,
    ProfileFactory,
    SlaveSetup,
)
from adapters.profibus.driver import LineDriver
from adapters.profibus.link import OPEN_ERRORS, PortHeld, SerialLink, SerialLinks, profibus_port
from adapters.profibus.master import (
    DiagnosisRead,
    FaultKind,
    InputsReceived,
    LineMode,
    LineNoise,
    Master,
    RecordDone,
    SlaveDown,
    SlaveFault,
    SlaveParams,
    SlaveState,
    SlaveStateChanged,
    SlaveUp,
)
from gateway.adapter import EventKind, HubPort, ParamValue
from gateway.config import BusConfig, DriveConfig
from gateway.devices import devices_of
from gateway.errors import DriveOffline, GatewayError, UnknownDrive
from gateway.loader import load
from gateway.model import CommState, DesiredCommand, Device, Source, StopAction
from gateway.schema import Table

log = logging.getLogger(__name__)

REOPEN_BACKOFF: Final = (0.5, 10.0)  # s, first and longest pause before reopening the port
CONNECT_BACKOFF: Final = (2.0, 60.0)  # s, between on_connect attempts of a drive
CONTROL_CHECK: Final = 0.1  # s between checks of lost northbound control
CODES_RETRY: Final = 1.0  # s before reading a profile's fault codes again after a failure
LEAVE_MARGIN: Final = 0.01  # s after the last Clear before the port is closed
MAX_REPARAMETERISE: Final = 2  # restarts asked by on_connect in a row before it is a failure
WATCHDOG_OFF: Final = "watchdog = 0: the DP watchdog is off, the drive never sees the master go"

CONNECTING_STATES: Final = frozenset(
    {
        SlaveState.SET_PRM,
        SlaveState.CHK_CFG,
        SlaveState.WAIT_READY,
        SlaveState.GET_CFG,
        SlaveState.FAULT,
    }
)

FAULT_EVENTS: Final[Mapping[FaultKind, EventKind]] = {
    FaultKind.DPV1_UNANSWERED: EventKind.BUS,  # the line's trouble; data exchange goes on
}

DIAG_KINDS: Final[Mapping[DiagKind, EventKind]] = {
    DiagKind.FAULT: EventKind.FAULT,
    DiagKind.TRIP: EventKind.TRIP,
    DiagKind.ALARM: EventKind.ALARM,
    DiagKind.PARAMETER: EventKind.PARAMETER,
    DiagKind.INFO: EventKind.BUS,
    DiagKind.CONFIG: EventKind.CONFIG,
    DiagKind.SAFETY: EventKind.SAFETY,
}


class PortState(Enum):
    """The serial port, as the diagnostics show it (``port_state``)."""

    CLOSED = "closed"
    OPEN = "open"
    REOPENING = "reopening"


@dataclass
class _Drive:
    config: DriveConfig  # with the profile's options
    profile: DpProfile
    setup: SlaveSetup
    up: bool = False  # in data exchange
    configured: bool = False  # on_connect succeeded
    connect_task: asyncio.Task[None] | None = None
    codes_task: asyncio.Task[None] | None = None
    codes_retry_at: float = 0.0
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    last_ext: bytes = b""
    absent_reported: bool = False
    connect_error: str | None = None
    watchdog: float = 0.0  # the slave's DP watchdog, s (0: off)
    reparameterised: int = 0  # restarts on_connect asked for since the last success

    @property
    def id(self) -> str:
        return self.config.id

    @property
    def address(self) -> int:
        return self.config.address


class ProfibusAdapter:
    """A Profibus DP class-1 master line (see the module docstring)."""

    devices: ClassVar[frozenset[Device]] = devices_of(BUS)  # the registry's (gateway.devices)
    # 0-126 in the core's check: a device's own range (its profile's ``addresses``, from its
    # manual) and the DP stations 0-125 are checked in parse_drive_options, naming the drive
    address_range: ClassVar[tuple[int, int]] = (0, SET_SLAVE_ADD_DEFAULT)
    profiles: ClassVar[Mapping[Device, str]] = PROFILES

    # ------------------------------------------------------------------ config

    @classmethod
    def parse_bus_options(cls, table: Table) -> opts.BusOptions:
        return opts.parse_bus_options(table)

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> opts.DriveOptions:
        profile_class = cls.profile_class(drive.device)
        refusal = profile_class.addresses.refusal(drive.device.value, drive.address)
        if refusal is not None:
            raise table.error("address", refusal)
        profile_options = profile_class.parse_options(table, drive)
        builtin = None  # the profile's own setup: only to check a GSD module or cfg against
        if table.has("gsd") or table.has("cfg"):
            builtin = profile_class(replace(drive, options=profile_options)).setup()
        telegram = profile_class.telegram_text(profile_options)
        return opts.parse_drive_options(table, drive, profile_options, builtin, telegram)

    @classmethod
    def check_bus(
        cls, table: Table, options: opts.BusOptions, drives: list[opts.DriveOptions]
    ) -> None:
        """``clear_on_lost_control`` only on a line whose every drive takes a Clear as a
        stop: Clear is for the whole line (no per-slave Clear without groups), and a drive
        that takes no outputs in Clear would get no client's stop while it lasts
        (decision 0091)."""
        if not options.clear_on_lost_control:
            return
        for d in drives:
            if not isinstance(d, opts.DriveOptions) or d.device is None:
                continue
            why = cls.profile_class(d.device).outputs_in_clear
            if why:
                raise table.error(
                    "clear_on_lost_control",
                    f"drive {d.drive_id} ({d.device.value}): {why}; the command watchdog "
                    "already stops the drive whose client is lost",
                )

    @classmethod
    def safety_warnings(cls, bus: BusConfig, drive: DriveConfig) -> list[str]:
        """``check-config``: what the drive's profile says of its safety settings from the
        config alone (its ``safety_warnings(drive, watchdog)`` hook, given the profile's
        options and the slave's DP watchdog; the WEG drives: watchdog 0 and P0313)."""
        hook = cls.profile_class(drive.device).safety_warnings
        bus_options = bus.options if isinstance(bus.options, opts.BusOptions) else None
        drive_options = drive.options if isinstance(drive.options, opts.DriveOptions) else None
        watchdog = _watchdog_of(bus_options or opts.BusOptions(), drive_options)
        inner, _ = opts.profile_config(drive)
        return [f"drive {drive.id}: {text}" for text in hook(inner, watchdog)]

    @classmethod
    def profile_class(cls, device: Device) -> ProfileFactory:
        try:
            target = cls.profiles[device]
        except KeyError:
            raise GatewayError(f"no Profibus profile for {device.value}") from None
        factory: ProfileFactory = load(target)
        return factory

    # ------------------------------------------------------------------ construction

    def __init__(self, bus: BusConfig, *, links: SerialLinks | None = None) -> None:
        """``links``: the line, as the composition root chose it (a simulated line for
        ``simulate = true``); None: the configured port."""
        self.bus = bus
        self.name = bus.name
        if not isinstance(bus.options, opts.BusOptions):
            raise missing_options(bus.name)
        self.options: opts.BusOptions = bus.options
        self.links: SerialLinks | None = links if links is not None else self._real_port()
        self._drives: dict[str, _Drive] = {}
        self._by_address: dict[int, _Drive] = {}
        slaves: list[SlaveParams] = []
        self._overrides: dict[str, opts.SetupOverride] = {}
        for d in bus.drives:
            drive_opts = d.options if isinstance(d.options, opts.DriveOptions) else None
            inner, override = opts.profile_config(d)
            if override is not None:
                self._overrides[d.id] = override
            profile: DpProfile = self.profile_class(d.device)(inner)
            setup = _overridden(profile.setup(), override)
            watchdog = _watchdog_of(self.options, drive_opts)
            drive = _Drive(config=inner, profile=profile, setup=setup, watchdog=watchdog)
            self._drives[d.id] = drive
            self._by_address[d.address] = drive
            slaves.append(_slave_params(d.address, setup, watchdog))
        self.master = Master(self.options.bus_params(), slaves)
        self._hub: HubPort | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._link: SerialLink | None = None
        self._driver: LineDriver | None = None
        self._jobs = RecordJobs(self.master, lambda: self._driver)
        self._port = self.options.port  # a simulated line's: once it started
        self._port_state = PortState.CLOSED
        self._port_error: str | None = None
        self._reopens = 0
        self._link_opens = 0  # PortHeld before the first: refuse to start (one master per line)
        self.claimed = asyncio.Event()
        """Set once the port's first open was not refused as held (the daemon's READY)."""
        self._control_timer: asyncio.TimerHandle | None = None

    def _real_port(self) -> SerialLinks | None:
        """The configured port; None for ``simulate = true`` (no simulated line given:
        refused when the adapter runs, not when it is built to be looked at)."""
        o = self.options
        return None if o.port is None else profibus_port(o.port, o.baudrate, o.rs485)

    def _line(self) -> SerialLinks:
        if self.links is None:
            raise unsimulated(self.name) if self.options.simulate else missing_options(self.name)
        return self.links

    # ------------------------------------------------------------------ running

    async def run(self, hub: HubPort) -> None:
        links = self._line()
        self._hub = hub
        self._loop = asyncio.get_running_loop()
        for drive in self._drives.values():
            hub.set_capabilities(drive.id, drive.profile.capabilities())
            hub.update(drive.id, comm=CommState.OFFLINE)
        off = hub.on_command(self._on_command)
        try:
            self._port = links.start()
            if self.options.clear_on_lost_control:
                self._control_timer = self._loop.call_later(CONTROL_CHECK, self._check_control)
            await self._serve()
        finally:
            off()
            await self._leave()

    async def _serve(self) -> None:
        loop = self._loop
        if loop is None or self._port is None:
            raise GatewayError("profibus adapter: no port")
        pause = REOPEN_BACKOFF[0]
        while True:
            failed: asyncio.Future[BaseException] = loop.create_future()

            def on_error(
                exc: BaseException, failed: asyncio.Future[BaseException] = failed
            ) -> None:
                if not failed.done():
                    failed.set_result(exc)

            try:
                link = await self._line().open(loop, _ignore, on_error)
            except PortHeld as exc:
                if self._link_opens == 0:
                    raise  # at start: refuse to be a second master (the daemon stops)
                self._port_down(str(exc))  # taken while ours was gone: wait for it
                await asyncio.sleep(pause)
                pause = min(2 * pause, REOPEN_BACKOFF[1])
                continue
            except OPEN_ERRORS as exc:
                self.claimed.set()  # not held by another master: missing, or refused
                self._port_down(f"cannot open {self._port}: {exc}")
                await asyncio.sleep(pause)
                pause = min(2 * pause, REOPEN_BACKOFF[1])
                continue
            self._link_opens += 1
            self.claimed.set()
            pause = REOPEN_BACKOFF[0]
            self._attach(link)
            lost = await failed
            await self._detach()
            self._port_down(f"serial port {self._port} lost: {lost}")
            await asyncio.sleep(pause)

    def _attach(self, link: SerialLink) -> None:
        if self._port_state is PortState.REOPENING:
            self._reopens += 1
        self._port_state = PortState.OPEN
        self._port_error = None
        self._link = link
        bursts = self.links is not None and self.links.far_end_apart()
        self._driver = LineDriver(
            self.master,
            link,
            self._on_action,
            self._on_flushed_noise,
            bursts=bursts,
            ring_priority=self.options.ring_priority,
        )
        if self._loop is not None:
            self._dispatch(self.master.reset(self._loop.time()))
        self._driver.start()
        log.info("%s: Profibus master %d on %s", self.name, self.master.address, self._port)

    async def _detach(self) -> None:
        link = self._link
        if self._driver is not None:
            self._driver.stop()
        self._driver = None
        self._link = None
        for drive in self._drives.values():
            self._lost(drive, "the serial port closed")
        if link is not None:
            await link.aclose()

    def _port_down(self, text: str) -> None:
        if self._port_error != text:
            log.warning("%s: %s", self.name, text)
            for drive in self._drives.values():
                self._event(drive, EventKind.BUS, text)
        self._port_error = text
        self._port_state = PortState.REOPENING

    async def _leave(self) -> None:
        """Leave the line: Global_Control Clear to all, then close the port (rule 4)."""
        if self._control_timer is not None:
            self._control_timer.cancel()
            self._control_timer = None
        tasks = [
            t
            for d in self._drives.values()
            for t in (d.connect_task, d.codes_task)
            if t is not None
        ]
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        driver, link, loop = self._driver, self._link, self._loop
        if driver is not None and link is not None and loop is not None:
            driver.stop()
            transmits = self.master.leave(loop.time())
            for t in transmits:
                wait = t.not_before - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                link.write(t.data)
            tail = self.master.bus.tx_time(sum(len(t.data) for t in transmits))
            await asyncio.sleep(tail + LEAVE_MARGIN)
            await self._line().settle()
            log.info("%s: Global_Control Clear sent; closing %s", self.name, self._port)
        await self._detach()
        self._port_state = PortState.CLOSED
        self._line().close()
        self._jobs.cancel()

    # ------------------------------------------------------------------ engine actions

    def _dispatch(self, actions: list[Any]) -> None:
        for action in actions:
            self._on_action(action)

    def _on_action(self, action: Any) -> None:
        handler = _ACTION_HANDLERS.get(type(action))
        if handler is not None:
            handler(self, action)

    def _on_flushed_noise(self, noise: LineNoise) -> None:
        self.master.count_noise(noise.error)

    def _drive_at(self, address: int) -> _Drive | None:
        return self._by_address.get(address)

    def _on_state(self, action: SlaveStateChanged) -> None:
        drive = self._drive_at(action.address)
        if drive is None or self._hub is None:
            return
        if action.new in CONNECTING_STATES:
            drive.absent_reported = False
            self._hub.update(drive.id, comm=CommState.CONNECTING)
        elif action.new is SlaveState.ABSENT:
            self._hub.update(drive.id, comm=CommState.OFFLINE, running=False)
            if not drive.absent_reported:
                drive.absent_reported = True
                self._event(drive, EventKind.COMM, f"no answer at address {drive.address}")

    def _on_up(self, action: SlaveUp) -> None:
        drive = self._drive_at(action.address)
        if drive is None or self._hub is None or self._loop is None:
            return
        drive.up = True
        drive.configured = False
        drive.absent_reported = False
        self._hub.update(drive.id, comm=CommState.CONNECTING)
        self._set_unconfigured(drive, self._loop.time())  # fresh: never a pre-loss output
        drive.connect_task = self._loop.create_task(
            self._connect(drive), name=f"profibus-connect-{drive.id}"
        )

    def _on_down(self, action: SlaveDown) -> None:
        drive = self._drive_at(action.address)
        if drive is not None:
            self._lost(drive, action.reason)

    def _lost(self, drive: _Drive, reason: str) -> None:
        was_up = drive.up
        drive.up = False
        drive.configured = False
        drive.last_ext = b""
        for task in (drive.connect_task, drive.codes_task):
            if task is not None:
                task.cancel()
        drive.connect_task = drive.codes_task = None
        if not was_up:
            return
        drive.profile.on_comm_lost()
        if self._hub is not None:
            self._hub.update(drive.id, comm=CommState.OFFLINE, running=False)
            self._event(drive, EventKind.COMM, f"left data exchange: {reason}", reason=reason)

    def _on_fault(self, action: SlaveFault) -> None:
        drive = self._drive_at(action.address)
        if drive is not None:
            kind = FAULT_EVENTS.get(action.kind, EventKind.CONFIG)
            text = action.text + _gsd_hint(self._overrides.get(drive.id), action.slave_cfg)
            self._event(drive, kind, text, fault=action.kind.value)

    def _on_inputs(self, action: InputsReceived) -> None:
        drive = self._drive_at(action.address)
        if drive is None or self._hub is None or self._loop is None:
            return
        now = self._loop.time()
        if drive.configured:
            changes = drive.profile.inputs(action.data, now)
            self._hub.update(drive.id, comm=CommState.ONLINE, **changes)
            if drive.profile.wants_codes:
                self._read_codes(drive, now)
        if self.master.outputs_pending(drive.address):
            self.master.quiet_inputs(drive.address, False)
            return  # the last outputs computed have not gone out: they go first
        if drive.configured:
            self._set_outputs(drive, self._hub.desired(drive.id), now)
        else:
            self._set_unconfigured(drive, now)
        self.master.quiet_inputs(drive.address, self._steady(drive))

    def _steady(self, drive: _Drive) -> bool:
        """Whether the drive's unchanged inputs tell the adapter nothing (the line's fast
        path, docs/decisions/0096): configured, no codes to read, nothing under way on
        the adapter's side, and a profile whose telegrams then depend on nothing else."""
        return (
            drive.configured
            and drive.up
            and drive.codes_task is None
            and not drive.lock.locked()
            and not drive.profile.wants_codes
            and drive.profile.steady
        )

    def _want(self, drive: _Drive) -> None:
        """Something besides the inputs changed for the drive: its next reply is handled."""
        if drive.up:
            self.master.quiet_inputs(drive.address, False)

    def _on_command(self, drive_id: str) -> None:
        """The hub's desired command changed: the new outputs go with the slave's next
        Data_Exchange (a stop waits for no reply), and its next reply is handled."""
        drive = self._drives.get(drive_id)
        if drive is None or not drive.up or self._hub is None or self._loop is None:
            return
        self._want(drive)
        if drive.configured and not self.master.outputs_pending(drive.address):
            self._set_outputs(drive, self._hub.desired(drive.id), self._loop.time())

    def _read_codes(self, drive: _Drive, now: float) -> None:
        """The profile wants fault/alarm codes its telegram does not carry: read them."""
        if drive.codes_task is not None or now < drive.codes_retry_at or self._loop is None:
            return
        drive.codes_task = self._loop.create_task(
            self._codes(drive), name=f"profibus-codes-{drive.id}"
        )

    async def _codes(self, drive: _Drive) -> None:
        try:
            if self._hub is not None:
                async with drive.lock:
                    changes = await drive.profile.read_codes(Channel(self._jobs, drive))
                if changes and drive.up:
                    self._hub.update(drive.id, **changes)
        except GatewayError as exc:
            log.info("%s: fault codes not read: %s", drive.id, exc)
            if self._loop is not None:
                drive.codes_retry_at = self._loop.time() + CODES_RETRY
        finally:
            drive.codes_task = None
            self._want(drive)

    def _on_diag(self, action: DiagnosisRead) -> None:
        drive = self._drive_at(action.address)
        if drive is None:
            return
        # A profile with ``sees_every_diag`` (MCD 600) keeps its own memory of the diagnosis.
        every = drive.profile.sees_every_diag
        if action.ext == drive.last_ext and not every:
            return
        drive.last_ext = action.ext
        if not action.ext and not every:
            return
        try:
            events = drive.profile.on_ext_diag(action.ext)
        except (GatewayError, ValueError) as exc:
            self._event(drive, EventKind.BUS, f"extended diagnosis not understood: {exc}")
            return
        for ev in events:
            self._event(drive, DIAG_KINDS[ev.kind], ev.text, **dict(ev.data))

    # ------------------------------------------------------------------ helpers

    def _event(self, drive: _Drive, kind: EventKind, text: str, **data: Any) -> None:
        if self._hub is not None:
            self._hub.event(drive.id, kind, text, address=drive.address, **data)

    def _safe(self, drive: _Drive) -> DesiredCommand:
        """The desired command with run and jog off (fault_reset_seq kept: no new edge)."""
        if self._hub is None:
            return DesiredCommand()
        return self._hub.desired(drive.id).stopped(StopAction.RAMP_STOP, Source.GATEWAY)

    def _set_outputs(self, drive: _Drive, desired: DesiredCommand, now: float) -> None:
        self.master.set_outputs(drive.address, drive.profile.outputs(desired, now))

    def _set_unconfigured(self, drive: _Drive, now: float) -> None:
        """Outputs while the drive is not configured: a stop (:func:`unconfigured_outputs`)."""
        self.master.set_outputs(
            drive.address, unconfigured_outputs(drive.profile, self._safe(drive), now)
        )

    async def _connect(self, drive: _Drive) -> None:
        """on_connect until it succeeds (back-off between attempts, an event on each new error)."""
        hub = self._hub
        if hub is None:
            return
        pause = CONNECT_BACKOFF[0]
        channel = Channel(self._jobs, drive)
        while drive.up:
            try:
                async with drive.lock:
                    changes = await drive.profile.on_connect(channel, self._sink(drive))
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # the profile's failure: the drive stays not configured
                if not isinstance(exc, GatewayError):
                    log.exception("%s: on_connect failed", drive.id)
                if self._reparameterise(drive, exc):
                    return
                text = f"not configured: {exc}"
                if text != drive.connect_error:
                    drive.connect_error = text
                    self._event(drive, EventKind.CONFIG, text)
                hub.update(drive.id, comm=CommState.CONNECTING)
                await asyncio.sleep(pause)
                pause = min(2 * pause, CONNECT_BACKOFF[1])
                continue
            drive.connect_error = None
            drive.reparameterised = 0
            hub.set_capabilities(drive.id, drive.profile.capabilities())
            drive.configured = True
            if not drive.watchdog and drive.profile.failsafe_needs_watchdog:
                own = changes.get("failsafe_text")
                changes["failsafe"] = False
                changes["failsafe_text"] = WATCHDOG_OFF + (f" ({own} never acts)" if own else "")
            if changes:
                hub.update(drive.id, **changes)
            self._want(drive)
            self._event(drive, EventKind.COMM, "configured: data exchange with the drive's profile")
            return

    def _reparameterise(self, drive: _Drive, exc: Exception) -> bool:
        """``on_connect`` asked for a restart of the slave (its exception's
        ``reparameterise``): out of data exchange, then Set_Prm again. True when done; the
        slave's SlaveUp starts a new connect. Asked again right after: a failure."""
        loop = self._loop
        if not getattr(exc, "reparameterise", False) or loop is None:
            return False
        if drive.reparameterised >= MAX_REPARAMETERISE:
            return False
        drive.reparameterised += 1
        self._event(drive, EventKind.PARAMETER, str(exc), reparameterise=True)
        drive.connect_task = None  # this task ends here: not cancelled by the SlaveDown
        self._dispatch(self.master.restart(drive.address, loop.time(), str(exc)))
        if self._driver is not None:
            self._driver.poke()
        return True

    def _sink(self, drive: _Drive) -> EventSink:
        def sink(text: str, kind: DiagKind = DiagKind.INFO, **data: Any) -> None:
            self._event(drive, DIAG_KINDS[kind], text, **data)

        return sink

    def _check_control(self) -> None:
        """clear_on_lost_control: Clear while any drive's command is the gateway's own."""
        self._control_timer = None
        hub, loop = self._hub, self._loop
        if hub is None or loop is None:
            return
        lost = [d.id for d in self._drives.values() if hub.desired(d.id).source is Source.GATEWAY]
        mode = LineMode.CLEAR if lost else LineMode.OPERATE
        if mode is not self.master.mode:
            text = (
                f"line in Clear: northbound control lost ({', '.join(lost)})"
                if lost
                else "line back in Operate"
            )
            log.warning("%s: %s", self.name, text)
            for drive in self._drives.values():
                self._event(drive, EventKind.BUS, text)
            self.master.set_mode(mode, loop.time())
            if self._driver is not None:
                self._driver.poke()
        self._control_timer = loop.call_later(CONTROL_CHECK, self._check_control)

    # ------------------------------------------------------------------ DriveAdapter

    def _drive(self, drive_id: str) -> _Drive:
        try:
            return self._drives[drive_id]
        except KeyError:
            raise UnknownDrive(f"no drive {drive_id!r} on bus {self.name}") from None

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        drive = self._drive(drive_id)
        if not drive.up:
            raise DriveOffline(f"drive {drive_id} is not in data exchange")
        async with drive.lock:
            return await drive.profile.read_param(Channel(self._jobs, drive), number, subindex)

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        drive = self._drive(drive_id)
        if not drive.up:
            raise DriveOffline(f"drive {drive_id} is not in data exchange")
        try:
            async with drive.lock:
                await drive.profile.write_param(Channel(self._jobs, drive), number, subindex, value)
        finally:
            self._want(drive)  # a cyclic output word or the speed scale may have changed

    def global_control(
        self,
        *,
        sync: bool = False,
        unsync: bool = False,
        freeze: bool = False,
        unfreeze: bool = False,
        groups: tuple[int, ...] = (),
    ) -> None:
        """Sync/Freeze (fact sheet 1.9) to the groups (1-8; none = every slave)."""
        control = GlobalControl(
            unfreeze=unfreeze,
            freeze=freeze,
            unsync=unsync,
            sync=sync,
            clear_data=self.master.mode is LineMode.CLEAR,
            group_select=GlobalControl.groups_mask(groups),
        )
        self.master.global_control(control)
        if self._driver is not None:
            self._driver.poke()

    def live_list(self) -> list[int]:
        return self.master.live_list()

    def diagnostics(self) -> dict[str, Any]:
        drives = {}
        for drive in self._drives.values():
            drives[drive.id] = {
                **self.master.slave_diagnostics(drive.address),
                "device": drive.config.device.value,
                "configured": drive.configured,
                "not_configured_reason": drive.connect_error,
            }
        return {
            "port": self._port,
            "simulated": self.options.simulate,
            "port_state": self._port_state.value,
            "port_error": self._port_error,
            "reopens": self._reopens,
            **self.master.line_diagnostics(),
            "drives": drives,
        }


def _ignore(data: bytes, now: float) -> None:
    return


def unconfigured_outputs(profile: DpProfile, safe: DesiredCommand, now: float) -> bytes:
    """The telegram for a slave in data exchange whose profile is not configured (first
    output after any (re)connection, and while ``on_connect`` fails): the profile's
    ``unconfigured_outputs`` hook where it has one (a stop whatever data profile the drive
    speaks, the WEG drives), else its outputs for ``safe`` (run and JOG off)."""
    return profile.unconfigured_outputs(safe, now)


def _watchdog_of(bus: opts.BusOptions, drive: opts.DriveOptions | None) -> float:
    """The slave's DP watchdog: its own, else the bus's (0: off)."""
    if drive is not None and drive.watchdog is not None:
        return drive.watchdog
    return bus.watchdog


def _overridden(setup: SlaveSetup, override: opts.SetupOverride | None) -> SlaveSetup:
    """The profile's setup with what a GSD file or explicit config keys give instead."""
    if override is None:
        return setup
    changes: dict[str, Any] = {"origin": override.origin}
    if override.ident_number is not None:
        changes["ident_number"] = override.ident_number
    if override.cfg is not None:
        changes["cfg"] = override.cfg
    if override.user_prm is not None:
        changes["user_prm"] = override.user_prm
    if override.dpv1 is not None:
        changes["dpv1"] = override.dpv1
    return replace(setup, **changes)


def _gsd_hint(override: opts.SetupOverride | None, slave_cfg: bytes | None) -> str:
    """Which module of the drive's GSD the slave's own configuration is (Cfg_Fault)."""
    if override is None or override.gsd is None or slave_cfg is None:
        return ""
    from adapters.profibus.codec.gsd import match_modules

    modules = match_modules(override.gsd, slave_cfg)
    if modules is None:
        return "; the slave's configuration is no module of the GSD"
    names = ", ".join(repr(m.name) for m in modules)
    return (
        f"; the slave's configuration is GSD module {names}: configure that, "
        "or program the drive for the one sent"
    )


def _slave_params(address: int, setup: SlaveSetup, watchdog: float) -> SlaveParams:
    return SlaveParams(
        address=address,
        ident_number=setup.ident_number,
        cfg=setup.cfg,
        user_prm=setup.user_prm,
        input_len=setup.input_len,
        output_len=setup.output_len,
        dpv1=setup.dpv1,
        group=setup.group,
        watchdog=watchdog or None,
        origin=setup.origin,
    )


_ACTION_HANDLERS: Final[dict[type, Callable[[ProfibusAdapter, Any], None]]] = {
    SlaveStateChanged: ProfibusAdapter._on_state,
    SlaveUp: ProfibusAdapter._on_up,
    SlaveDown: ProfibusAdapter._on_down,
    SlaveFault: ProfibusAdapter._on_fault,
    InputsReceived: ProfibusAdapter._on_inputs,
    DiagnosisRead: ProfibusAdapter._on_diag,
    RecordDone: lambda adapter, action: adapter._jobs.done(action),
}
