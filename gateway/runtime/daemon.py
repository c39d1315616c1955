"""The composition root: config -> hub, adapters and front ends, signals, systemd.

Adapters are found through the name -> "module:Class" table of
:mod:`gateway.config` (``ADAPTERS``) and front ends through :data:`FRONT_ENDS`, both
imported lazily; each front end gets the :class:`Runtime` as its
:class:`gateway.frontend.RuntimeView`. An adapter that crashes is logged with its
traceback and restarted with back-off while its drives are offline; the rest of the
gateway keeps running.
One master per line: an adapter whose first run finds its line held by another master
(:class:`LineHeld`) stops the daemon before it starts, one line logged and exit status
:data:`EXIT_LINE_HELD`; met again after a restart, it is logged and retried. READY waits
for every adapter's optional ``claimed`` event (its line held) as for the front ends'
``ready``, so a refused start never reports READY.
SIGTERM/SIGINT shut down in order (safety rule 4). SIGHUP reloads nothing (a restart
is the way, docs/decisions/0007-no-reload.md): it checks the file on disk and logs the
result.

Start-up: the front ends start first; a :class:`StartupError` from one of them before
READY (a Modbus port in use or not allowed, a Zenoh endpoint that cannot be bound or
parsed) is fatal: one line naming the cause and the fix, no READY, no bus touched, and
:data:`EXIT_STARTUP` (docs/operations.md). Only once they serve are the buses started.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway import __version__
from gateway.access.audit import AuditTrail, Kind, Result
from gateway.access.users import fingerprints, user_changes
from gateway.adapter import EventKind
from gateway.config import BusConfig, Config, load, load_adapter
from gateway.errors import ConfigError, ConfigErrors, LineHeld, StartupError
from gateway.frontend import FrontEnd, RuntimeView
from gateway.history.recorder import HistoryRecorder
from gateway.history.store import HistoryStore
from gateway.hub import DrivePolicy, Hub
from gateway.loader import load as load_target
from gateway.loader import load_optional
from gateway.model import CommState, DriveState
from gateway.runtime.limits import descriptor_problems
from gateway.runtime.linethread import LineThread
from gateway.runtime.preflight import front_end_problems
from gateway.runtime.systemd import Notifier

log = logging.getLogger(__name__)

FRONT_ENDS: dict[str, str] = {
    "zenoh": "gateway.zenoh.frontend:ZenohFrontEnd",
    "modbus": "gateway.modbus.frontend:ModbusFrontEnd",
    "web": "gateway.web.frontend:WebFrontEnd",
    "opcua": "gateway.opcua.frontend:OpcuaFrontEnd",
}
"""Front-end name (its config section) -> "module:Class"."""

SIMULATORS: dict[str, str] = {
    "profibus": "adapters.profibus.sim.simulated:SimulatedLine",
    "devicenet": "adapters.devicenet.sim.simulated:SimulatedBus",
    "canopen": "adapters.canopen.sim.simulated:SimulatedBus",
}
"""Adapter name -> "module:Class" of its simulated line, made from the bus's config for a
bus with ``simulate = true`` and given to the adapter as its link factory; the adapters
themselves never import a simulator."""

RESTART_BACKOFF = (0.5, 30.0)  # first and longest pause before restarting a crashed adapter
DIAG_REUSE = 0.05  # s a bus's diagnostics serve all its drives' diag (one heartbeat pass)
SWITCH_INTERVAL = 0.0005
"""s a thread may hold the interpreter while another waits (``sys.setswitchinterval``): a
line's thread woken by its port waits at most this for a busy daemon loop (0071)."""
READY_BOUND = 10.0  # s the daemon waits for its front ends to serve before it reports READY
EXIT_LINE_HELD = 75  # EX_TEMPFAIL (sysexits.h): another master holds a line; it may be freed
EXIT_STARTUP = 2
"""Exit status when the gateway cannot start (as for a config error; the unit file's
RestartPreventExitStatus=2 keeps systemd from restarting into the same error)."""


