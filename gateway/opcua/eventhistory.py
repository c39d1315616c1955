"""A stored event as OPC UA gives it back in a HistoryRead of events.

Each event of the history store becomes a BaseEventType event with the standard fields a
client selects (EventId, EventType, SourceNode, SourceName, Time, ReceiveTime, Message,
Severity) and the gateway's own kind (``Kind``, the ``kind`` of the Zenoh events key). The
EventId is derived from the event itself, so the same event read twice has the same id.
Severity follows the kind (:data:`SEVERITIES`): a fault or trip as the live alarm has it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from datetime import UTC, datetime, timedelta
from typing import Any, Final, Protocol

from asyncua import ua
from asyncua.common.events import Event

from gateway.opcua.alarms import SEVERITY_FAULT

SEVERITIES: Final[Mapping[str, int]] = {
    "fault": SEVERITY_FAULT,
    "trip": SEVERITY_FAULT,
    "safety": 700,
    "alarm": 600,
    "comm": 500,
    "bus": 400,
    "command_refused": 400,
    "config": 300,
    "parameter": 300,
    "control": 200,
    "command": 200,
}
"""OPC UA severity (1-1000) by the gateway's event kind."""
OTHER_SEVERITY: Final = 300
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


class HistoryEventLike(Protocol):
    """One stored event: wall-clock seconds, its drive, kind and text."""

    @property
    def t(self) -> float: ...

    @property
    def drive_id(self) -> str: ...

    @property
    def kind(self) -> str: ...

    @property
    def text(self) -> str: ...


def event_id(e: HistoryEventLike) -> bytes:
    """16 bytes naming the event (the same on every read)."""
    key = f"{e.t!r}\x00{e.drive_id}\x00{e.kind}\x00{e.text}"
    return hashlib.sha256(key.encode("utf-8", "surrogatepass")).digest()[:16]


def history_event(e: HistoryEventLike, source: ua.NodeId) -> Any:
    """``e`` as asyncua's Event, emitted by ``source`` (its drive's object)."""
    when = _EPOCH + timedelta(seconds=e.t)
    ev = Event(source)
    fields: tuple[tuple[str, Any, ua.VariantType], ...] = (
        ("EventId", event_id(e), ua.VariantType.ByteString),
        ("EventType", ua.NodeId(ua.ObjectIds.BaseEventType), ua.VariantType.NodeId),
        ("SourceNode", source, ua.VariantType.NodeId),
        ("SourceName", e.drive_id, ua.VariantType.String),
        ("Time", when, ua.VariantType.DateTime),
        ("ReceiveTime", when, ua.VariantType.DateTime),
        ("Message", ua.LocalizedText(f"{e.drive_id}: {e.text}"), ua.VariantType.LocalizedText),
        ("Severity", SEVERITIES.get(e.kind, OTHER_SEVERITY), ua.VariantType.UInt16),
        ("Kind", e.kind, ua.VariantType.String),
    )
    for name, value, kind in fields:
        ev.add_property(name, value, kind)
    return ev
