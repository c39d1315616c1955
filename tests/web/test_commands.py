"""A page in control is a client like any other: the command watchdog watches it (rule 3),
and control passing to or from it clears run (rule 1)."""

from __future__ import annotations

from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    ControlMode,
    Device,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    StopAction,
)


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def hub_with_drive(control: ControlMode = ControlMode.ANY) -> tuple[Hub, Clock]:
    clock = Clock()
    hub = Hub(clock=clock, wallclock=clock)
    hub.add_drive(
        DriveState(id="d", device=Device.TEST, bus="b", address=1),
        DrivePolicy(control=control, command_timeout=1.0, on_command_timeout=StopAction.COAST),
    )
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY)
    return hub, clock


def test_the_watchdog_stops_a_drive_whose_page_went_away() -> None:
    hub, clock = hub_with_drive()
    hub.submit("d", Source.WEB, DriveCommand(run=True), "127.0.0.1 page-1")
    clock.now = 0.9
    hub.submit("d", Source.WEB, DriveCommand(), "127.0.0.1 page-1")  # the page's keep-alive
    clock.now = 1.8
    hub.tick()
    assert hub.desired("d").run  # fed 0.9 s ago
    hub.submit("d", Source.WEB, DriveCommand(), "127.0.0.1 page-2")  # another page: no feed
    clock.now = 2.0
    hub.tick()
    desired = hub.desired("d")
    assert not desired.run and desired.coast_stop and desired.source is Source.GATEWAY


def test_another_page_taking_control_needs_its_own_run_command() -> None:
    hub, _ = hub_with_drive()
    hub.submit("d", Source.WEB, DriveCommand(run=True), "127.0.0.1 page-1")
    hub.submit(
        "d",
        Source.WEB,
        DriveCommand(speed_pct=None, direction=None, remote=True),
        "127.0.0.1 page-2",
    )
    desired = hub.desired("d")
    assert not desired.run and desired.client == "127.0.0.1 page-2"


def test_control_web_admits_the_page_only() -> None:
    hub, _ = hub_with_drive(ControlMode.WEB)
    hub.submit("d", Source.WEB, DriveCommand(run=True), "127.0.0.1 page-1")
    assert hub.desired("d").run
    assert ControlMode.ANY.admits(Source.WEB) and not ControlMode.ZENOH.admits(Source.WEB)
    assert not ControlMode.WEB.admits(Source.MODBUS)
