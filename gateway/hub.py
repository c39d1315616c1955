"""The hub: latest state per drive, desired command per drive, arbitration, safety timers.

All methods run on the event loop's thread. Time comes from an injected
monotonic clock (watchdogs) and wall clock (timestamps), so the safety rules are
tested by stepping :meth:`Hub.tick` with a fake clock.

Safety rules (docs/architecture.md, "Safety rules"; docs/safety.md) enforced here:

1. No unintended start: a drive runs only on a run command given after the last
   of these: the gateway started; the drive came (back) online or left online; a
   fault or trip ended, however it ended; a quick stop or coast stop was given or
   released; control passed to another client, or to the drive's local control and
   back; the command watchdog acted. Each of these clears the desired ``run`` (and
   ``jog``). A run command that arrives while the drive is faulted or tripped, latched
   in quick stop or coast stop, not online, in local control, doubtful, or (with
   ``require_failsafe``) without a known fail-safe reaction is refused with the
   reason, never held for later. A stop is never refused: the stop part of a command
   is applied whatever else holds, and a stop kind the drive lacks becomes the nearest
   one it has. An offline drive's readings are unknown, never its last values.
2. Fault reset is an edge: each request bumps ``fault_reset_seq`` once.
3. Control belongs to a client (a source and the client's id within it: a Modbus
   peer address, the label of a Zenoh session id), not to a protocol. The command
   watchdog is fed only by the client in control; a client that stops refreshing
   within ``command_timeout`` gets ``on_command_timeout`` applied (ramp stop, coast,
   hold).

Every accepted command that changes the desired command is written to the log
and to the drive's events (the audit trail); repeated identical refusals are
logged once per client, reason and period, with a count (gateway/eventlog.py).
What a change of a drive's readings makes the hub do (the events, the run cleared,
the unknown readings of a drive not heard) is in gateway/transitions.py.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum
from functools import partial
from typing import Any, Protocol, Unpack

from gateway.adapter import Capabilities, Event, EventKind, ParamValue
from gateway.devices import code_text
from gateway.errors import (
    CommandRejected,
    DriveOffline,
    ParameterNotWritable,
    StopAppliedRestRefused,
    UnknownDrive,
)
from gateway.eventlog import EventLog
from gateway.model import (
    COMMAND_FIELDS,
    STATE_FIELDS,
    CommState,
    ControlMode,
    DesiredCommand,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    DriveUpdate,
    Source,
    StopAction,
)
from gateway.transitions import TRANSITION_FIELDS, UNKNOWN_COMM, mask_unknown, on_transitions

log = logging.getLogger(__name__)

Clock = Callable[[], float]
EVENT_QUEUE_LIMIT = 1000
_WATCHED = (Source.ZENOH, Source.MODBUS, Source.WEB, Source.OPCUA)
"""The client sources whose command in force the watchdog watches (rule 3)."""


@dataclass(frozen=True, slots=True)
class DrivePolicy:
    """The per-drive settings the hub enforces (from the drive's config)."""

    control: ControlMode = ControlMode.ANY
    command_timeout: float | None = None
    on_command_timeout: StopAction = StopAction.RAMP_STOP
    on_shutdown: StopAction = StopAction.RAMP_STOP
    writable_params: frozenset[int] = frozenset()
    writable_entries: frozenset[tuple[int, int]] = frozenset()
    """(number, subindex) pairs writable on their own (``"0x2000:1"``)."""
    modbus_unit: int | None = None
    require_failsafe: bool = False
    """Refuse run commands while the drive's own reaction to a lost master is not known to
    stop it (``failsafe`` not true; docs/safety.md)."""

    def writable(self, number: int, subindex: int = 0) -> bool:
        """Rule 5: the config allows writes to this parameter (and subindex)."""
        return number in self.writable_params or (number, subindex) in self.writable_entries


_STOP_FIELDS: dict[str, bool] = {
    "run": False,
    "jog": False,
    "quick_stop": True,
    "coast_stop": True,
}
"""The command fields, and their values, that ask for less motion: never refused."""
_HUB_FIELDS = frozenset({"seq", "ts", "control_source", "control_client"})
"""Fields the hub sets itself; an adapter's values for them are ignored."""


class ParamService(Protocol):
    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue: ...

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None: ...


@dataclass
class _Drive:
    state: DriveState
    policy: DrivePolicy
    desired: DesiredCommand
    caps: Capabilities
    last_refresh: float = 0.0
    watchdog_expired: bool = False
    params: ParamService | None = None
    substitutes_said: set[str] = field(default_factory=set)


class StateSubscription:
    """Conflating view of state changes: a slow reader sees the newest state of
    each drive, never an unbounded queue, and never misses the last one."""

    def __init__(self, hub: Hub, on_ready: Callable[[], None] | None = None) -> None:
        self._hub = hub
        self._pending: dict[str, DriveState] = {}
        self._ready = asyncio.Event()
        self._signal = self._ready.set if on_ready is None else on_ready

    def _offer(self, state: DriveState) -> None:
        pending = self._pending
        if not pending:  # else signalled already: get clears the event only when empty
            self._signal()
        pending[state.id] = state

    async def get(self) -> DriveState:
        while not self._pending:
            self._ready.clear()
            await self._ready.wait()
        drive_id = next(iter(self._pending))
        return self._pending.pop(drive_id)

    def drain(self) -> list[DriveState]:
        out = list(self._pending.values())
        self._pending.clear()
        return out

    def close(self) -> None:
        hub = self._hub
        hub._state_subs = tuple(s for s in hub._state_subs if s is not self)

    def __enter__(self) -> StateSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


NEVER_DROPPED = frozenset({EventKind.FAULT, EventKind.TRIP, EventKind.SAFETY, EventKind.COMM})
"""Event kinds a subscription never drops: a fault or trip, a safety action, a comm change."""


class EventSubscription:
    """A bounded queue of events, in order.

    When ``limit`` events wait, a new one is dropped and counted, unless its kind is
    in :data:`NEVER_DROPPED` (those are always queued: the drives make them, not the
    network). The next event queued after a drop carries ``dropped``: how many were
    lost before it (docs/zenoh-keys.md, "Session and delivery").
    """

    def __init__(self, hub: Hub, limit: int = EVENT_QUEUE_LIMIT) -> None:
        self._hub = hub
        self._limit = limit
        self._queue: collections.deque[Event] = collections.deque()
        self._ready = asyncio.Event()
        self.dropped = 0  # in all
        self._lost = 0  # since the last event queued

    def _offer(self, event: Event) -> None:
        if len(self._queue) >= self._limit and event.kind not in NEVER_DROPPED:
            self.dropped += 1
            self._lost += 1
            return
        if self._lost:
            event = replace(event, data={**event.data, "dropped": self._lost})
            self._lost = 0
        self._queue.append(event)
        self._ready.set()

    async def get(self) -> Event:
        while not self._queue:
            self._ready.clear()
            await self._ready.wait()
        return self._queue.popleft()

    def drain(self) -> list[Event]:
        out = list(self._queue)
        self._queue.clear()
        return out

    def close(self) -> None:
        self._hub._event_subs.discard(self)

    def __enter__(self) -> EventSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Hub:
    """Latest state and desired command of every drive, with the safety rules."""

    def __init__(self, clock: Clock = time.monotonic, wallclock: Clock = time.time) -> None:
        self._clock = clock
        self._wallclock = wallclock
        self._drives: dict[str, _Drive] = {}
        self._state_subs: tuple[StateSubscription, ...] = ()
        self._event_subs: set[EventSubscription] = set()
        self._seq = 0
        self._listeners: list[Callable[[str], None]] = []
        self._event_log = EventLog(log, clock, self._deliver_event)
        self.started = clock()
        self.shutting_down = False

    # ------------------------------------------------------------ drives

    def add_drive(self, state: DriveState, policy: DrivePolicy | None = None) -> None:
        if state.id in self._drives:
            raise ValueError(f"drive {state.id!r} added twice")
        # Rule 1: the gateway starts with every drive stopped.
        self._drives[state.id] = _Drive(
            state=state,
            policy=policy or DrivePolicy(),
            desired=DesiredCommand(),
            caps=Capabilities(),
        )

    def drive_ids(self) -> list[str]:
        return list(self._drives)

    def _drive(self, drive_id: str) -> _Drive:
        try:
            return self._drives[drive_id]
        except KeyError:
            raise UnknownDrive(f"no drive {drive_id!r}") from None

    def policy(self, drive_id: str) -> DrivePolicy:
        return self._drive(drive_id).policy

    def capabilities(self, drive_id: str) -> Capabilities:
        return self._drive(drive_id).caps

    def set_capabilities(self, drive_id: str, caps: Capabilities) -> None:
        self._drive(drive_id).caps = caps

    def attach_params(self, drive_ids: Iterable[str], service: ParamService) -> None:
        for drive_id in drive_ids:
            self._drive(drive_id).params = service

    def now(self) -> float:
        return self._clock()

    # ------------------------------------------------------------ state

    def state(self, drive_id: str) -> DriveState:
        return self._drive(drive_id).state

    def states(self) -> list[DriveState]:
        return [d.state for d in self._drives.values()]

    def update(self, drive_id: str, **changes: Unpack[DriveUpdate]) -> DriveState:
        """An adapter reports readings; returns the (possibly new) state.

        The names and types are checked by mypy (:class:`DriveUpdate`); a name that is no
        field of the state is still refused at run time (TypeError).

        Hot path: one pass keeps the readings that differ (``seq``, ``ts`` and
        ``control_source`` are the hub's own and ignored), the new state is built
        once, and seq grows only when a reading changed.
        """
        drv = self._drives.get(drive_id)
        if drv is None:
            raise UnknownDrive(f"no drive {drive_id!r}")
        old = drv.state
        current = old.__dict__  # its fields by name, and nothing else (DriveState.changed)
        delta: dict[str, Any] = {}
        transition = False
        try:
            for name, value in changes.items():
                if current[name] != value and name not in _HUB_FIELDS:
                    delta[name] = value
                    if name in TRANSITION_FIELDS:
                        transition = True
        except KeyError:
            unknown = sorted(changes.keys() - STATE_FIELDS)
            raise TypeError(f"DriveState has no field(s) {unknown}") from None
        if delta.get("comm", old.comm) in UNKNOWN_COMM:
            transition = mask_unknown(current, delta) or transition
        if not delta:
            return old
        self._seq += 1
        delta["seq"] = self._seq
        delta["ts"] = self._wallclock()
        desired = drv.desired
        if desired.source is not old.control_source:
            delta["control_source"] = desired.source
        client = desired.client or None
        if client != old.control_client:
            delta["control_client"] = client
        new = drv.state = old.changed(**delta)
        if transition:
            clear_run = partial(self._clear_run, drive_id, drv)
            alarm_texts = drv.caps.alarm_texts
            on_transitions(drive_id, old, new, alarm_texts, event=self.event, clear_run=clear_run)
        for sub in self._state_subs:
            sub._offer(drv.state)
        return drv.state

    def _commit(self, drv: _Drive, new: DriveState) -> DriveState:
        self._seq += 1
        new = new.changed(
            seq=self._seq,
            ts=self._wallclock(),
            control_source=drv.desired.source,
            control_client=drv.desired.client or None,
        )
        drv.state = new
        for sub in self._state_subs:
            sub._offer(new)
        return new

    def _clear_run(self, drive_id: str, drv: _Drive, why: str) -> None:
        if drv.desired.run or drv.desired.jog:
            drv.desired = replace(drv.desired, run=False, jog=False)
            self.event(drive_id, EventKind.SAFETY, f"run command cleared: {why}")
            self._notify_command(drive_id)

    def subscribe_states(self, on_ready: Callable[[], None] | None = None) -> StateSubscription:
        """A conflating view of state changes. Read it with ``get`` and ``drain``; or
        give ``on_ready``, called (synchronously, on the loop) when a state arrives while
        none is pending, and ``drain`` it from there."""
        sub = StateSubscription(self, on_ready)
        self._state_subs = (*self._state_subs, sub)
        return sub

    async def wait_for(self, drive_id: str, predicate: Callable[[DriveState], bool]) -> DriveState:
        """Wait until the drive's state satisfies ``predicate`` (tests, shutdown)."""
        state = self.state(drive_id)
        if predicate(state):
            return state
        with self.subscribe_states() as sub:
            while True:
                state = await sub.get()
                if state.id == drive_id and predicate(state):
                    return state

    # ------------------------------------------------------------ events

    def event(self, drive_id: str, kind: EventKind, text: str, **data: Any) -> None:
        """An event of a drive: logged and delivered to every subscription. A burst of
        identical events (the kind and text of the drive's event before it) is the first
        one at once, then one with ``repeats``, the count of those held back, once per
        window (:meth:`tick`) or just before the drive's next different event
        (gateway/eventlog.py); a different event is never held back."""
        ev = Event(drive_id=drive_id, kind=kind, text=text, ts=self._wallclock(), data=data)
        self._event_log.offer(ev)

    def _deliver_event(self, ev: Event) -> None:
        for sub in tuple(self._event_subs):
            sub._offer(ev)

    @property
    def events_folded(self) -> int:
        """Events held back as repeats of the one before them, in all (each is counted in
        the ``repeats`` of a later event)."""
        return self._event_log.folded

    def subscribe_events(self) -> EventSubscription:
        sub = EventSubscription(self)
        self._event_subs.add(sub)
        return sub

    # ------------------------------------------------------------ commands

    def desired(self, drive_id: str) -> DesiredCommand:
        return self._drive(drive_id).desired

    def on_command(self, listener: Callable[[str], None]) -> Callable[[], None]:
        """Call ``listener(drive_id)`` whenever a desired command changes; returns the
        call that ends it."""
        self._listeners.append(listener)

        def off() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)

        return off

    def _notify_command(self, drive_id: str) -> None:
        for listener in list(self._listeners):
            listener(drive_id)

    def check(self, drive_id: str, source: Source, cmd: DriveCommand, client: str = "") -> None:
        """Raise CommandRejected (with the reason) if ``cmd`` may not be applied.

        A command that only asks for less motion (:data:`_STOP_FIELDS`) is never refused.
        """
        drv = self._drive(drive_id)
        cmd = self._substituted(drive_id, drv, cmd, announce=False)
        if _stop_part(cmd) == cmd and not cmd.is_empty:
            return
        self._check(drive_id, drv, source, cmd)

    def _check(self, drive_id: str, drv: _Drive, source: Source, cmd: DriveCommand) -> None:
        if self.shutting_down:
            raise CommandRejected("the gateway is shutting down")
        if not drv.policy.control.admits(source):
            raise CommandRejected(
                f"drive {drive_id} takes commands from {drv.policy.control.value} only"
            )
        if drv.state.comm is not CommState.ONLINE:
            raise CommandRejected(f"drive {drive_id} is {drv.state.comm.value}")
        if cmd.run and cmd.fault_reset:
            raise CommandRejected("send run after the fault reset, not in the same command")
        if cmd.run or cmd.jog:
            _check_start(drive_id, drv, cmd)
        _check_capabilities(drv, cmd)

    def in_control(self, drive_id: str, source: Source, client: str = "") -> bool:
        """Whether this client is the one in control of the drive (rule 3)."""
        return self._drive(drive_id).desired.controller == (source, client)

    def submit(
        self, drive_id: str, source: Source, cmd: DriveCommand, client: str = ""
    ) -> DesiredCommand:
        """Apply a partial command from a northbound client, or raise CommandRejected.

        ``client`` tells apart the clients of one source (a Modbus peer address, a
        Zenoh session id). Nothing of a refused command is applied. An empty command
        is a keep-alive: it feeds the watchdog of the client in control and does
        nothing for any other client (it neither takes control nor feeds it).
        """
        who = _client_text(source, client)
        drv = self._drive(drive_id)
        cmd = self._substituted(drive_id, drv, cmd, announce=True)
        stop = _stop_part(cmd)
        if stop != cmd or cmd.is_empty:
            try:
                self._check(drive_id, drv, source, cmd)
            except CommandRejected as exc:
                self.event(
                    drive_id,
                    EventKind.COMMAND_REFUSED,
                    f"command from {who} refused: {exc.reason}",
                    source=source.value,
                    client=client,
                )
                if stop.is_empty:
                    raise
                # Rule 1: a command that asks for less motion is never refused because of
                # another field: its stop part is applied, the rest is not.
                self._apply(drive_id, drv, source, stop, client)
                fields_ = ", ".join(f"{k} {str(v).lower()}" for k, v in stop.to_json().items())
                raise StopAppliedRestRefused(
                    f"{fields_} applied; the rest of the command was refused: {exc.reason}"
                ) from None
        return self._apply(drive_id, drv, source, cmd, client)

    def _substituted(
        self, drive_id: str, drv: _Drive, cmd: DriveCommand, *, announce: bool
    ) -> DriveCommand:
        """``cmd`` with each stop kind the drive lacks replaced by the nearest one it has
        (``Capabilities.stop_substitutes``; a stop kind only listed as unsupported becomes a
        ramp stop). Said once per drive and kind in a ``safety`` event."""
        subs = _stop_substitutes(drv.caps)
        if not subs:
            return cmd
        changes: dict[str, Any] = {}
        for name, sub in subs.items():
            value = getattr(cmd, name)
            if value is None:
                continue
            changes[name] = None
            if value:
                changes.update({"run": False, "jog": False} if sub == "run" else {sub: True})
                if announce and name not in drv.substitutes_said:
                    drv.substitutes_said.add(name)
                    instead = "a ramp stop" if sub == "run" else sub
                    self.event(
                        drive_id,
                        EventKind.SAFETY,
                        f"{name} is not in the {drv.state.device.value}: {instead} applied instead",
                        substitute=sub,
                    )
            elif sub != "run" and getattr(cmd, sub) is None:
                changes[sub] = False
        return replace(cmd, **changes) if changes else cmd

    def _apply(
        self, drive_id: str, drv: _Drive, source: Source, cmd: DriveCommand, client: str
    ) -> DesiredCommand:
        who = _client_text(source, client)
        if cmd.is_empty:
            self.refresh(drive_id, source, client)
            return drv.desired
        old = drv.desired
        if not drv.policy.control.admits(source):
            return self._apply_outside_stop(drive_id, drv, who, cmd)
        base = old
        if old.controller != (source, client) and old.source is not Source.NONE:
            # Rule 1: control passes to another client -> run needs a new run command.
            base = replace(old, run=False, jog=False)
            self.event(
                drive_id,
                EventKind.CONTROL,
                f"control passed from {_client_text(old.source, old.client)} to {who}",
                source=source.value,
                client=client,
            )
        new = base.merged(cmd, source, client)
        if cmd.run is False and cmd.jog is None:
            new = replace(new, jog=False)  # a stop ends a jog too
        if cmd.fault_reset or new.quick_stop or new.coast_stop:
            # Rules 1 and 2: a reset is one edge and the drive does not restart by itself;
            # a quick stop or coast stop ends a run, and its release never restarts one.
            new = replace(new, run=False, jog=False)
        drv.desired = new
        drv.last_refresh = self._clock()
        drv.watchdog_expired = False
        if new != old:
            self._audit(drive_id, who, (source, client), old, new)
            self._notify_command(drive_id)
            if new.controller != (drv.state.control_source, drv.state.control_client or ""):
                self._commit(drv, drv.state)
        return new

    def _apply_outside_stop(
        self, drive_id: str, drv: _Drive, who: str, cmd: DriveCommand
    ) -> DesiredCommand:
        """A stop from a source the drive's ``control`` leaves out: applied (a stop is never
        refused), and control stays where it is (it feeds no watchdog either)."""
        old = drv.desired
        new = old.merged(cmd, old.source, old.client)
        if cmd.run is False and cmd.jog is None:
            new = replace(new, jog=False)
        if new.quick_stop or new.coast_stop:
            new = replace(new, run=False, jog=False)
        drv.desired = new
        if new != old:
            self._audit(drive_id, who, (old.source, old.client), old, new)
            self._notify_command(drive_id)
        return new

    def _audit(
        self,
        drive_id: str,
        who: str,
        controller: tuple[Source, str],
        old: DesiredCommand,
        new: DesiredCommand,
    ) -> None:
        """The audit trail: one log line and one event per command that changed something."""
        changes = _command_changes(old, new)
        text = f"command from {who} accepted: " + (
            ", ".join(f"{name} {before} -> {after}" for name, before, after in changes)
            or "takes control"
        )
        self.event(
            drive_id,
            EventKind.COMMAND,
            text,
            source=controller[0].value,
            client=controller[1],
            changes={name: after for name, _before, after in changes},
        )

    def refresh(self, drive_id: str, source: Source, client: str = "") -> None:
        """A keep-alive: it feeds the command watchdog only when it comes from the
        client in control (rule 3); from any other client it does nothing."""
        drv = self._drive(drive_id)
        if drv.desired.controller == (source, client):
            drv.last_refresh = self._clock()
            drv.watchdog_expired = False

    # ------------------------------------------------------------ timers

    def tick(self) -> None:
        """Run the safety timers (rule 3); call it periodically."""
        now = self._clock()
        for drive_id, drv in self._drives.items():
            self._check_watchdog(drive_id, drv, now)
        self._event_log.flush()

    def _check_watchdog(self, drive_id: str, drv: _Drive, now: float) -> None:
        timeout = drv.policy.command_timeout
        source = drv.desired.source
        if timeout is None or drv.watchdog_expired or source not in _WATCHED:
            return
        if now - drv.last_refresh < timeout:
            return
        drv.watchdog_expired = True
        action = drv.policy.on_command_timeout
        who = _client_text(source, drv.desired.client)
        self.apply_stop(drive_id, action, f"no command from {who} for {timeout:g} s")

    def apply_stop(self, drive_id: str, action: StopAction, why: str) -> None:
        """A safety action of the gateway: stop (or hold) the drive."""
        drv = self._drive(drive_id)
        old = drv.desired
        new = old.stopped(action, Source.GATEWAY)
        if action is StopAction.HOLD:
            new = replace(new, source=Source.GATEWAY)
        drv.desired = new
        self.event(
            drive_id, EventKind.SAFETY, f"{why}: {action.value} applied", action=action.value
        )
        if new != old:
            self._notify_command(drive_id)
            self._commit(drv, drv.state)

    def apply_shutdown(self) -> None:
        """Rule 4, first half: every drive gets its ``on_shutdown`` action.

        From here on every command is refused, so nothing restarts a drive while
        the gateway waits for the drives to stop.
        """
        self.shutting_down = True
        for drive_id, drv in self._drives.items():
            self.apply_stop(drive_id, drv.policy.on_shutdown, "gateway shutting down")

    def all_stopped(self) -> bool:
        """True when no online drive that is to be stopped is still turning."""
        return all(
            not (d.state.online and d.state.running) or d.desired.run for d in self._drives.values()
        )

    # ------------------------------------------------------------ parameters

    def _param_service(self, drive_id: str) -> ParamService:
        drv = self._drive(drive_id)
        if drv.params is None:
            raise DriveOffline(f"drive {drive_id} has no parameter service")
        return drv.params

    async def read_param(self, drive_id: str, number: int, subindex: int = 0) -> ParamValue:
        return await self._param_service(drive_id).read_param(drive_id, number, subindex)

    async def write_param(
        self, drive_id: str, number: int, value: ParamValue, subindex: int = 0
    ) -> None:
        drv = self._drive(drive_id)
        if not drv.policy.writable(number, subindex):
            # Rule 5: writes only to the parameters the drive's config allows.
            where = f"{number}.{subindex}" if subindex else f"{number}"
            raise ParameterNotWritable(
                f"parameter {where} is not in writable_params of drive {drive_id}"
            )
        await self._param_service(drive_id).write_param(drive_id, number, subindex, value)
        self.event(drive_id, EventKind.PARAMETER, f"parameter {number}.{subindex} written: {value}")

    # ------------------------------------------------------------ views

    def snapshot(self) -> Mapping[str, DriveState]:
        return {k: d.state for k, d in self._drives.items()}