class Backoff:
    """The pause before restarting a crashed task: ``first``, doubling up to ``longest``,
    and back to ``first`` once a run lasted longer than ``longest`` (it was healthy)."""

    def __init__(
        self, first: float = RESTART_BACKOFF[0], longest: float = RESTART_BACKOFF[1]
    ) -> None:
        self.first = first
        self.longest = longest
        self._next = first

    def after_crash(self, ran_for: float) -> float:
        """The pause to take now, for a run that lasted ``ran_for`` seconds."""
        if ran_for > self.longest:
            self._next = self.first
        pause = self._next
        self._next = min(pause * 2, self.longest)
        return pause


@dataclass
class Runtime:
    """The running gateway: what front ends may see of it (:class:`RuntimeView`)."""

    config: Config
    hub: Hub
    adapters: dict[str, LineThread] = field(default_factory=dict)
    started: float = field(default_factory=time.monotonic)
    version: str = __version__
    restarts: dict[str, int] = field(default_factory=dict)
    front_ends: dict[str, FrontEnd] = field(default_factory=dict)
    """The running instance of each front end (the web front end's metrics read the others)."""
    history: HistoryStore | None = None
    """The history's queries while ``[history]`` is on (gateway/history/store.py)."""
    audit: AuditTrail = field(default_factory=AuditTrail)
    """The audit trail (memory only until the daemon opens the configured one)."""
    _diag: dict[str, tuple[float, LineThread, dict[str, Any]]] = field(
        default_factory=dict, init=False, repr=False
    )

    def bus_of(self, drive_id: str) -> str:
        return self.hub.state(drive_id).bus

    def drive_diagnostics(self, drive_id: str) -> dict[str, Any]:
        """One drive's figures. The bus's diagnostics are made once for all its drives
        (reused for :data:`DIAG_REUSE` s): a heartbeat pass over a line of 64 slaves would
        otherwise make the whole line's diagnostics 64 times."""
        bus = self.bus_of(drive_id)
        adapter = self.adapters.get(bus)
        if adapter is None:
            return {}
        now = time.monotonic()
        cached = self._diag.get(bus)
        if cached is None or cached[1] is not adapter or now - cached[0] > DIAG_REUSE:
            cached = self._diag[bus] = (now, adapter, adapter.diagnostics())
        drives = cached[2].get("drives", {})
        result: dict[str, Any] = drives.get(drive_id, {})
        return result

    def health(self) -> dict[str, Any]:
        buses = {}
        for bus in self.config.buses:
            adapter = self.adapters.get(bus.name)
            diag = adapter.diagnostics() if adapter is not None else {}
            live = [d.id for d in bus.drives if self.hub.state(d.id).online]
            buses[bus.name] = {
                "adapter": bus.adapter,
                "live": live,
                "restarts": self.restarts.get(f"bus {bus.name}", 0),
                **{k: v for k, v in diag.items() if k != "drives"},
            }
        return {
            "name": self.config.gateway.name,
            "version": self.version,
            "uptime_s": round(time.monotonic() - self.started, 3),
            "drives": len(self.config.drives),
            "drive_ids": [d.id for d in self.config.drives],
            "online": sum(1 for s in self.hub.states() if s.online),
            "faulted": sum(1 for s in self.hub.states() if s.online and s.faulted),
            "buses": buses,
        }


def build_hub(config: Config, hub: Hub | None = None) -> Hub:
    """A hub holding every configured drive, stopped and offline."""
    hub = hub or Hub()
    for bus in config.buses:
        for d in bus.drives:
            state = DriveState(id=d.id, device=d.device, bus=bus.name, address=d.address)
            policy = DrivePolicy(
                control=d.control,
                command_timeout=d.command_timeout,
                on_command_timeout=d.on_command_timeout,
                on_shutdown=d.on_shutdown,
                require_failsafe=d.require_failsafe,
                writable_params=d.writable_params,
                writable_entries=d.writable_entries,
                modbus_unit=d.modbus_unit,
            )
            hub.add_drive(state, policy)
    return hub


