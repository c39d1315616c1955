"""The hub's hand-over to a line's own thread (gateway/runtime/lineport.py), step by step:
the hub's loop is played by the test, which runs what the port posts when it likes."""

from __future__ import annotations

from collections.abc import Callable

from gateway.adapter import EventKind
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState
from gateway.runtime.lineport import OUTBOX_EVENTS, LinePort


def rig() -> tuple[Hub, LinePort, list[Callable[[], None]]]:
    hub = Hub()
    hub.add_drive(DriveState(id="d", device=Device.CFW11, bus="b", address=1))
    posted: list[Callable[[], None]] = []
    return hub, LinePort(hub, posted.append), posted


def run(posted: list[Callable[[], None]]) -> None:
    calls, posted[:] = list(posted), []
    for call in calls:
        call()


def test_a_batch_is_posted_once_and_applied_in_order() -> None:
    hub, port, posted = rig()
    port.update("d", comm=CommState.ONLINE)
    port.update("d", speed_rpm=10.0)
    port.update("d", speed_rpm=20.0)  # merged into the one before: no transition between
    port.event("d", EventKind.BUS, "one")
    assert len(posted) == 1 and port.waiting == 3
    with hub.subscribe_events() as events:
        run(posted)
        texts = [e.text for e in events.drain()]
    assert texts == ["comm offline -> online", "one"]
    assert hub.state("d").speed_rpm == 20.0 and port.waiting == 0


def test_unchanged_readings_are_handed_over_once() -> None:
    hub, port, posted = rig()
    port.update("d", comm=CommState.ONLINE, speed_rpm=10.0)
    run(posted)
    seq = hub.state("d").seq
    for _ in range(100):
        port.update("d", comm=CommState.ONLINE, speed_rpm=10.0)
    assert posted == [] and port.waiting == 0 and hub.state("d").seq == seq


def test_readings_after_a_comm_change_are_handed_over_again() -> None:
    """The hub shows an offline drive's readings as unknown: the same speed heard again
    once it is back must reach the hub, though it equals the last one handed over."""
    hub, port, posted = rig()
    port.update("d", comm=CommState.ONLINE, speed_rpm=300.0)
    port.update("d", comm=CommState.OFFLINE)
    port.update("d", speed_rpm=300.0)  # a late reading, masked by the hub
    run(posted)
    assert hub.state("d").speed_rpm is None
    port.update("d", comm=CommState.ONLINE)
    port.update("d", speed_rpm=300.0)
    run(posted)
    assert hub.state("d").speed_rpm == 300.0


def test_events_beyond_the_outbox_bound_are_dropped_unless_never_dropped() -> None:
    hub, port, posted = rig()
    for i in range(OUTBOX_EVENTS + 10):
        port.event("d", EventKind.BUS, f"bus {i}")
    port.event("d", EventKind.FAULT, "a fault is never dropped")
    assert port.events_dropped == 10
    with hub.subscribe_events() as events:
        run(posted)
        kinds = [e.kind for e in events.drain()]
    assert kinds.count(EventKind.BUS) == OUTBOX_EVENTS and kinds[-1] is EventKind.FAULT