def _client_text(source: Source, client: str) -> str:
    """How logs and events name a client: ``modbus 10.0.0.5``, ``zenoh <session id>``."""
    return f"{source.value} {client}" if client else source.value


def _check_start(drive_id: str, drv: _Drive, cmd: DriveCommand) -> None:
    """Rule 1: a run or jog command is refused, never held, while the drive may not start."""
    state = drv.state
    _check_trust(drive_id, drv)
    if drv.caps.run_needs_ready and state.status is DriveStatus.NOT_READY:
        raise CommandRejected(
            f"drive {drive_id} is not ready: send the run command when it is ready "
            "(a run given now would not be kept for later)"
        )
    if state.faulted:
        code = "" if state.fault_code is None else f" {code_text(state.device, state.fault_code)}"
        text = f" ({state.fault_text})" if state.fault_text else ""
        raise CommandRejected(
            f"drive {drive_id} is {state.status.label}{code}{text}: "
            "reset the fault, then send a new run command"
        )
    desired = drv.desired
    for latch in ("quick_stop", "coast_stop"):
        wanted = getattr(cmd, latch)
        if wanted:
            raise CommandRejected(f"run and {latch} in one command: a stop wins; send one")
        if getattr(desired, latch):
            if wanted is False:
                raise CommandRejected(f"send run after releasing {latch}, in a command of its own")
            raise CommandRejected(
                f"drive {drive_id} is latched in {latch}: release it ({latch} false), "
                "then send a new run command"
            )


