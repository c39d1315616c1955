"""The OPC UA front end: what the daemon runs as ``OpcuaFrontEnd(runtime).run()``.

An asyncua server on the daemon's own event loop, at ``opc.tcp://<bind>/drive-gateway``,
serving the drive model (gateway/opcua/space.py), the drives' methods through the hub
(gateway/opcua/commands.py), their faults as alarms (gateway/opcua/alarms.py) and, when
the gateway has a history store, HistoryRead of the readings (gateway/opcua/history.py).

Values reach the server in batches: the hub's conflating state subscription (the newest
state of each drive that changed) is drained every ``opcua.publish_interval`` and only the
variables whose value changed are written, so the server's work grows with the changes,
not with the clients, and nothing on a line's thread ever waits for it (the lines report
to the hub; the hub runs on this loop and only marks a drive pending). A batch and the
notifications it makes may take at most :data:`LOOP_SHARE` of the loop: under more changes
than that, the period stretches and each drive's newest state is written, never a backlog.
What the batches cost is counted (:meth:`OpcuaFrontEnd.figures`).

Every second the lines' figures are copied to Objects/Buses and the firmware of a drive
that came online is read once (a parameter read through the hub); the EURange of the
speed readings follows the drive's scale. The command watchdog of a drive controlled by an
OPC UA session is fed (four times per ``command_timeout``) while that session's client
makes requests within the timeout: its subscription's publish requests, reads or calls
(safety rule 3: a client that vanishes or hangs stops feeding it, and ``on_command_timeout``
applies; a session that closes stops feeding it at once).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import time
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any

from asyncua import Server, ua

from gateway.adapter import Capabilities
from gateway.errors import GatewayError, StartupError
from gateway.frontend import FrontEndCounters, RuntimeView
from gateway.model import CommState, DriveState, Source
from gateway.opcua.alarms import Alarms
from gateway.opcua.commands import Commands
from gateway.opcua.history import DriveHistory, ReadingHistory
from gateway.opcua.limits import (
    UAPROCESSOR_LOG,
    OwnRefusalLines,
    Refusals,
    SessionGuard,
    SessionLimits,
    server_wide_subscriptions,
)
from gateway.opcua.security import ensure_certificate, policies, thumbprint, trust_clients
from gateway.opcua.sessions import CALLER, Role, RoleMap, Sessions, default_roles
from gateway.opcua.space import (
    LAST_RESULT,
    NAMESPACE,
    Builder,
    BusNodes,
    DriveNodes,
    add_bus,
    add_bus_figure,
    add_drive,
    eu_range,
    variant,
)
from gateway.opcua.users import ConfiguredUsers
from gateway.opcua.variables import READINGS, Range, bus_figures, changed_values, values_of
from gateway.paramsbackup import firmware_of

log = logging.getLogger(__name__)


class NotStarted(GatewayError):
    """A server call before the server was built (or after it stopped)."""


SLOW_PERIOD = 1.0  # s between bus figures, firmware reads, ranges and watchdog feeds
LOOP_SHARE = 0.25
"""The share of the daemon's loop the value batches may take; beyond, their period stretches."""
SLICE = 0.005  # s of a batch's work between two turns of the loop
MAX_PAUSE = 2.0  # s: the longest the batches' period stretches to
STOP_TIMEOUT = 2.0  # s the server gets to close its connections when the gateway stops
_BIND_FIXES = {
    errno.EADDRINUSE: ("the address is in use", "stop what uses it, or set [opcua] bind"),
    errno.EACCES: ("permission denied", "use a port above 1023, or set [opcua] bind"),
    errno.EADDRNOTAVAIL: ("no such local address", "set [opcua] bind to an address of this host"),
}
_NO_DATA = {
    True: ua.StatusCode(ua.StatusCodes.BadNoData),
    False: ua.StatusCode(ua.StatusCodes.BadNoCommunication),
}


