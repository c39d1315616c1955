"""Issue 32 at the hub: the rules between the rules (docs/safety.md).

Each test names the item of the hazard table it shows; each failed on the hub before
the change (a drive left online kept its run, a stop beside a refused field or a stop
kind the drive lacks was refused, an offline drive kept its last readings, local control
and doubtful readings were not looked at).
"""

from __future__ import annotations

import pytest

from gateway.adapter import Capabilities, EventKind
from gateway.errors import CommandRejected, StopAppliedRestRefused
from gateway.model import CommState, Direction, DriveCommand, DriveStatus, Source, SpeedScale
from tests.gateway.test_hub import RUN, make_hub

STOP_KINDS = (
    DriveCommand(run=False),
    DriveCommand(quick_stop=True),
    DriveCommand(coast_stop=True),
    DriveCommand(run=False, quick_stop=True),
    DriveCommand(jog=False, coast_stop=True),
)


@pytest.mark.parametrize("comm", [CommState.OFFLINE, CommState.CONNECTING, CommState.CLEAR])
def test_leaving_online_clears_run_at_once(comm: CommState) -> None:
    """Item 1: the moment a drive leaves online, for any cause, its desired run and jog
    are cleared, so the first output after it comes back is a stop."""
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    with hub.subscribe_events() as events:
        hub.update("d", comm=comm)
        assert hub.desired("d").run is False and hub.desired("d").jog is False
        texts = [e.text for e in events.drain() if e.kind is EventKind.SAFETY]
    assert texts == [f"run command cleared: drive left online ({comm.value})"]
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY)
    assert hub.desired("d").run is False


@pytest.mark.parametrize("comm", [CommState.OFFLINE, CommState.CONNECTING])
def test_an_offline_drive_publishes_unknown_readings(comm: CommState) -> None:
    """Item 7: offline is published as offline: not running, speed and current unknown."""
    hub, _ = make_hub()
    hub.update(
        "d",
        status=DriveStatus.RUNNING,
        running=True,
        speed_rpm=896.0,
        speed_pct=49.8,
        current_a=4.1,
        direction=Direction.FORWARD,
    )
    state = hub.update("d", comm=comm)
    assert (state.status, state.running) == (DriveStatus.NOT_READY, False)
    assert (state.speed_rpm, state.speed_pct, state.current_a) == (None, None, None)
    # a late reading from the adapter changes nothing while the drive is not heard
    assert hub.update("d", speed_rpm=100.0, running=True) is state


def test_a_faulted_drive_going_offline_is_no_fault_cleared() -> None:
    hub, _ = make_hub()
    hub.update("d", status=DriveStatus.FAULTED, fault_code=21)
    with hub.subscribe_events() as events:
        hub.update("d", comm=CommState.OFFLINE)
        kinds = [e.kind for e in events.drain()]
    assert EventKind.FAULT not in kinds
    with hub.subscribe_events() as events:
        hub.update("d", comm=CommState.ONLINE, status=DriveStatus.FAULTED, fault_code=21)
        assert [e.text for e in events.drain() if e.kind is EventKind.FAULT] == ["fault 21"]


@pytest.mark.parametrize("stop", STOP_KINDS)
@pytest.mark.parametrize(
    "why",
    ["offline", "shutting_down", "control", "faulted", "local", "doubtful"],
)
def test_a_stop_is_never_refused(stop: DriveCommand, why: str) -> None:
    """Items 4 and 6: whatever else holds, a command that asks for less motion is applied."""
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN, "scada")
    setup = {
        "offline": lambda: hub.update("d", comm=CommState.CONNECTING),
        "shutting_down": lambda: setattr(hub, "shutting_down", True),
        "control": lambda: None,
        "faulted": lambda: hub.update("d", status=DriveStatus.FAULTED),
        "local": lambda: hub.update("d", local_control=True),
        "doubtful": lambda: hub.update("d", doubtful=True),
    }
    setup[why]()
    hub.submit("d", Source.MODBUS, stop, "10.0.0.5")
    desired = hub.desired("d")
    assert desired.run is False
    assert desired.quick_stop is bool(stop.quick_stop)
    assert desired.coast_stop is bool(stop.coast_stop)


def test_a_stop_kind_the_drive_lacks_becomes_the_nearest_it_has() -> None:
    """Item 4: the CFW320 has no quick stop; {run false, quick stop true} used to be
    refused whole and left the drive running."""
    hub, _ = make_hub()
    hub.set_capabilities(
        "d",
        Capabilities(
            speed_scale=SpeedScale(1800.0),
            unsupported={"remote": "no remote bit"},
            stop_substitutes={"quick_stop": "coast_stop"},
        ),
    )
    hub.submit("d", Source.ZENOH, RUN)
    with hub.subscribe_events() as events:
        hub.submit("d", Source.ZENOH, DriveCommand(run=False, quick_stop=True))
        hub.submit("d", Source.ZENOH, DriveCommand(quick_stop=False))
        hub.submit("d", Source.ZENOH, DriveCommand(quick_stop=True))
        said = [e.text for e in events.drain() if e.kind is EventKind.SAFETY]
    assert hub.desired("d").coast_stop is True and hub.desired("d").run is False
    assert said == ["quick_stop is not in the CFW-11: coast_stop applied instead"]


