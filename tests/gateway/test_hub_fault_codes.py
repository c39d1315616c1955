"""Fault and alarm events carry the device's meaning: a fault code the drive gives only
later (read over the bus after the status word said "fault") gets its own event, and an
alarm event names the alarm's text from the adapter's table."""

from __future__ import annotations

from gateway.adapter import Capabilities, EventKind
from gateway.hub import DrivePolicy, Hub
from gateway.model import CommState, Device, DriveState, DriveStatus


def test_a_fault_code_that_comes_later_gets_its_own_event() -> None:
    hub = Hub(clock=lambda: 0.0, wallclock=lambda: 0.0)
    hub.add_drive(DriveState(id="d", device=Device.CFW320, bus="b", address=5), DrivePolicy())
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY)
    with hub.subscribe_events() as sub:
        hub.update("d", status=DriveStatus.FAULTED)  # the status word's fault bit only
        hub.update("d", fault_code=32, fault_text="Comm. plug-in module communication lost")
        hub.update("d", current_a=0.0)  # other readings while faulted: no new fault event
        hub.update("d", status=DriveStatus.READY, fault_code=None, fault_text=None)
        faults = [(e.text, e.data) for e in sub.drain() if e.kind is EventKind.FAULT]
    assert faults == [
        ("fault", {"code": None}),
        ("fault 32: Comm. plug-in module communication lost", {"code": 32}),
        ("fault cleared", {}),
    ]


def test_an_alarm_event_has_the_devices_text_when_its_adapter_gives_one() -> None:
    hub = Hub(clock=lambda: 0.0, wallclock=lambda: 0.0)
    hub.add_drive(DriveState(id="d", device=Device.CFW700, bus="b", address=4), DrivePolicy())
    hub.set_capabilities("d", Capabilities(alarm_texts={139: "Profibus DP interface offline"}))
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY)
    with hub.subscribe_events() as sub:
        hub.update("d", alarm=True)  # the status word's alarm bit, the code read later
        hub.update("d", alarm_code=139)
        hub.update("d", alarm=False, alarm_code=None)
        hub.update("d", alarm=True, alarm_code=140)  # not in the table: its number only
        alarms = [(e.text, e.data) for e in sub.drain() if e.kind is EventKind.ALARM]
    assert alarms == [
        ("alarm", {"code": None}),  # the code not read yet: no "None" in the text
        ("alarm 139: Profibus DP interface offline", {"code": 139}),
        ("alarm 140", {"code": 140}),
    ]


def test_a_canopen_drive_s_codes_are_in_hex_as_cia_301_writes_them() -> None:
    """EMCY 0x8130 (heartbeat or life guard error), never 33072: in the fault and alarm
    events, and in the refusal of a run command while faulted."""
    import pytest

    from gateway.errors import CommandRejected
    from gateway.model import DriveCommand, Source

    hub = Hub(clock=lambda: 0.0, wallclock=lambda: 0.0)
    hub.add_drive(DriveState(id="co", device=Device.CIA402, bus="b", address=5), DrivePolicy())
    hub.update("co", comm=CommState.ONLINE, status=DriveStatus.READY)
    with hub.subscribe_events() as sub:
        hub.update("co", alarm=True, alarm_code=0x4210)
        hub.update("co", status=DriveStatus.FAULTED, fault_code=0x8130, fault_text="life guard")
        texts = [(e.text, e.data) for e in sub.drain() if e.kind is not EventKind.COMM]
    assert ("alarm 0x4210", {"code": 0x4210}) in texts
    assert ("fault 0x8130: life guard", {"code": 33072}) in texts  # the JSON keeps a number
    with pytest.raises(CommandRejected, match=r"faulted 0x8130 \(life guard\)"):
        hub.submit("co", Source.ZENOH, DriveCommand(run=True))