def _check_capabilities(drv: _Drive, cmd: DriveCommand) -> None:
    """What the drive cannot do (its capabilities): unsupported fields, reverse, speed."""
    for name, reason in drv.caps.unsupported.items():
        value = getattr(cmd, name, None)
        if value not in (None, False):
            raise CommandRejected(reason)
    no_reverse = drv.caps.reverse_refused
    if no_reverse is not None:
        if cmd.direction is Direction.REVERSE:
            raise CommandRejected(f"direction reverse: {no_reverse}")
        for name in ("speed_rpm", "speed_pct"):
            value = getattr(cmd, name)
            if value is not None and value < 0:
                raise CommandRejected(f"{name} {value:g} asks for reverse: {no_reverse}")
    scale = drv.caps.speed_scale
    if cmd.has_speed and scale is None:
        raise CommandRejected(f"{drv.state.device.value} has no speed reference")
    if scale is None:
        return
    if cmd.speed_rpm is not None and abs(cmd.speed_rpm) > scale.max_rpm + 1e-9:
        raise CommandRejected(
            f"speed_rpm {cmd.speed_rpm:g} is beyond the drive's scale (±{scale.max_rpm:g} rpm)"
        )
    if cmd.speed_pct is not None and abs(cmd.speed_pct) > scale.max_pct + 1e-9:
        raise CommandRejected(
            f"speed_pct {cmd.speed_pct:g} is beyond the drive's scale (±{scale.max_pct:g} %)"
        )