class OpcuaFrontEnd:
    """The OPC UA server of the drive model."""

    def __init__(
        self,
        runtime: RuntimeView,
        history: ReadingHistory | None = None,
        roles: RoleMap | None = None,
    ) -> None:
        self.runtime = runtime
        self.hub = runtime.hub
        self.section = runtime.config.opcua
        self.history = history if history is not None else getattr(runtime, "history", None)
        users = runtime.config.users
        # the config's users (gateway/access): sessions log in, their roles decide
        self.users = ConfiguredUsers(users, Role.OBSERVE) if users else None
        default = self.users.role_of if self.users is not None else default_roles(self.section)
        self.roles = roles or default
        self.ready = asyncio.Event()
        self.commands = Commands(self.hub, self.roles)
        self.server: Server | None = None
        self.sessions: Sessions | None = None
        self.alarms: Alarms | None = None
        self.drives: dict[str, DriveNodes] = {}
        self.buses: dict[str, BusNodes] = {}
        self._builder: Builder | None = None
        self._written: dict[str, dict[str, Any]] = {}
        self._ranges: dict[str, dict[str, Range]] = {}
        self._caps: dict[str, Capabilities] = {}
        self._firmware: dict[str, asyncio.Task[None]] = {}
        self._wake = asyncio.Event()
        self.slow_pass = asyncio.Event()
        """Set after each pass of the once-a-second work (tests wait for it)."""
        self.batches = 0
        self.writes = 0
        self.busy = 0.0  # s spent in batches
        self.stretched = 0  # batches after which the period stretched (LOOP_SHARE)
        self._stretch = 1.0
        self.calls = 0
        self.refusals = Refusals()
        """Subscriptions and monitored items refused over a session's limits."""

    # ------------------------------------------------------------ life cycle

    @property
    def endpoint(self) -> str:
        return self.section.endpoint

    async def run(self) -> None:
        server = self.server = Server(user_manager=self.users)
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name(f"drive-gateway {self.runtime.config.gateway.name}")
        app_uri = f"urn:drive-gateway:{self.runtime.config.gateway.name}"
        await server.set_application_uri(app_uri)
        server.set_security_policy(policies(self.section))
        pair = ensure_certificate(self.section, app_uri)
        if pair is not None:
            await server.load_certificate(str(pair[0]))
            await server.load_private_key(str(pair[1]))
        trusted = await trust_clients(server, self.section)
        if trusted is not None:
            log.info(
                "OPC UA: %d trusted client certificate(s) in %s",
                trusted,
                self.section.trusted_clients,
            )
        limits = SessionLimits.of(self.section)
        server.iserver.max_subscriptions = server_wide_subscriptions(
            self.section.max_sessions, limits
        )
        self.sessions = Sessions(
            server.iserver, self.section.max_sessions, SessionGuard(limits, self.refusals)
        )
        ns = await server.register_namespace(NAMESPACE)
        await self._build(server, ns)
        try:
            await server.start()
        except OSError as exc:
            raise self._bind_error(exc) from None
        own_lines = OwnRefusalLines()
        logging.getLogger(UAPROCESSOR_LOG).addFilter(own_lines)
        try:
            self._log_serving(pair)
            self.ready.set()
            await self._serve()
        finally:
            logging.getLogger(UAPROCESSOR_LOG).removeFilter(own_lines)
            self.ready.clear()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(STOP_TIMEOUT):
                    await server.stop()
            for task in self._firmware.values():
                task.cancel()
            log.info("OPC UA front end stopped")

    async def _build(self, server: Server, ns: int) -> None:
        b = self._builder = Builder(server, ns)
        objects = ua.NodeId(ua.ObjectIds.ObjectsFolder)
        drives = b.object(objects, b.node_id("Drives"), "Drives", folder=True)
        buses = b.object(objects, b.node_id("Buses"), "Buses", folder=True)
        await b.commit()
        history = self.history is not None
        for state in self.hub.states():
            caps = self.hub.capabilities(state.id)
            nodes = self.drives[state.id] = await add_drive(b, drives, state, caps, history)
            self._ranges[state.id] = {r.name: r.range_of(caps) for r in READINGS}
            self._link_methods(server, nodes)
            await asyncio.sleep(0)  # about 60 nodes a drive: the loop's other work goes on
        for bus in self.runtime.config.buses:
            self.buses[bus.name] = await add_bus(b, buses, bus.name)
        self.alarms = Alarms(
            server,
            {d: n.object for d, n in self.drives.items()},
            {d: n.alarm for d, n in self.drives.items() if n.alarm is not None},
        )
        server.link_method(
            server.get_node(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge),
            self._acknowledge,
        )
        if self.history is not None:
            fields = {
                n.variables[r.name]: (d, r.field) for d, n in self.drives.items() for r in READINGS
            }
            sources: dict[ua.NodeId, str | None] = {n.object: d for d, n in self.drives.items()}
            server_node = ua.NodeId(ua.ObjectIds.Server)
            sources[server_node] = None  # every drive's events
            notifier = ua.EventNotifier.SubscribeToEvents.mask | ua.EventNotifier.HistoryRead.mask
            await server.get_node(server_node).write_attribute(
                ua.AttributeIds.EventNotifier,
                ua.DataValue(ua.Variant(notifier, ua.VariantType.Byte)),
            )
            server.iserver.history_manager.set_storage(
                DriveHistory(self.history, fields, sources=sources)
            )

    def _link_methods(self, server: Server, nodes: DriveNodes) -> None:
        for name, node in nodes.methods.items():

            async def call(
                _parent: ua.NodeId, *args: Any, drive: str = nodes.drive_id, method: str = name
            ) -> ua.CallMethodResult:
                self.calls += 1
                values = tuple(a.Value if isinstance(a, ua.Variant) else a for a in args)
                outcome = self.commands.call(drive, method, values)
                await self._show_result(drive, outcome.text)
                return outcome.result()

            server.iserver.isession.add_method_callback(node, call)

    async def _acknowledge(self, parent: ua.NodeId, *args: Any) -> ua.CallMethodResult:
        res = ua.CallMethodResult()
        values = [a.Value if isinstance(a, ua.Variant) else a for a in args]
        session = CALLER.get()
        client = session.client if session is not None else "internal"
        if session is not None and self.roles(session.user_of()) is not Role.OPERATE:
            res.StatusCode = ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
            return res
        if len(values) != 2 or not isinstance(values[0], bytes):
            res.StatusCode = ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            return res
        comment = values[1].Text if isinstance(values[1], ua.LocalizedText) else str(values[1])
        if self.alarms is None:
            raise NotStarted("the OPC UA server is not started")
        status = await self.alarms.acknowledge(parent, values[0], comment or "", client)
        res.StatusCode = ua.StatusCode(status)
        return res

    def _bind_error(self, exc: OSError) -> StartupError:
        where = f"{self.section.host}:{self.section.port}"
        cause, fix = _BIND_FIXES.get(
            exc.errno or 0, ((exc.strerror or str(exc)).lower(), "check [opcua] bind")
        )
        return StartupError("opcua", f"cannot listen on {where}: {cause}", fix)

    def _log_serving(self, pair: Any) -> None:
        modes = ", ".join(m.value for m in self.section.security)
        log.info("OPC UA server on %s (security: %s)", self.endpoint, modes)
        if pair is not None:
            log.info(
                "OPC UA server certificate %s, SHA-1 thumbprint %s", pair[0], thumbprint(pair[0])
            )

    # ------------------------------------------------------------ values

    async def _serve(self) -> None:
        period = self.section.publish_interval
        feed = self._feed_period()
        loop = asyncio.get_running_loop()
        with self.hub.subscribe_states(on_ready=self._wake.set) as sub:
            await self._batch(self.hub.states())
            next_slow = next_feed = loop.time()
            while True:
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(max(0.0, min(next_slow, next_feed) - loop.time())):
                        await self._wake.wait()
                self._wake.clear()
                spent = await self._batch(sub.drain())
                now = loop.time()
                if now >= next_feed:
                    next_feed = now + feed
                    self._feed_watchdogs()
                if now >= next_slow:
                    next_slow = now + SLOW_PERIOD
                    await self._slow()
                await self._pause(period, spent)

    async def _pause(self, period: float, spent: float) -> None:
        """The pause before the next batch. The batches take at most LOOP_SHARE of the
        loop; and while the loop comes back late from the pause (asyncua's publishing to
        the sessions, which the batches' changes cause, holds it), the pause doubles, up
        to MAX_PAUSE, and shrinks again once the loop is on time. Under more changes than
        the loop can carry, each drive's newest state is written, never a backlog."""
        loop = asyncio.get_running_loop()
        pause = max(period, spent * (1 - LOOP_SHARE) / LOOP_SHARE) * self._stretch
        pause = min(pause, MAX_PAUSE)
        if pause > period:
            self.stretched += 1
        wake = loop.time() + pause
        await asyncio.sleep(pause)
        late = loop.time() - wake
        if late > period:
            self._stretch = min(self._stretch * 2, MAX_PAUSE / period)
        else:
            self._stretch = max(1.0, self._stretch * 0.8)

    def _feed_period(self) -> float:
        """How often the watchdogs of drives controlled by a session are fed: a quarter of
        the shortest ``command_timeout``, at most once a second."""
        timeouts = [self.hub.policy(d).command_timeout for d in self.hub.drive_ids()]
        shortest = min((t for t in timeouts if t), default=4 * SLOW_PERIOD)
        return max(self.section.publish_interval, min(SLOW_PERIOD, shortest / 4))

    async def _batch(self, states: list[DriveState]) -> float:
        """Write the variables that changed, and step the alarms; the seconds of work it
        took. The loop gets a turn after every :data:`SLICE` s of it."""
        if self.server is None or self.alarms is None:
            raise NotStarted("the OPC UA server is not started")
        write = self.server.iserver.aspace.write_attribute_value
        now = datetime.now(UTC)
        work = 0.0
        began = time.perf_counter()
        for state in states:
            nodes = self.drives.get(state.id)
            if nodes is None:
                continue
            missing = _NO_DATA[state.comm is CommState.ONLINE]
            values = {k: missing if v is None else v for k, v in values_of(state).items()}
            old = self._written.get(state.id)
            changes = changed_values(old, values)
            self._written[state.id] = {**(old or {}), **values}
            for name, value in changes.items():
                await write(
                    nodes.variables[name],
                    ua.AttributeIds.Value,
                    self._datavalue(nodes, name, value, state, now),
                )
            self.writes += len(changes)
            await self.alarms.on_state(state)
            await self._update_ranges(state.id, nodes)
            if time.perf_counter() - began >= SLICE:
                work += time.perf_counter() - began
                await asyncio.sleep(0)
                began = time.perf_counter()
        work += time.perf_counter() - began
        self.batches += 1
        self.busy += work
        return work

    @staticmethod
    def _datavalue(
        nodes: DriveNodes, name: str, value: Any, state: DriveState, now: datetime
    ) -> ua.DataValue:
        when = datetime.fromtimestamp(state.ts, UTC) if state.ts else now
        if isinstance(value, ua.StatusCode):  # no value: the status says why
            return ua.DataValue(
                ua.Variant(None, ua.VariantType.Null),
                StatusCode=value,
                SourceTimestamp=when,
                ServerTimestamp=now,
            )
        return ua.DataValue(
            variant(nodes.kinds[name], value), SourceTimestamp=when, ServerTimestamp=now
        )

    async def _show_result(self, drive_id: str, text: str) -> None:
        """A method call's outcome, in the drive's LastCommandResult."""
        if self.server is None:
            raise NotStarted("the OPC UA server is not started")
        await self.server.iserver.aspace.write_attribute_value(
            self.drives[drive_id].variables[LAST_RESULT],
            ua.AttributeIds.Value,
            ua.DataValue(ua.Variant(text, ua.VariantType.String)),
        )

    # ------------------------------------------------------------ slow work

    async def _slow(self) -> None:
        started = time.perf_counter()
        await self._bus_figures()
        self._read_firmware()
        self.busy += time.perf_counter() - started
        self.slow_pass.set()

    async def _bus_figures(self) -> None:
        if self.server is None or self._builder is None:
            raise NotStarted("the OPC UA server is not started")
        write = self.server.iserver.aspace.write_attribute_value
        for name, line in self.runtime.adapters.items():
            bus = self.buses.get(name)
            if bus is None:
                continue
            try:
                figures = bus_figures(line.diagnostics())
            except Exception:
                log.debug("OPC UA: figures of bus %s not read this time", name, exc_info=True)
                continue
            for key, value in figures.items():
                node = bus.figures.get(key)
                if node is None:
                    node = await add_bus_figure(self._builder, bus, key)
                    if node is None:
                        continue
                await write(
                    node,
                    ua.AttributeIds.Value,
                    ua.DataValue(ua.Variant(value, ua.VariantType.Double)),
                )

    async def _update_ranges(self, drive_id: str, nodes: DriveNodes) -> None:
        """The EURange of the readings, once the drive's capabilities (its scale) change."""
        caps: Capabilities = self.hub.capabilities(drive_id)
        if self._caps.get(drive_id) is caps:
            return
        self._caps[drive_id] = caps
        if self.server is None:
            raise NotStarted("the OPC UA server is not started")
        write = self.server.iserver.aspace.write_attribute_value
        known = self._ranges[drive_id]
        for reading in READINGS:
            new = reading.range_of(caps)
            if known.get(reading.name) != new:
                known[reading.name] = new
                await write(
                    nodes.ranges[reading.name], ua.AttributeIds.Value, ua.DataValue(eu_range(new))
                )

    def _read_firmware(self) -> None:
        for drive_id in self.drives:
            if drive_id in self._firmware or not self.hub.state(drive_id).online:
                continue
            self._firmware[drive_id] = asyncio.create_task(self._firmware_of(drive_id))

    async def _firmware_of(self, drive_id: str) -> None:
        state = self.hub.state(drive_id)
        caps = self.hub.capabilities(drive_id)

        async def read(number: int, subindex: int) -> Any:
            return await self.hub.read_param(drive_id, number, subindex)

        try:
            firmware, source = await firmware_of(
                state.device.value,
                state.values,
                self.runtime.drive_diagnostics(drive_id),
                caps.params,
                read,
            )
        except Exception as exc:
            log.info("OPC UA: firmware of %s not read: %s", drive_id, exc)
            return
        if firmware is None:
            log.debug("OPC UA: no firmware for %s: %s", drive_id, source)
            return
        if self.server is None:
            raise NotStarted("the OPC UA server is not started")
        await self.server.iserver.aspace.write_attribute_value(
            self.drives[drive_id].properties["Firmware"],
            ua.AttributeIds.Value,
            ua.DataValue(ua.Variant(firmware, ua.VariantType.String)),
        )

    def _feed_watchdogs(self) -> None:
        """A drive controlled by an OPC UA session whose client still makes requests: its
        command watchdog is fed (only by that session: ``hub.refresh`` checks)."""
        if self.sessions is None:
            raise NotStarted("the OPC UA server is not started")
        now = time.monotonic()
        for drive_id in self.drives:
            desired = self.hub.desired(drive_id)
            if desired.source is not Source.OPCUA:
                continue
            session = self.sessions.get(desired.client)
            timeout = self.hub.policy(drive_id).command_timeout
            if session is None or timeout is None:
                continue
            if now - session.last_request < timeout:
                self.hub.refresh(drive_id, Source.OPCUA, desired.client)

    # ------------------------------------------------------------ figures

    def counted(self) -> FrontEndCounters:
        sessions = self.sessions
        return FrontEndCounters(
            requests={"call": self.calls},
            commands_accepted=self.commands.accepted,
            commands_refused=self.commands.refused,
            refused=self.refusals.by_reason(),
            connections_accepted=0 if sessions is None else sessions.opened,
            connections_over_limit=0 if sessions is None else sessions.refused,
            connections_open=0 if sessions is None else len(sessions),
        )

    def figures(self) -> Mapping[str, float]:
        """What the value batches cost: batches, variable writes, seconds spent."""
        return {
            "batches": self.batches,
            "writes": self.writes,
            "busy_s": self.busy,
            "stretched": self.stretched,
        }
