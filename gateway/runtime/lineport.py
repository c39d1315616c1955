"""The hub as a line's own thread sees it: bounded hand-overs that never block either side.

A line runs on an event loop of its own (:mod:`gateway.runtime.linethread`); the hub and the
front ends run on the daemon's loop. :class:`LinePort` is the adapter's
:class:`~gateway.adapter.HubPort` on the line's side:

- **readings out**: ``update``, ``event`` and ``set_capabilities`` go into an outbox the
  daemon's loop applies to the hub in order (:meth:`LinePort.flush`, scheduled once per
  batch with ``call_soon_threadsafe``). Consecutive updates of one drive that change no
  transition field are merged into one, so a stalled daemon loop holds at most one update
  per drive between transitions; events beyond :data:`OUTBOX_EVENTS` waiting are dropped
  and counted unless their kind is one the hub never drops.
- **the desired command in**: ``desired`` reads the hub's latest command (one attribute
  read of a frozen value: no lock, no wait).

Safety rule 1 across the hand-over (docs/architecture.md, docs/safety.md): the hub clears
the desired run and jog on some transitions (a drive coming online or leaving it, not
ready, a fault, local control). Between the line reporting such a transition and the hub
applying it, the hub's command is older than the line's readings: the port works out the
same transitions on a shadow of the transition fields it reported
(:func:`gateway.transitions.on_transitions`, the hub's own rules) and, until the hub has
applied that report, gives the line the desired command with run and jog cleared. The line
never sends a run the hub would have cleared.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, Unpack

from gateway.adapter import Capabilities, EventKind
from gateway.hub import NEVER_DROPPED, Hub
from gateway.model import DesiredCommand, DriveState, DriveUpdate
from gateway.transitions import TRANSITION_FIELDS, UNKNOWN_COMM, mask_unknown, on_transitions

log = logging.getLogger(__name__)

OUTBOX_EVENTS = 1000
"""Events waiting in one line's outbox beyond which droppable kinds are dropped (counted)."""

Post = Callable[[Callable[[], None]], object]
"""Run a callable on the hub's loop soon, from any thread (``loop.call_soon_threadsafe``)."""


@dataclass(slots=True)
class _Update:
    drive_id: str
    changes: dict[str, Any]
    transition: bool


@dataclass(frozen=True, slots=True)
class _Event:
    drive_id: str
    kind: EventKind
    text: str
    data: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class _Caps:
    drive_id: str
    caps: Capabilities


_Item = _Update | _Event | _Caps


class Transition(Enum):
    """What one update changes of the transition fields, as the hub will see it."""

    NONE = "none"
    CHANGE = "change"
    CLEARS_RUN = "clears_run"


def _ignore_event(drive_id: str, kind: EventKind, text: str, **data: Any) -> None:
    """The event sink of the shadow transitions: the hub raises the real ones."""


def transition_delta(current: DriveState, changes: dict[str, Any]) -> dict[str, Any]:
    """The transition fields ``changes`` changes in ``current``, as the hub's update sees
    them (an offline or connecting drive's readings unknown: :func:`mask_unknown`)."""
    fields = current.__dict__
    delta = {k: v for k, v in changes.items() if k in TRANSITION_FIELDS and fields[k] != v}
    if delta.get("comm", current.comm) in UNKNOWN_COMM:
        mask_unknown(fields, delta)
    return delta


def clears_run(old: DriveState, new: DriveState) -> bool:
    """Whether the hub clears the desired run and jog going from ``old`` to ``new``."""
    cleared: list[str] = []
    on_transitions(old.id, old, new, {}, event=_ignore_event, clear_run=cleared.append)
    return bool(cleared)