def test_an_unsupported_stop_kind_is_a_ramp_stop() -> None:
    hub, _ = make_hub()
    hub.set_capabilities(
        "d",
        Capabilities(speed_scale=SpeedScale(1800.0), unsupported={"quick_stop": "none here"}),
    )
    hub.submit("d", Source.ZENOH, RUN)
    hub.submit("d", Source.ZENOH, DriveCommand(quick_stop=True))
    desired = hub.desired("d")
    assert (desired.run, desired.quick_stop, desired.coast_stop) == (False, False, False)


def test_a_stop_beside_a_refused_field_is_applied_and_the_rest_refused() -> None:
    hub, _ = make_hub()
    hub.set_capabilities(
        "d", Capabilities(speed_scale=SpeedScale(1800.0), unsupported={"remote": "no remote"})
    )
    hub.submit("d", Source.ZENOH, RUN)
    with pytest.raises(StopAppliedRestRefused, match=r"run false applied.*no remote"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=False, remote=True))
    assert hub.desired("d").run is False and hub.desired("d").remote is True


def test_a_check_of_a_stop_never_refuses() -> None:
    hub, _ = make_hub()
    hub.shutting_down = True
    hub.check("d", Source.MODBUS, DriveCommand(run=False), "plc")
    with pytest.raises(CommandRejected):
        hub.check("d", Source.MODBUS, DriveCommand(run=True), "plc")


def test_local_control_refuses_run_clears_it_and_says_so() -> None:
    """Item 6: while the drive ignores the network, a run is refused with that reason."""
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    with hub.subscribe_events() as events:
        state = hub.update("d", local_control=True)
        texts = [e.text for e in events.drain()]
    assert state.to_json()["local_control"] is True
    assert hub.desired("d").run is False
    assert any("drive in local control" in t for t in texts)
    with pytest.raises(CommandRejected, match="in local control"):
        hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", local_control=False)
    hub.submit("d", Source.ZENOH, RUN)
    assert hub.desired("d").run is True
    hub.update("d", local_control=True)
    hub.update("d", local_control=False)
    assert hub.desired("d").run is False  # back in network control: a new run is needed


def test_doubtful_readings_refuse_run() -> None:
    """Item 12: while frames contradict each other, no run is started on their word."""
    hub, _ = make_hub()
    with hub.subscribe_events() as events:
        hub.update("d", doubtful=True)
        assert any("readings doubtful" in e.text for e in events.drain())
    with pytest.raises(CommandRejected, match="doubtful"):
        hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", doubtful=False)
    hub.submit("d", Source.ZENOH, RUN)


def test_failsafe_false_is_said_and_a_site_may_require_it() -> None:
    """Item 5: a drive that keeps running when the gateway is lost is said in a safety
    event; with require_failsafe its run commands are refused."""
    hub, _ = make_hub(require_failsafe=True)
    with pytest.raises(
        CommandRejected, match=r"no known fail-safe reaction to a lost master \(unknown\)"
    ):
        hub.submit("d", Source.ZENOH, RUN)
    text = "P0313 = 0: inactive, the drive keeps running"
    with hub.subscribe_events() as events:
        hub.update("d", failsafe=False, failsafe_text=text)
        safety = [e.text for e in events.drain() if e.kind is EventKind.SAFETY]
    assert safety == [f"the drive keeps running if the gateway is lost: {text}"]
    with pytest.raises(CommandRejected, match="P0313 = 0"):
        hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", failsafe=True, failsafe_text="P0313 = 1: ramp stop")
    hub.submit("d", Source.ZENOH, RUN)
    assert hub.desired("d").run is True


def test_a_drive_that_becomes_not_ready_loses_its_run() -> None:
    """Rule 1: a reset input opened, an enable taken away: when it ends, nothing restarts."""
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", status=DriveStatus.RUNNING, running=True)
    hub.update("d", status=DriveStatus.NOT_READY, running=False)
    assert hub.desired("d").run is False
    hub.update("d", status=DriveStatus.READY)
    assert hub.desired("d").run is False


def test_a_drive_that_needs_ready_refuses_a_run_while_not_ready() -> None:
    hub, _ = make_hub()
    hub.set_capabilities("d", Capabilities(run_needs_ready=True))
    hub.update("d", status=DriveStatus.NOT_READY)
    with pytest.raises(CommandRejected, match="is not ready"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    hub.update("d", status=DriveStatus.READY)
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))
