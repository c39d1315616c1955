"""The recorder takes the hub's states and events without ever waiting for the file: a
writer that falls behind has samples refused and counted, never the hub held up."""

from __future__ import annotations

from pathlib import Path

from gateway.adapter import EventKind
from gateway.config import HistorySection
from gateway.history.recorder import HistoryRecorder, history_event
from gateway.history.store import samples_of
from gateway.history.writer import HistoryWriter, Retention
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState, DriveStatus


def hub_of(*drives: str) -> Hub:
    hub = Hub()
    for i, drive in enumerate(drives):
        hub.add_drive(DriveState(id=drive, device=Device.TEST, bus="line", address=i + 1))
    return hub


def test_a_full_queue_drops_and_counts_instead_of_waiting(tmp_path: Path) -> None:
    hub = hub_of("d1", "d2", "off")
    for drive in ("d1", "d2"):
        hub.update(drive, comm=CommState.ONLINE, status=DriveStatus.READY, speed_rpm=10.0)
    recorder = HistoryRecorder(hub, HistorySection(enabled=True, path=tmp_path / "h.sqlite"))
    recorder.writer = HistoryWriter(tmp_path / "h.sqlite", Retention(1e9, 1 << 30), limit=2)
    for _ in range(5):  # the writer thread is not even started: nothing takes the queue
        recorder.sample()
    counters = recorder.writer.counters
    assert counters.samples_dropped == 3 * 2  # three samplings of the two online drives
    assert recorder.writer.waiting == 2


def test_an_offline_drive_gives_no_sample_and_events_keep_their_fields() -> None:
    hub = hub_of("d1")
    assert samples_of(0.0, hub.states()) == []
    hub.update("d1", comm=CommState.ONLINE, speed_rpm=5.0)
    (sample,) = samples_of(1.0, hub.states())
    assert (sample.drive_id, sample.t, sample.values[0]) == ("d1", 1.0, 5.0)
    with hub.subscribe_events() as events:
        hub.event("d1", EventKind.FAULT, "F021 undervoltage", code=21)
        (ev,) = events.drain()
    kept = history_event(ev)
    assert (kept.drive_id, kept.kind, kept.text, kept.data) == (
        "d1",
        "fault",
        "F021 undervoltage",
        {"code": 21},
    )
