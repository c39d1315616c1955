"""What a change of a drive's readings makes the hub do (gateway/hub.py, safety rule 1;
docs/safety.md): the events it raises and the run command it clears; and the readings of
a drive that is not heard, which are unknown, never its last values.

The hub calls :func:`on_transitions` when one of :data:`TRANSITION_FIELDS` changed, with
its own ``event`` and a ``clear_run`` for the drive (rule 1: the desired run and jog are
cleared, and said in a ``safety`` event).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

from gateway.adapter import EventKind
from gateway.devices import code_text
from gateway.model import CommState, DriveState, DriveStatus

TRANSITION_FIELDS = frozenset(
    {
        "comm",
        "status",
        "alarm",
        "alarm_code",
        "fault_code",
        "local_control",
        "failsafe",
        "doubtful",
    }
)
"""Fields whose change may raise an event or clear run (rule 1)."""
_READY_STATUSES = frozenset(
    {DriveStatus.READY, DriveStatus.STARTING, DriveStatus.RUNNING, DriveStatus.STOPPING}
)
UNKNOWN_COMM = frozenset({CommState.OFFLINE, CommState.CONNECTING})
"""Comm states in which nothing the drive said is current: its readings are unknown."""
_UNKNOWN_READINGS: dict[str, Any] = {
    "status": DriveStatus.NOT_READY,
    "running": False,
    "at_reference": False,
    "alarm": False,
    "speed_rpm": None,
    "speed_pct": None,
    "current_a": None,
    "current_pct_flc": None,
    "motor_temp_pct": None,
    "power_kw": None,
    "voltage_v": None,
    "fault_code": None,
    "fault_text": None,
    "alarm_code": None,
}
"""What an offline or connecting drive publishes (docs/safety.md, "Offline drives"): never
its last values, which would show a drive that may have stopped, or started, as it was."""


class EventSink(Protocol):
    """The hub's ``event``."""

    def __call__(self, drive_id: str, kind: EventKind, text: str, **data: Any) -> None: ...


ClearRun = Callable[[str], None]
"""Clear the drive's desired run and jog, saying why (rule 1)."""


def mask_unknown(current: Mapping[str, Any], delta: dict[str, Any]) -> bool:
    """Put the unknown readings of an offline drive into ``delta``; True when one of
    them is a transition field that changes."""
    transition = False
    for name, value in _UNKNOWN_READINGS.items():
        if current[name] != value:
            delta[name] = value
            transition = transition or name in TRANSITION_FIELDS
        else:
            delta.pop(name, None)
    return transition


def on_transitions(
    drive_id: str,
    old: DriveState,
    new: DriveState,
    alarm_texts: Mapping[int, str],
    *,
    event: EventSink,
    clear_run: ClearRun,
) -> None:
    """The events and the run clearing of a change from ``old`` to ``new``."""
    if old.comm is not new.comm:
        event(drive_id, EventKind.COMM, f"comm {old.comm.value} -> {new.comm.value}")
        if new.comm is CommState.ONLINE:
            clear_run("drive came online")
        elif old.comm is CommState.ONLINE:
            # Rule 1, made structural: whatever the cause, a drive that comes back gets
            # no run from before the loss.
            clear_run(f"drive left online ({new.comm.value})")
    _on_trust_transitions(drive_id, old, new, event, clear_run)
    if new.comm in UNKNOWN_COMM:
        return  # no fault or alarm news from a drive that is not heard
    if new.status is DriveStatus.NOT_READY and old.status in _READY_STATUSES and old.online:
        # Rule 1: what made it not ready (a reset input opened, undervoltage, an enable
        # taken away) must not start it again by itself when it ends.
        clear_run("drive became not ready")
    if new.faulted and not old.faulted:
        kind = _fault_event(drive_id, new, event)
        clear_run(f"drive {kind.value}")
    elif new.faulted and new.fault_code is not None and new.fault_code != old.fault_code:
        # the code came after the fault (read over the bus later): the event with its text
        _fault_event(drive_id, new, event)
    if old.faulted and not new.faulted:
        event(drive_id, EventKind.FAULT, "fault cleared")
        # Rule 1: however the fault ended (keypad, auto-reset, power cycle, our reset)
        clear_run("fault ended")
    if new.alarm and (not old.alarm or new.alarm_code != old.alarm_code):
        known = alarm_texts.get(new.alarm_code) if new.alarm_code else None
        shown = "" if new.alarm_code is None else code_text(new.device, new.alarm_code)
        text = f"alarm {shown}".rstrip() + (f": {known}" if known else "")
        event(drive_id, EventKind.ALARM, text, code=new.alarm_code)


def _on_trust_transitions(
    drive_id: str, old: DriveState, new: DriveState, event: EventSink, clear_run: ClearRun
) -> None:
    """Local control, the drive's fail-safe reaction, doubtful readings (docs/safety.md)."""
    if new.local_control and not old.local_control:
        event(
            drive_id,
            EventKind.SAFETY,
            "drive in local control: it ignores the network's run commands; "
            "run commands are refused, stops are still sent",
        )
        clear_run("drive in local control")
    elif old.local_control and not new.local_control:
        event(drive_id, EventKind.CONTROL, "drive back in network control")
        clear_run("drive back in network control")
    if new.failsafe is False and old.failsafe is not False:
        event(
            drive_id,
            EventKind.SAFETY,
            "the drive keeps running if the gateway is lost: "
            + (new.failsafe_text or "no reaction to a lost master"),
            failsafe=False,
        )
    if new.doubtful and not old.doubtful:
        event(
            drive_id,
            EventKind.SAFETY,
            "readings doubtful: frames that contradict each other were heard for this "
            "drive; run commands are refused until its readings are consistent again",
        )
    elif old.doubtful and not new.doubtful:
        event(drive_id, EventKind.SAFETY, "readings consistent again")


def _fault_event(drive_id: str, new: DriveState, event: EventSink) -> EventKind:
    kind = EventKind.TRIP if new.status is DriveStatus.TRIPPED else EventKind.FAULT
    code = "" if new.fault_code is None else f" {code_text(new.device, new.fault_code)}"
    text = f": {new.fault_text}" if new.fault_text else ""
    event(drive_id, kind, f"{kind.value}{code}{text}", code=new.fault_code)
    return kind
