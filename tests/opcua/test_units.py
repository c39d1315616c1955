"""The OPC UA front end's parts without a server: the values of a drive's variables, the
fault condition's state machine, HistoryRead over a store, and the methods' commands."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime
from types import SimpleNamespace
from typing import Any

import pytest
from asyncua import ua
from hypothesis import given
from hypothesis import strategies as st

from gateway.adapter import Capabilities
from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    ControlMode,
    Device,
    DriveState,
    DriveStatus,
    Source,
    SpeedScale,
)
from gateway.opcua.alarms import AlarmState
from gateway.opcua.commands import Commands
from gateway.opcua.history import DriveHistory
from gateway.opcua.sessions import CALLER, Role, SessionUser, default_roles
from gateway.opcua.variables import (
    AMPERE,
    KILOWATT,
    PERCENT,
    READINGS,
    RPM,
    VOLT,
    bus_figures,
    changed_values,
    values_of,
)
from gateway.opcuaconfig import OpcuaSection
from tests.opcua.harness import HISTORY_START, FakeHistory

STATE = DriveState(id="d1", device=Device.TEST, bus="l", address=1)


# ---------------------------------------------------------------- variables


def test_units_are_unece_codes_as_opcua_encodes_them() -> None:
    assert {u.code: u.unit_id for u in (RPM, PERCENT, AMPERE, KILOWATT, VOLT)} == {
        "RPM": 0x52504D,
        "P1": 0x5031,
        "AMP": 0x414D50,
        "KWT": 0x4B5754,
        "VLT": 0x564C54,
    }


def test_a_reading_the_drive_does_not_give_has_no_value_never_zero() -> None:
    values = values_of(STATE.changed(speed_rpm=float("nan"), current_a=3.5, fault_code=None))
    assert values["SpeedRpm"] is None and values["PowerKw"] is None
    assert values["CurrentA"] == 3.5
    assert values["FaultCode"] == -1 and values["FaultText"] == ""
    assert values["Status"] == "not_ready" and values["StatusCode"] == 0


def test_ranges_follow_the_drives_scale() -> None:
    speed = next(r for r in READINGS if r.name == "SpeedRpm")
    pct = next(r for r in READINGS if r.name == "SpeedPercent")
    caps = Capabilities(speed_scale=SpeedScale(1500.0, 400.0))
    assert speed.range_of(caps) == (-6000.0, 6000.0)
    assert pct.range_of(caps) == (-400.0, 400.0)
    assert speed.range_of(Capabilities()) == (-3600.0, 3600.0)


@given(st.dictionaries(st.sampled_from(["SpeedRpm", "Running", "Status"]), st.integers()))
def test_only_changed_values_are_written(old: dict[str, Any]) -> None:
    new = {"SpeedRpm": 1, "Running": 2, "Status": 3}
    changes = changed_values(old, new)
    assert changes == {k: v for k, v in new.items() if old.get(k) != v}
    assert changed_values(None, new) == new


def test_bus_figures_are_the_lines_numbers() -> None:
    diag = {"cycles": 5, "ok": True, "name": "x", "rate": float("inf"), "drives": {"a": {}}}
    assert bus_figures(diag) == {"cycles": 5.0, "ok": 1.0}


# ---------------------------------------------------------------- alarms


def faulted(code: int, text: str = "overcurrent") -> DriveState:
    return STATE.changed(status=DriveStatus.FAULTED, fault_code=code, fault_text=text)


def test_a_fault_is_active_unacknowledged_until_it_ends_and_is_acknowledged() -> None:
    idle = AlarmState()
    assert idle.stepped(STATE) is None and not idle.retain
    raised = idle.stepped(faulted(70))
    assert raised is not None
    assert (raised.active, raised.acked, raised.retain) == (True, False, True)
    assert raised.message == "fault 70: overcurrent"
    assert raised.stepped(faulted(70)) is None  # the same fault: no new event
    other = raised.stepped(faulted(71, "overvoltage"))
    assert other is not None and other.code == 71 and not other.acked
    raised = AlarmState(active=True, acked=False, code=70, text="overcurrent", event_id=b"e1")
    cleared = raised.stepped(STATE.changed(status=DriveStatus.READY))
    assert cleared is not None
    assert (cleared.active, cleared.acked, cleared.retain) == (False, False, True)
    assert cleared.message == "fault 70: overcurrent (cleared)"
    acked = cleared.acknowledged(b"e1")
    assert isinstance(acked, AlarmState) and not acked.retain
    assert cleared.acknowledged(b"old") == ua.StatusCodes.BadEventIdUnknown
    assert acked.acknowledged(b"e1") == ua.StatusCodes.BadConditionBranchAlreadyAcked
    assert AlarmState().acknowledged(b"") == ua.StatusCodes.BadEventIdUnknown


def test_a_trip_of_a_soft_starter_is_an_alarm_too() -> None:
    tripped = STATE.changed(status=DriveStatus.TRIPPED, fault_code=3, fault_text=None)
    raised = AlarmState().stepped(tripped)
    assert raised is not None and raised.active and raised.message == "fault 3"


# ---------------------------------------------------------------- history


NODE = ua.NodeId("d1.SpeedRpm", 2)


def when(offset: float) -> datetime:
    return datetime.fromtimestamp(HISTORY_START + offset, UTC)


async def test_history_read_asks_the_store_for_the_span_and_maps_the_field() -> None:
    store = FakeHistory()
    history = DriveHistory(store, {NODE: ("d1", "speed_rpm")})
    values, more = await history.read_node_history(NODE, when(5), when(7), 0)
    assert [v.Value.Value for v in values] == [50.0, 60.0, 70.0]
    assert values[0].SourceTimestamp == when(5) and more is None
    assert store.calls == [("d1", HISTORY_START + 5, HISTORY_START + 7, None)]
    backwards, _ = await history.read_node_history(NODE, when(7), when(5), 0)
    assert [v.Value.Value for v in backwards] == [70.0, 60.0, 50.0]
    assert await history.read_node_history(ua.NodeId("x", 2), when(0), when(9), 0) == ([], None)


async def test_history_read_gives_a_continuation_point_past_the_limit() -> None:
    history = DriveHistory(FakeHistory(), {NODE: ("d1", "speed_rpm")}, max_values=20)
    first, more = await history.read_node_history(NODE, when(0), when(49), 0)
    assert len(first) == 20 and more == when(20)
    rest, more = await history.read_node_history(NODE, more, when(49), 0)
    assert len(rest) == 20 and rest[0].Value.Value == 200.0
    few, more = await history.read_node_history(NODE, when(0), when(49), 5)
    assert len(few) == 5 and more == when(5)


async def test_a_value_missing_in_a_row_is_bad_no_data_and_a_failing_store_is_bad() -> None:
    history = DriveHistory(FakeHistory(), {NODE: ("d1", "current_a")})
    values, _ = await history.read_node_history(NODE, when(0), when(1), 0)
    assert [v.StatusCode.value for v in values] == [ua.StatusCodes.BadNoData] * 2

    class Broken:
        def readings(self, *args: Any) -> list[Any]:
            raise OSError("disk I/O error")

        def events(self, *args: Any, **kw: Any) -> list[Any]:
            raise OSError("disk I/O error")

    source = ua.NodeId("d1", 2)
    broken = DriveHistory(Broken(), {NODE: ("d1", "speed_rpm")}, sources={source: "d1"})
    with pytest.raises(ua.UaStatusCodeError):
        await broken.read_node_history(NODE, when(0), when(1), 0)
    assert broken.failures == 1
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await broken.read_event_history(source, when(0), when(1), 0, None)
    assert refused.value.code == ua.StatusCodes.BadHistoryOperationUnsupported
    assert broken.failures == 2


# ---------------------------------------------------------------- commands


@pytest.fixture
def hub() -> Hub:
    h = Hub(clock=lambda: 0.0, wallclock=lambda: 1.0)
    h.add_drive(STATE)
    h.add_drive(
        DriveState(id="d2", device=Device.TEST, bus="l", address=2),
        DrivePolicy(control=ControlMode.MODBUS),
    )
    for d in ("d1", "d2"):
        h.set_capabilities(d, Capabilities(speed_scale=SpeedScale(1800.0)))
        h.update(d, comm=CommState.ONLINE, status=DriveStatus.READY)
    return h


@pytest.fixture
def caller() -> Iterator[None]:
    session = SimpleNamespace(
        client="session 42",
        user_of=lambda: SessionUser(client="session 42", user_name=None, peer="127.0.0.1"),
    )
    token = CALLER.set(session)  # type: ignore[arg-type]
    yield
    CALLER.reset(token)


def test_a_method_is_a_command_of_the_calling_session(hub: Hub, caller: None) -> None:
    commands = Commands(hub, lambda _user: Role.OPERATE)
    assert commands.call("d1", "SetSpeed", (900.0,)).accepted
    assert commands.call("d1", "Run", ()).accepted
    desired = hub.desired("d1")
    assert desired.run and desired.speed_rpm == 900.0
    assert desired.controller == (Source.OPCUA, "session 42")
    assert commands.call("d1", "QuickStop", ()).accepted
    assert hub.desired("d1").quick_stop and not hub.desired("d1").run
    assert not commands.call("d1", "Run", ()).accepted  # latched: released by Reset
    assert commands.call("d1", "Reset", ()).accepted
    assert not hub.desired("d1").quick_stop and not hub.desired("d1").run
    assert (commands.accepted, commands.refused) == (4, 1)


def test_refusals_carry_a_bad_status_and_the_reason(hub: Hub, caller: None) -> None:
    commands = Commands(hub, lambda _user: Role.OPERATE)
    refused = commands.call("d2", "Run", ())
    assert (refused.status, refused.text) == (
        ua.StatusCodes.BadInvalidState,
        "drive d2 takes commands from modbus only",
    )
    result = refused.result()
    assert result.StatusCode.is_bad() and result.OutputArguments[0].Value == refused.text
    for bad in ((), ("fast",), (True,), (float("inf"),), (1.0, 2.0)):
        outcome = commands.call("d1", "SetSpeed", bad)
        assert outcome.status == ua.StatusCodes.BadInvalidArgument, bad
    assert commands.call("d1", "SetSpeed", (99999.0,)).text.startswith("speed_rpm 99999 is beyond")
    assert commands.call("nope", "Stop", ()).status == ua.StatusCodes.BadNodeIdUnknown
    assert hub.desired("d1").speed_rpm is None


def test_a_session_without_the_operate_role_commands_nothing(hub: Hub, caller: None) -> None:
    commands = Commands(hub, lambda _user: Role.OBSERVE)
    outcome = commands.call("d1", "Run", ())
    assert outcome.status == ua.StatusCodes.BadUserAccessDenied
    assert "session 42 may not operate drives" in outcome.text
    assert not hub.desired("d1").run


def test_the_default_roles_operate_on_loopback_only() -> None:
    user = SessionUser(client="session 1", user_name=None, peer="10.0.0.5")
    assert default_roles(OpcuaSection(host="127.0.0.1"))(user) is Role.OPERATE
    assert default_roles(OpcuaSection(host="0.0.0.0"))(user) is Role.OBSERVE
