"""Issue 17 in the hub: the widened rule 1, control owned by a client, the audit trail.

Stepped with an injected clock (no sleeping); the end-to-end tests through the
daemon are in tests/e2e.
"""

from __future__ import annotations

import logging

import pytest

from gateway.adapter import Event, EventKind
from gateway.errors import CommandRejected
from gateway.hub import EventSubscription, Hub
from gateway.model import CommState, DriveCommand, DriveStatus, Source, StopAction
from tests.gateway.test_hub import RUN, make_hub

PLC = "10.0.0.5"
HMI = "10.0.0.6"


class Recorder:
    """Every event of the hub from now on (a subscription too large to drop any)."""

    def __init__(self, hub: Hub) -> None:
        self.sub = EventSubscription(hub, limit=100_000)
        hub._event_subs.add(self.sub)
        self.seen: list[Event] = []

    def all(self) -> list[Event]:
        self.seen += self.sub.drain()
        return self.seen

    def texts(self, kind: EventKind) -> list[str]:
        return [e.text for e in self.all() if e.kind is kind]


def cmd(**fields: bool) -> DriveCommand:
    return DriveCommand.from_json(fields)


# ------------------------------------------------------------------ rule 1, widened


@pytest.mark.parametrize("how", ["keypad", "auto_reset", "power_cycle"])
def test_a_fault_that_ends_at_the_drive_never_restarts_it(how: str) -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", status=DriveStatus.RUNNING, running=True)
    hub.update("d", status=DriveStatus.FAULTED, fault_code=21, running=False)
    if how == "power_cycle":
        hub.update("d", comm=CommState.OFFLINE)
        hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY, fault_code=None)
    else:
        hub.update("d", status=DriveStatus.READY, fault_code=None)
    assert hub.desired("d").run is False
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    assert hub.desired("d").run is True


def test_a_run_that_slipped_in_before_the_fault_was_seen_is_cleared_when_it_ends() -> None:
    hub, _ = make_hub()
    hub.update("d", status=DriveStatus.FAULTED)
    # the hub saw the fault: refused. Were it not seen yet, the run would be accepted,
    # then cleared by the fault's start; and the end of the fault clears it again:
    hub.update("d", status=DriveStatus.READY)
    hub.submit("d", Source.ZENOH, RUN)
    hub._drives["d"].state = hub.state("d").changed(status=DriveStatus.FAULTED)  # unseen edge
    hub.update("d", status=DriveStatus.READY)
    assert hub.desired("d").run is False


@pytest.mark.parametrize("status", [DriveStatus.FAULTED, DriveStatus.TRIPPED])
@pytest.mark.parametrize("field", ["run", "jog"])
def test_run_or_jog_while_faulted_or_tripped_is_refused(status: DriveStatus, field: str) -> None:
    hub, _ = make_hub()
    hub.update("d", status=status, fault_code=5)
    with pytest.raises(CommandRejected, match=f"is {status.label} 5: reset the fault"):
        hub.submit("d", Source.MODBUS, cmd(**{field: True}), PLC)
    assert not hub.desired("d").run and not hub.desired("d").jog


@pytest.mark.parametrize("latch", ["quick_stop", "coast_stop"])
def test_a_stop_latch_clears_run_and_its_release_never_restarts(latch: str) -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    hub.submit("d", Source.ZENOH, cmd(**{latch: True}))
    assert hub.desired("d").run is False
    with pytest.raises(CommandRejected, match=f"latched in {latch}: release it"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    with pytest.raises(CommandRejected, match=f"send run after releasing {latch}"):
        hub.submit("d", Source.ZENOH, cmd(run=True, **{latch: False}))
    hub.submit("d", Source.ZENOH, cmd(**{latch: False}))
    assert hub.desired("d").run is False  # the release alone starts nothing
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    assert hub.desired("d").run is True


def test_run_with_a_stop_in_the_same_command_is_refused() -> None:
    hub, _ = make_hub()
    # the stop wins: it is applied, the run is refused
    with pytest.raises(CommandRejected, match="run and quick_stop in one command"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=True, quick_stop=True))
    assert hub.desired("d").quick_stop is True and hub.desired("d").run is False
    hub.submit("d", Source.ZENOH, DriveCommand(quick_stop=False))
    # a full command that restates released latches is fine
    hub.submit("d", Source.ZENOH, DriveCommand(run=True, quick_stop=False, coast_stop=False))
    assert hub.desired("d").run is True


def test_after_a_coast_watchdog_action_run_needs_the_release_first() -> None:
    hub, clock = make_hub(command_timeout=1.0, on_command_timeout=StopAction.COAST)
    hub.submit("d", Source.MODBUS, RUN, PLC)
    clock.t += 1.5
    hub.tick()
    assert hub.desired("d").run is False and hub.desired("d").coast_stop
    with pytest.raises(CommandRejected, match="latched in coast_stop"):
        hub.submit("d", Source.MODBUS, DriveCommand(run=True), PLC)