def _check_trust(drive_id: str, drv: _Drive) -> None:
    """Local control, doubtful readings, a required fail-safe reaction (docs/safety.md)."""
    state = drv.state
    if state.local_control:
        raise CommandRejected(
            f"drive {drive_id} is in local control: it ignores the network's run commands; "
            "switch it to remote (network) control, then send a new run command"
        )
    if state.doubtful:
        raise CommandRejected(
            f"drive {drive_id}'s readings are doubtful: frames that contradict each other "
            "were heard for it on its bus (see its events)"
        )
    if drv.policy.require_failsafe and state.failsafe is not True:
        what = state.failsafe_text or "unknown"
        raise CommandRejected(
            f"drive {drive_id} has no known fail-safe reaction to a lost master ({what}) "
            "and its config requires one (require_failsafe)"
        )


def _stop_part(cmd: DriveCommand) -> DriveCommand:
    """The fields of ``cmd`` that ask for less motion (:data:`_STOP_FIELDS`), alone."""
    return DriveCommand(
        **{name: value for name, value in _STOP_FIELDS.items() if getattr(cmd, name) is value}
    )


def _stop_substitutes(caps: Capabilities) -> dict[str, str]:
    subs = dict(caps.stop_substitutes)
    for name in ("quick_stop", "coast_stop"):
        if name in caps.unsupported:
            subs.setdefault(name, "run")
    return subs


_AUDITED = (*(n for n in COMMAND_FIELDS if n != "fault_reset"), "fault_reset_seq")


def _command_changes(old: DesiredCommand, new: DesiredCommand) -> list[tuple[str, Any, Any]]:
    """The fields a command changed, with their JSON values before and after."""
    out: list[tuple[str, Any, Any]] = []
    for name in _AUDITED:
        before, after = getattr(old, name), getattr(new, name)
        if before != after:
            if name == "fault_reset_seq":
                out.append(("fault_reset", False, True))
                continue
            out.append((name, _plain(before), _plain(after)))
    return out


def _plain(value: Any) -> Any:
    return value.value if isinstance(value, Enum) else value
