from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.errors import CommandRejected
from gateway.model import (
    EXTRA_JSON_FIELDS,
    JSON_FIELDS,
    CommState,
    DesiredCommand,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    StopAction,
)

FIXED = [
    "id", "device", "bus", "address", "comm", "status", "running", "direction",
    "at_reference", "remote", "alarm", "speed_rpm", "speed_pct", "speed_ref_rpm",
    "speed_ref_pct", "current_a", "current_pct_flc", "motor_temp_pct", "power_kw",
    "voltage_v", "fault_code", "fault_text", "alarm_code", "seq", "ts",
]  # fmt: skip


def test_json_has_exactly_the_contract_fields_first() -> None:
    state = DriveState(id="d1", device=Device.CFW11, bus="line1", address=3)
    doc = state.to_json()
    assert list(doc)[: len(FIXED)] == FIXED
    assert list(JSON_FIELDS) == FIXED
    assert set(doc) == set(FIXED) | set(EXTRA_JSON_FIELDS)


def test_unknown_readings_are_null_not_zero() -> None:
    doc = json.loads(
        json.dumps(DriveState(id="s", device=Device.MCD600, bus="b", address=5).to_json())
    )
    for name in ("speed_rpm", "speed_pct", "current_a", "power_kw", "voltage_v", "fault_code"):
        assert doc[name] is None
    assert doc["status"] == "not_ready"
    assert doc["comm"] == "offline"
    assert doc["device"] == "MCD 600"


def test_json_round_trip() -> None:
    state = DriveState(
        id="d", device=Device.CFW700, bus="b", address=4, comm=CommState.ONLINE,
        status=DriveStatus.FAULTED, direction=Direction.REVERSE, speed_rpm=-900.0,
        fault_code=70, fault_text="overcurrent", seq=9, ts=1.5, control_source=Source.MODBUS,
        values={"P0002": 1200},
    )  # fmt: skip
    assert DriveState.from_json(json.loads(json.dumps(state.to_json()))) == state


def test_status_codes_are_stable() -> None:
    # Modbus input register 1 carries these values: they are a contract.
    assert [s.value for s in DriveStatus] == [0, 1, 2, 3, 4, 5, 6]
    assert DriveStatus.TRIPPED.label == "tripped"


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        ([], "a command is a JSON object"),
        ({"speed": 3}, "unknown field(s): speed"),
        ({"run": 1}, "run must be true or false, not 1"),
        ({"speed_rpm": "fast"}, "speed_rpm must be a number, not 'fast'"),
        ({"speed_rpm": True}, "speed_rpm must be a number, not True"),
        ({"direction": "up"}, "direction must be 'forward' or 'reverse', not 'up'"),
        ({"speed_rpm": 10, "speed_pct": 5}, "give speed_rpm or speed_pct, not both"),
        ({"speed_pct": float("nan")}, "speed_pct must be a finite number"),
    ],
)
def test_command_parse_errors(payload: object, reason: str) -> None:
    with pytest.raises(CommandRejected) as err:
        DriveCommand.from_json(payload)
    assert err.value.reason == reason


def test_partial_commands_merge() -> None:
    desired = DesiredCommand()
    desired = desired.merged(DriveCommand(run=True, speed_rpm=900), Source.ZENOH)
    desired = desired.merged(DriveCommand(direction=Direction.REVERSE), Source.ZENOH)
    assert desired.run and desired.speed_rpm == 900 and desired.direction is Direction.REVERSE
    desired = desired.merged(DriveCommand(speed_pct=50), Source.ZENOH)
    assert desired.speed_pct == 50 and desired.speed_rpm is None
    reset = desired.merged(DriveCommand(fault_reset=True), Source.ZENOH)
    assert reset.fault_reset_seq == desired.fault_reset_seq + 1


def test_stop_actions() -> None:
    running = DesiredCommand(run=True, speed_rpm=100)
    assert running.stopped(StopAction.RAMP_STOP, Source.GATEWAY).run is False
    coast = running.stopped(StopAction.COAST, Source.GATEWAY)
    assert coast.run is False and coast.coast_stop is True
    assert running.stopped(StopAction.HOLD, Source.GATEWAY) == running


command_json = st.fixed_dictionaries(
    {},
    optional={
        "run": st.booleans(),
        "direction": st.sampled_from(["forward", "reverse"]),
        "speed_rpm": st.floats(-5000, 5000),
        "fault_reset": st.just(True),
        "quick_stop": st.booleans(),
        "coast_stop": st.booleans(),
        "jog": st.booleans(),
        "remote": st.booleans(),
    },
)


@settings(max_examples=100, deadline=None)
@given(command_json)
def test_command_json_round_trip(doc: dict[str, object]) -> None:
    cmd = DriveCommand.from_json(doc)
    assert DriveCommand.from_json(cmd.to_json()) == cmd


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.text(max_size=12), st.none() | st.booleans() | st.integers() | st.text()))
def test_command_parser_only_raises_command_rejected(doc: dict[str, object]) -> None:
    with contextlib.suppress(CommandRejected):
        DriveCommand.from_json(doc)


def test_readings_are_the_state_fields_an_adapter_reports() -> None:
    from gateway.model import STATE_FIELDS, DriveUpdate, Readings

    identity = {"id", "device", "bus", "address"}
    hubs_own = {"seq", "ts", "control_source", "control_client"}
    assert set(DriveUpdate.__annotations__) == STATE_FIELDS - identity - hubs_own
    assert set(DriveUpdate.__annotations__) - set(Readings.__annotations__) == {"comm"}
    assert not Readings.__required_keys__ and not DriveUpdate.__required_keys__