def load_front_end(name: str) -> Callable[[RuntimeView], FrontEnd] | None:
    factory: Callable[[RuntimeView], FrontEnd] | None = load_optional(FRONT_ENDS[name])
    if factory is None:
        log.warning("%s front end is not part of this build; not serving it", name)
    return factory


def simulated_line(bus: BusConfig) -> object:
    """The simulated line of a bus with ``simulate = true`` (its adapter's link factory)."""
    target = SIMULATORS.get(bus.adapter)
    if target is None:
        raise ConfigError(
            "configuration",
            f"buses.{bus.name}.simulate",
            f"adapter {bus.adapter!r} has no simulator",
        )
    factory: Callable[[BusConfig], object] = load_target(target)
    return factory(bus)


class Daemon:
    def __init__(self, config: Config, notifier: Notifier | None = None) -> None:
        self.config = config
        self.notifier = notifier or Notifier()
        self.hub = build_hub(config)
        self.runtime = Runtime(config=config, hub=self.hub)
        self._stop = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._adapter_tasks: list[asyncio.Task[None]] = []
        self.front_ends: dict[str, FrontEnd] = self.runtime.front_ends
        """The running instance of each front end (a new one after a restart)."""
        self._started_front_ends: list[str] = []
        self.ready = asyncio.Event()
        """Set when the daemon has reported READY (its front ends serve)."""
        self.recorder: HistoryRecorder | None = None
        if config.history.enabled:
            self.recorder = HistoryRecorder(self.hub, config.history)
            self.runtime.history = self.recorder.store
        self._history_task: asyncio.Task[None] | None = None
        self.exit_status = 0
        self.fatal: StartupError | ConfigError | None = None
        """Why the gateway could not start (then it exits with EXIT_STARTUP)."""

    def request_stop(self) -> None:
        self._stop.set()

    def check_reload(self) -> None:
        """SIGHUP: no reload. The running config stays as it is; the file on disk is
        validated so the operator learns, before a restart, whether it would start."""
        file = self.config.file
        try:
            new = load(file)
            problems = front_end_problems(new)
            if problems:
                raise ConfigErrors(problems)
        except (ConfigErrors, ConfigError) as exc:
            errors = exc.errors if isinstance(exc, ConfigErrors) else [exc]
            self.runtime.audit.record(
                Kind.CONFIG_RELOAD,
                Result.FAILURE,
                interface="signal",
                identity="SIGHUP",
                detail=f"{file}: {len(errors)} error(s); not reloaded",
            )
            log.error(
                "SIGHUP: configuration is not reloaded; %s has %d error(s), a restart would "
                "fail; the running configuration stays: %s",
                file,
                len(errors),
                "; ".join(str(e) for e in errors),
            )
            return
        except Exception:
            log.exception("SIGHUP: configuration is not reloaded; checking %s failed", file)
            return
        self.runtime.audit.record(
            Kind.CONFIG_RELOAD,
            Result.FAILURE,
            interface="signal",
            identity="SIGHUP",
            detail=f"{file} checks ok; not reloaded (a restart applies it)",
        )
        log.warning(
            "SIGHUP: configuration is not reloaded; the running configuration stays "
            "(%s checks ok: %d drive(s); restart the gateway to apply it)",
            file,
            len(new.drives),
        )

    # ------------------------------------------------------------ adapters

    def _make_line(self, bus: BusConfig) -> LineThread:
        """The bus's adapter on a thread and event loop of its own (0071)."""
        cls = load_adapter(bus.adapter)
        adapter = cls(bus, links=simulated_line(bus)) if bus.simulate else cls(bus)
        line = LineThread(adapter, self.hub)
        self.runtime.adapters[bus.name] = line
        self.hub.attach_params([d.id for d in bus.drives], line)
        return line

    def _offline(self, bus: BusConfig) -> None:
        for d in bus.drives:
            self.hub.update(d.id, comm=CommState.OFFLINE, running=False)

    async def _supervise(
        self, what: str, start: Callable[[], Awaitable[None]], on_crash: Callable[[], None]
    ) -> None:
        """Run ``start()`` again and again, with back-off, until cancelled."""
        backoff = Backoff()
        first = True
        while True:
            started = time.monotonic()
            error: Exception | None = None
            try:
                await start()
            except asyncio.CancelledError:
                raise
            except LineHeld as exc:
                if first:
                    self._refuse_start(what, exc)
                    on_crash()
                    return
                error = exc
            except (StartupError, ConfigError) as exc:
                if not self.ready.is_set():
                    self._cannot_start(exc)
                    return
                error = exc
            except Exception as exc:
                error = exc
            first = False
            pause = backoff.after_crash(time.monotonic() - started)
            if isinstance(error, LineHeld):  # its text says it all: one line
                log.error("%s: %s; retrying in %.1f s", what, error, pause)
            elif isinstance(error, StartupError | ConfigError):  # its one line says it all
                log.error("%s crashed: %s; restarting in %.1f s", what, error, pause)
            elif error is not None:  # logged with its traceback
                log.error("%s crashed; restarting in %.1f s", what, pause, exc_info=error)
            else:
                log.error("%s returned; restarting in %.1f s", what, pause)
            self.runtime.restarts[what] = self.runtime.restarts.get(what, 0) + 1
            on_crash()
            await asyncio.sleep(pause)

    def _refuse_start(self, what: str, error: LineHeld) -> None:
        """Another master holds a line of ours at start: stop, never become the second."""
        log.error(
            "%s: %s; drive-gateway does not start (exit status %d)", what, error, EXIT_LINE_HELD
        )
        self.exit_status = EXIT_LINE_HELD
        self._stop.set()

    def _open_audit(self) -> bool:
        """The configured audit trail, its first record the configuration loaded."""
        section = self.config.audit
        try:
            trail = AuditTrail(section)
        except (OSError, ValueError) as exc:
            where = f"[audit] file {section.file}"
            reason = (getattr(exc, "strerror", None) or str(exc)).lower()
            self._cannot_start(
                StartupError("audit", f"cannot open {where}: {reason}", "fix [audit] file")
            )
            return False
        self.runtime.audit = trail
        journal = "on" if trail.journal_open else "off (no journald socket)"
        log.info("audit trail: file %s, journal %s", section.file or "(none)", journal)
        trail.record(
            Kind.CONFIG_LOAD,
            Result.SUCCESS,
            interface="config",
            identity="drive-gateway",
            detail=f"{self.config.file}: {len(self.config.drives)} drive(s), "
            f"{len(self.config.users)} user(s)",
        )
        if section.file is not None:
            self._audit_user_changes(trail, section.file.with_name(section.file.name + ".users"))
        return True

    def _audit_user_changes(self, trail: AuditTrail, kept: Path) -> None:
        """Users live in the config: a change shows between one start and the next. The
        users' fingerprints (roles, digests of their hashes) are kept beside the audit
        file, and each change since the last start is a record."""
        try:
            read = json.loads(kept.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            read = {}
        before = (
            {k: v for k, v in read.items() if isinstance(v, dict)} if isinstance(read, dict) else {}
        )
        after = fingerprints(self.config.users)
        for line in user_changes(before, after):
            trail.record(
                Kind.USER_CHANGE,
                Result.SUCCESS,
                interface="config",
                identity="drive-gateway",
                detail=f"{line} ({self.config.file})",
            )
        try:
            kept.write_text(json.dumps(after, sort_keys=True), encoding="utf-8")
        except OSError as exc:
            log.warning("audit: cannot keep the users' fingerprints in %s: %s", kept, exc)

    def _cannot_start(self, error: StartupError | ConfigError) -> None:
        """Fatal at start-up: one line with the cause and the fix, then stop."""
        if self.fatal is None:
            self.fatal = error
            log.error("drive-gateway cannot start: %s", error)
            self.notifier.status(f"cannot start: {error}")
        self._stop.set()

    def _supervise_bus(self, bus: BusConfig) -> Awaitable[None]:
        async def start() -> None:
            await self._make_line(bus).run()

        return self._supervise(f"bus {bus.name}", start, lambda: self._offline(bus))

    # ------------------------------------------------------------ loops

    async def _ticker(self) -> None:
        interval = self.config.gateway.tick
        while True:
            self.hub.tick()
            self.runtime.audit.flush()  # the counts of refusals folded (at most once a second)
            await asyncio.sleep(interval)

    async def _watchdog(self, interval: float) -> None:
        while True:
            self.notifier.watchdog()
            await asyncio.sleep(interval)

    def _spawn(self, coro: Awaitable[None], name: str) -> asyncio.Task[None]:
        task = asyncio.ensure_future(coro)
        task.set_name(name)
        task.add_done_callback(self._task_done)
        self._tasks.append(task)
        return task

    def _task_done(self, task: asyncio.Task[None]) -> None:
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:
            log.error("task %s failed: %r; shutting down", task.get_name(), exc, exc_info=exc)
            self._stop.set()

    def _start_front_ends(self) -> None:
        enabled = {
            "zenoh": self.config.zenoh.enabled,
            "modbus": self.config.modbus.enabled,
            "web": self.config.web.enabled,
            "opcua": self.config.opcua.enabled,
        }
        for name, on in enabled.items():
            if not on:
                continue
            factory = load_front_end(name)
            if factory is None:
                continue

            def start(
                factory: Callable[[RuntimeView], FrontEnd] = factory, name: str = name
            ) -> Awaitable[None]:
                front_end = self.front_ends[name] = factory(self.runtime)
                return front_end.run()

            self._spawn(self._supervise(f"{name} front end", start, lambda: None), name)
            self._started_front_ends.append(name)

    # ------------------------------------------------------------ life cycle

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, self.request_stop)
        loop.add_signal_handler(signal.SIGHUP, self.check_reload)
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL)
        try:
            return await self._run()
        finally:
            sys.setswitchinterval(switch_interval)
            for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
                loop.remove_signal_handler(sig)
            self.notifier.close()

    async def _run(self) -> int:
        drives = self.config.drives
        if not drives:
            log.warning(
                "no drives are configured in %s; serving the gateway only", self.config.file
            )
        for problem in descriptor_problems(self.config):
            log.warning("%s", problem)
        if not self._open_audit():
            return EXIT_STARTUP
        if self.recorder is not None:  # before the front ends: it records their events too
            self._history_task = self._spawn(self.recorder.run(), "history")
        self._start_front_ends()
        self._spawn(self._ticker(), "hub-ticker")
        if self.notifier.watchdog_interval:
            self._spawn(self._watchdog(self.notifier.watchdog_interval), "sd-watchdog")
        not_serving = await self._front_ends_serving()
        if self.fatal is not None:  # no bus touched, no READY
            await self._cancel(self._tasks)
            return EXIT_STARTUP
        for bus in self.config.buses if not self._stop.is_set() else ():
            self._adapter_tasks.append(self._spawn(self._supervise_bus(bus), f"bus-{bus.name}"))
        unclaimed = await self._lines_claimed()
        status = f"{len(drives)} drive(s) on {len(self.config.buses)} bus(es)"
        if not_serving:
            status += f"; not serving yet: {', '.join(not_serving)}"
            log.error("front end(s) %s not serving after %g s", ", ".join(not_serving), READY_BOUND)
        if unclaimed:
            status += f"; line not claimed yet: {', '.join(unclaimed)}"
            log.warning(
                "bus(es) %s: line not claimed after %g s", ", ".join(unclaimed), READY_BOUND
            )
        if not self._stop.is_set():
            self.notifier.ready(status)
            self.ready.set()
            log.info("drive-gateway %s running: %s", __version__, status)
        await self._stop.wait()
        await self._shutdown()
        return self.exit_status

    async def _front_ends_serving(self) -> list[str]:
        """Wait until every front end serves (its ``ready`` event), bounded by READY_BOUND;
        returns the names of those that do not."""
        deadline = asyncio.get_running_loop().time() + READY_BOUND
        return [
            name
            for name in self._started_front_ends
            if not await self._until_set(self.front_ends, name, "ready", deadline)
        ]

    async def _lines_claimed(self) -> list[str]:
        """Wait until every adapter has claimed its line (its ``claimed`` event: a serial
        port held, a DeviceNet MAC ID checked), bounded by READY_BOUND, so that a line
        another master holds stops the daemon before it reports READY; returns the buses
        that have not. An adapter without the event claims nothing."""
        deadline = asyncio.get_running_loop().time() + READY_BOUND
        return [
            bus.name
            for bus in self.config.buses
            if not await self._until_set(self.runtime.adapters, bus.name, "claimed", deadline)
        ]

    async def _until_set(
        self, parts: Mapping[str, object], name: str, attr: str, deadline: float
    ) -> bool:
        """Wait until the ``attr`` event of ``parts[name]`` is set, or the daemon stops; False
        at ``deadline``. A part restarted meanwhile is a new instance: its own event is the
        one waited for; an instance without such an event is set once it exists."""
        loop = asyncio.get_running_loop()
        while not self._stop.is_set():
            current = parts.get(name)
            event = getattr(current, attr, None)
            if current is not None and not isinstance(event, asyncio.Event):
                return True
            if event is not None and event.is_set():
                return True
            remaining = deadline - loop.time()
            if remaining <= 0:
                return False
            if event is None:
                await asyncio.sleep(0.01)  # its task has not created it yet
                continue
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(remaining, 0.25)):
                    await event.wait()
        return True

    async def _shutdown(self) -> None:
        """Rule 4: on_shutdown, bounded wait for stopped, then leave the buses."""
        log.info("shutting down: applying on_shutdown to every drive")
        self.notifier.stopping()
        self.hub.apply_shutdown()
        bound = self.config.gateway.shutdown_timeout
        try:
            await asyncio.wait_for(self._wait_stopped(), bound)
            log.info("all drives stopped")
        except TimeoutError:
            self._left_turning(bound)
        # Adapters first (they leave their buses cleanly on cancellation), then the rest.
        await self._cancel(self._adapter_tasks)
        last = [t for t in (self._history_task,) if t is not None]  # records the shutdown
        await self._cancel([t for t in self._tasks if t not in self._adapter_tasks + last])
        await self._cancel(last)
        self.runtime.audit.close()
        log.info("drive-gateway stopped")

    def _left_turning(self, bound: float) -> None:
        """The shutdown bound passed with drives still turning (docs/safety.md, "Shutdown"):
        the gateway does not wait on (systemd's stop timeout would end it mid-way); it says
        which drives, and leaves each to the stop it was sent and to its own reaction to a
        lost master."""
        still = [s for s in self.hub.states() if s.online and s.running]
        log.warning(
            "shutdown bound %.1f s reached; still running: %s", bound, [s.id for s in still]
        )
        for state in still:
            speed = "" if state.speed_rpm is None else f" at {state.speed_rpm:g} rpm"
            self.hub.event(
                state.id,
                EventKind.SAFETY,
                f"still turning{speed} after the shutdown bound ({bound:g} s): the gateway "
                "leaves the bus with the stop sent; the drive's own reaction to a lost master "
                f"follows ({state.failsafe_text or 'not known to the gateway'})",
            )

    async def _wait_stopped(self) -> None:
        with self.hub.subscribe_states() as sub:
            while not self.hub.all_stopped():
                await sub.get()

    @staticmethod
    async def _cancel(tasks: list[asyncio.Task[None]]) -> None:
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task


def run(config: Config) -> int:
    return asyncio.run(Daemon(config).run())