# ------------------------------------------------------------------ rule 3: control is a client's


def test_another_clients_keepalive_never_feeds_the_watchdog() -> None:
    hub, clock = make_hub(command_timeout=1.0)
    hub.submit("d", Source.MODBUS, RUN, PLC)
    for _ in range(5):
        clock.t += 0.4
        hub.refresh("d", Source.MODBUS, HMI)  # the HMI's keep-alive register
        hub.submit("d", Source.ZENOH, DriveCommand(), "zid-scada")  # an empty command
        hub.tick()
    assert hub.desired("d").run is False
    assert hub.desired("d").source is Source.GATEWAY


def test_the_controlling_clients_keepalive_feeds_it() -> None:
    hub, clock = make_hub(command_timeout=1.0)
    hub.submit("d", Source.MODBUS, RUN, PLC)
    for _ in range(5):
        clock.t += 0.4
        hub.refresh("d", Source.MODBUS, PLC)
        hub.tick()
    assert hub.desired("d").run is True


def test_a_command_from_another_client_of_the_same_source_takes_control() -> None:
    hub, _ = make_hub()
    rec = Recorder(hub)
    hub.submit("d", Source.MODBUS, RUN, PLC)
    hub.submit("d", Source.MODBUS, DriveCommand(speed_rpm=300), HMI)
    desired = hub.desired("d")
    assert desired.run is False  # rule 1: control passed
    assert desired.controller == (Source.MODBUS, HMI)
    assert hub.state("d").control_client == HMI
    assert rec.texts(EventKind.CONTROL) == [f"control passed from modbus {PLC} to modbus {HMI}"]


def test_an_empty_command_from_another_client_does_not_take_control() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN, "zid-a")
    hub.submit("d", Source.ZENOH, DriveCommand(), "zid-b")
    assert hub.desired("d").run is True
    assert hub.desired("d").controller == (Source.ZENOH, "zid-a")


# ------------------------------------------------------------------ the audit trail


def test_every_accepted_change_is_one_event_and_one_log_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    hub, _ = make_hub()
    rec = Recorder(hub)
    with caplog.at_level(logging.INFO, logger="gateway.hub"):
        hub.submit("d", Source.MODBUS, RUN, PLC)
        hub.submit("d", Source.MODBUS, RUN, PLC)  # no change: no entry
        hub.submit("d", Source.MODBUS, DriveCommand(speed_rpm=450), PLC)
    assert rec.texts(EventKind.COMMAND) == [
        f"command from modbus {PLC} accepted: run False -> True, speed_rpm None -> 900",
        f"command from modbus {PLC} accepted: speed_rpm 900 -> 450",
    ]
    ev = next(e for e in rec.all() if e.kind is EventKind.COMMAND)
    assert ev.data["client"] == PLC and ev.data["source"] == "modbus"
    assert ev.data["changes"] == {"run": True, "speed_rpm": 900}
    lines = [r.getMessage() for r in caplog.records if "accepted" in r.getMessage()]
    assert len(lines) == 2


def test_a_flood_of_refusals_is_logged_once_per_period_with_a_count(
    caplog: pytest.LogCaptureFixture,
) -> None:
    hub, clock = make_hub()
    rec = Recorder(hub)
    hub.update("d", status=DriveStatus.FAULTED)
    with caplog.at_level(logging.INFO, logger="gateway.hub"):
        for _ in range(1000):
            with pytest.raises(CommandRejected):
                hub.submit("d", Source.ZENOH, DriveCommand(run=True), "zid-a")
        clock.t += 11.0
        hub.tick()
    refused = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(refused) == 2
    assert refused[1].endswith("(999 more like it since the last line)")
    # the burst is one event, then one with the count (every refusal is counted)
    events = [e for e in rec.all() if e.kind is EventKind.COMMAND_REFUSED]
    assert len(events) == 2 and "repeats" not in events[0].data
    assert events[1].data["repeats"] == 999 and events[1].text == events[0].text
    assert hub.events_folded == 999


def test_refusals_that_go_on_are_logged_once_per_period_with_a_count(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A flood that lasts: its events come once per fold window, its log lines once per
    refusal period, and every refusal is in a count."""
    hub, clock = make_hub()
    hub.update("d", status=DriveStatus.FAULTED)
    with caplog.at_level(logging.INFO, logger="gateway.hub"):
        for _ in range(25):  # 25 s of 10 refusals a second, the hub ticking
            for _ in range(10):
                with pytest.raises(CommandRejected):
                    hub.submit("d", Source.ZENOH, DriveCommand(run=True), "zid-a")
                clock.t += 0.1
                hub.tick()
        clock.t += 11.0
        hub.tick()
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert 3 <= len(lines) <= 5  # the first, then one per 10 s
    counted = [int(line.rsplit("(", 1)[1].split()[0]) for line in lines[1:]]
    assert sum(counted) + 1 == 250
