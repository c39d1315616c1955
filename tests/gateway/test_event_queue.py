"""Issue 18: a subscriber's event queue is bounded, says what it lost, and never
drops a fault, a trip, a safety action or a comm change."""

from __future__ import annotations

from gateway.adapter import EventKind
from gateway.hub import NEVER_DROPPED, EventSubscription
from gateway.model import DriveStatus
from tests.gateway.test_hub import make_hub


def test_a_full_queue_drops_and_the_next_event_says_how_many() -> None:
    hub, _ = make_hub()
    sub = EventSubscription(hub, limit=3)
    hub._event_subs.add(sub)
    for i in range(10):
        hub.event("d", EventKind.COMMAND_REFUSED, f"refused {i}")
    assert [e.text for e in sub.drain()] == ["refused 0", "refused 1", "refused 2"]
    assert sub.dropped == 7
    hub.event("d", EventKind.COMMAND_REFUSED, "refused 10")
    (after,) = sub.drain()
    assert after.text == "refused 10" and after.data["dropped"] == 7
    hub.event("d", EventKind.COMMAND_REFUSED, "refused 11")
    assert "dropped" not in sub.drain()[0].data  # counted once


def test_a_fault_is_queued_even_when_the_queue_is_full() -> None:
    hub, _ = make_hub()
    sub = EventSubscription(hub, limit=2)
    hub._event_subs.add(sub)
    for i in range(5):
        hub.event("d", EventKind.COMMAND_REFUSED, f"refused {i}")
    hub.update("d", status=DriveStatus.FAULTED, fault_code=70)  # a fault, a safety line
    events = sub.drain()
    kinds = [e.kind for e in events]
    assert kinds[:2] == [EventKind.COMMAND_REFUSED, EventKind.COMMAND_REFUSED]
    fault = next(e for e in events if e.kind is EventKind.FAULT)
    assert fault.data["dropped"] == 3  # the first event queued after the drops says so
    assert {EventKind.FAULT, EventKind.TRIP, EventKind.SAFETY, EventKind.COMM} <= NEVER_DROPPED