class LinePort:
    """An adapter's hub port on its line's thread (see the module's docstring)."""

    def __init__(self, hub: Hub, post: Post) -> None:
        self._hub = hub
        self._post = post
        self._lock = threading.Lock()  # held for an append or a list swap, nothing else
        self._outbox: list[_Item] = []
        self._events_waiting = 0
        self._posted = 0  # number of the last item put into the outbox
        self._applied = 0  # number of the last item the hub applied (written by flush)
        self._shadow: dict[str, DriveState] = {}
        self._guard: dict[str, int] = {}  # drive -> item number the hub must apply first
        self._sent: dict[str, dict[str, Any]] = {}  # the readings last handed over, by drive
        self.events_dropped = 0
        self.flushes = 0

    # ------------------------------------------------------------ the line's side

    def state(self, drive_id: str) -> DriveState:
        return self._hub.state(drive_id)

    def now(self) -> float:
        return self._hub.now()

    def on_command(self, listener: Callable[[str], None]) -> Callable[[], None]:
        """``listener(drive_id)`` on the calling (the line's) loop whenever the hub changed a
        desired command; the relay is registered at once (a list append), so no change
        made after this call is missed."""
        loop = asyncio.get_running_loop()

        def relay(drive_id: str) -> None:  # on the hub's loop
            with contextlib.suppress(RuntimeError):  # the line's loop has closed
                loop.call_soon_threadsafe(listener, drive_id)

        return self._hub.on_command(relay)

    def desired(self, drive_id: str) -> DesiredCommand:
        desired = self._hub.desired(drive_id)
        guard = self._guard.get(drive_id)
        if guard is None:
            return desired
        if self._applied >= guard:
            del self._guard[drive_id]
            return desired
        if desired.run or desired.jog:
            return replace(desired, run=False, jog=False)
        return desired

    def update(self, drive_id: str, **changes: Unpack[DriveUpdate]) -> DriveState:
        """Hand over the readings that differ from those last handed over (none: nothing
        to do, the steady state of a line); returns the state as the hub last committed
        it. A comm change hands everything over afresh: the hub shows an offline drive's
        readings as unknown, so what was handed over before says nothing of its state."""
        items = self._new_readings(drive_id, changes)
        if not items:
            return self._hub.state(drive_id)
        transition = self._shadow_update(drive_id, items)
        with self._lock:
            self._posted += 1
            last = self._outbox[-1] if self._outbox else None
            if (
                transition is Transition.NONE
                and isinstance(last, _Update)
                and last.drive_id == drive_id
                and not last.transition
            ):
                last.changes.update(items)
            else:
                self._outbox.append(_Update(drive_id, items, transition is not Transition.NONE))
            first = len(self._outbox) == 1
            posted = self._posted
        if transition is Transition.CLEARS_RUN:
            self._guard[drive_id] = posted
        if first:
            self._post(self.flush)
        return self._hub.state(drive_id)

    def _new_readings(self, drive_id: str, changes: Mapping[str, Any]) -> dict[str, Any]:
        sent = self._sent.get(drive_id)
        if sent is None or ("comm" in changes and changes["comm"] != sent.get("comm")):
            self._sent[drive_id] = dict(changes)
            return dict(changes)
        items = {k: v for k, v in changes.items() if k not in sent or sent[k] != v}
        sent.update(items)
        return items

    def event(self, drive_id: str, kind: EventKind, text: str, **data: Any) -> None:
        self._put(_Event(drive_id, kind, text, data), event=True)

    def set_capabilities(self, drive_id: str, caps: Capabilities) -> None:
        self._put(_Caps(drive_id, caps))

    def _put(self, item: _Item, event: bool = False) -> None:
        with self._lock:
            if (
                event
                and self._events_waiting >= OUTBOX_EVENTS
                and isinstance(item, _Event)
                and item.kind not in NEVER_DROPPED
            ):
                self.events_dropped += 1
                return
            self._posted += 1
            self._outbox.append(item)
            self._events_waiting += event
            first = len(self._outbox) == 1
        if first:
            self._post(self.flush)

    def _shadow_update(self, drive_id: str, changes: dict[str, Any]) -> Transition:
        old = self._shadow.get(drive_id)
        if old is None:
            old = self._shadow[drive_id] = self._hub.state(drive_id)
        delta = transition_delta(old, changes)
        if not delta:
            return Transition.NONE
        new = self._shadow[drive_id] = old.changed(**delta)
        return Transition.CLEARS_RUN if clears_run(old, new) else Transition.CHANGE

    # ------------------------------------------------------------ the hub's side

    def flush(self) -> None:
        """Apply what the line handed over, in order (on the hub's loop)."""
        with self._lock:
            items, self._outbox = self._outbox, []
            self._events_waiting = 0
            last = self._posted
        self.flushes += 1
        hub = self._hub
        for item in items:
            try:
                _APPLY[type(item)](hub, item)
            except Exception:
                log.exception("applying %r from a line failed", item)
        self._applied = last

    @property
    def waiting(self) -> int:
        """Items handed over and not yet applied."""
        return len(self._outbox)


def _apply_update(hub: Hub, item: Any) -> None:
    hub.update(item.drive_id, **item.changes)


def _apply_event(hub: Hub, item: Any) -> None:
    hub.event(item.drive_id, item.kind, item.text, **item.data)


def _apply_caps(hub: Hub, item: Any) -> None:
    hub.set_capabilities(item.drive_id, item.caps)


_APPLY: dict[type, Callable[[Hub, Any], None]] = {
    _Update: _apply_update,
    _Event: _apply_event,
    _Caps: _apply_caps,
}
