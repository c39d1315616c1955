"""Faults and trips as OPC UA alarms (Alarms & Conditions, AlarmConditionType events).

Each drive has one condition, its FaultAlarm object. :class:`AlarmState` is the
condition's state machine, stepped by the drive's states and by Acknowledge (sans-IO):

- the drive faults or trips: the alarm becomes active and unacknowledged (Retain true),
  with the fault code and the device's text in its Message;
- the fault ends (reset, keypad, power cycle): the alarm becomes inactive; it is retained
  until acknowledged;
- Acknowledge(EventId, Comment) of the newest event: acknowledged; an older EventId gets
  BadEventIdUnknown, a second acknowledgement BadConditionBranchAlreadyAcked.

Every change is an event on the Server object (where SCADA alarm clients subscribe) with
the drive object as SourceNode and the FaultAlarm object as ConditionId; ConditionRefresh
replays the retained ones (asyncua keeps them). asyncua gives event types and the
refresh, not a condition engine: the rest is here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from asyncua import Server, ua

from gateway.model import DriveState

SEVERITY_FAULT = 800
SEVERITY_CLEARED = 200


@dataclass(frozen=True, slots=True)
class AlarmState:
    """One drive's fault condition."""

    active: bool = False
    acked: bool = True
    code: int | None = None
    text: str = ""
    event_id: bytes = b""

    @property
    def retain(self) -> bool:
        return self.active or not self.acked

    @property
    def message(self) -> str:
        code = "" if self.code is None else f" {self.code}"
        what = f"fault{code}" + (f": {self.text}" if self.text else "")
        if self.active:
            return what
        return f"{what} (cleared)"

    def stepped(self, state: DriveState) -> AlarmState | None:
        """The condition after the drive's new state; None when it does not change."""
        if state.faulted:
            code, text = state.fault_code, state.fault_text or ""
            if self.active and (code, text) == (self.code, self.text):
                return None
            return AlarmState(active=True, acked=False, code=code, text=text)
        if self.active:
            return replace(self, active=False)
        return None

    def acknowledged(self, event_id: bytes) -> AlarmState | int:
        """The condition once acknowledged, or the Bad status code of the refusal."""
        if not self.event_id or event_id != self.event_id:
            return int(ua.StatusCodes.BadEventIdUnknown)
        if self.acked:
            return int(ua.StatusCodes.BadConditionBranchAlreadyAcked)
        return replace(self, acked=True)


Trigger = Callable[[str, AlarmState, str], Any]


class Alarms:
    """The drives' fault conditions on one server: events out, Acknowledge in."""

    def __init__(
        self, server: Server, sources: dict[str, ua.NodeId], conditions: dict[str, ua.NodeId]
    ) -> None:
        self.server = server
        self.sources = sources
        self.conditions = conditions
        self.by_condition = {node: d for d, node in conditions.items()}
        self.states: dict[str, AlarmState] = {}
        self._generators: dict[str, Any] = {}
        self.raised = 0
        self.acknowledged = 0

    async def on_state(self, state: DriveState) -> None:
        current = self.states.get(state.id, AlarmState())
        new = current.stepped(state)
        if new is not None:
            await self._emit(state.id, new, "")

    async def acknowledge(
        self, condition: ua.NodeId, event_id: bytes, comment: str, client: str
    ) -> int:
        drive_id = self.by_condition.get(condition)
        if drive_id is None:
            return int(ua.StatusCodes.BadNodeIdUnknown)
        outcome = self.states.get(drive_id, AlarmState()).acknowledged(event_id)
        if isinstance(outcome, int):
            return outcome
        self.acknowledged += 1
        await self._emit(
            drive_id, outcome, f"acknowledged by {client}" + (f": {comment}" if comment else "")
        )
        return int(ua.StatusCodes.Good)

    async def _generator(self, drive_id: str) -> Any:
        gen = self._generators.get(drive_id)
        if gen is None:
            gen = await self.server.get_event_generator(
                ua.ObjectIds.AlarmConditionType, ua.ObjectIds.Server
            )
            ev = gen.event
            ev.SourceNode = self.sources[drive_id]
            ev.SourceName = drive_id
            ev.NodeId = self.conditions[drive_id]
            ev.ConditionName = "FaultAlarm"
            self._generators[drive_id] = gen
        return gen

    async def _emit(self, drive_id: str, alarm: AlarmState, comment: str) -> None:
        gen = await self._generator(drive_id)
        ev = gen.event
        ev.Severity = SEVERITY_FAULT if alarm.active else SEVERITY_CLEARED
        ev.Retain = alarm.retain
        ev.ActiveState = ua.LocalizedText("Active" if alarm.active else "Inactive")
        setattr(ev, "ActiveState/Id", alarm.active)
        ev.AckedState = ua.LocalizedText("Acknowledged" if alarm.acked else "Unacknowledged")
        setattr(ev, "AckedState/Id", alarm.acked)
        ev.EnabledState = ua.LocalizedText("Enabled")
        setattr(ev, "EnabledState/Id", True)
        ev.Comment = ua.LocalizedText(comment)
        await gen.trigger(message=f"{drive_id}: {alarm.message}")
        event_id = ev.EventId.Value if isinstance(ev.EventId, ua.Variant) else ev.EventId
        self.states[drive_id] = replace(alarm, event_id=bytes(event_id))
        if alarm.active and not alarm.acked and comment == "":
            self.raised += 1
