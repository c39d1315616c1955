"""Sans-IO request handling: commands and parameter requests from payload bytes."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.adapter import ParamInfo
from gateway.errors import (
    CommandRejected,
    GatewayTimeout,
    ParameterError,
    ParameterNotWritable,
    UnknownDrive,
)
from gateway.model import (
    CommState,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
)
from gateway.zenoh.requests import (
    Answer,
    BadRequest,
    ParamRequest,
    command_accepted,
    command_refused,
    encode_json,
    encode_state,
    error_body,
    param_result,
    parse_command,
    parse_param_request,
)


def test_a_command_payload_parses() -> None:
    cmd = parse_command(b'{"run": true, "direction": "reverse", "speed_rpm": 900}')
    assert cmd == DriveCommand(run=True, direction=Direction.REVERSE, speed_rpm=900.0)
    assert parse_command(b"{}").is_empty
    assert command_accepted() == {"accepted": True}
    assert command_refused("why") == {"accepted": False, "error": "why"}


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (None, "a command is a JSON object, and the payload is empty"),
        (b"", "a command is a JSON object, and the payload is empty"),
        (b"{", "invalid JSON: Expecting property name enclosed in double quotes at position 1"),
        (b"\xff", "payload is not UTF-8"),
        (b"[]", "a command is a JSON object"),
        (b'{"run": 1}', "run must be true or false, not 1"),
        (b'{"speed": 1}', "unknown field(s): speed"),
        (b'{"speed_rpm": "fast"}', "speed_rpm must be a number, not 'fast'"),
        (b'{"speed_rpm": 1, "speed_pct": 1}', "give speed_rpm or speed_pct, not both"),
        (b'{"speed_rpm": NaN}', "speed_rpm must be a finite number"),
    ],
)
def test_a_bad_command_is_refused_with_the_reason(payload: bytes | None, reason: str) -> None:
    with pytest.raises(CommandRejected) as exc:
        parse_command(payload)
    assert exc.value.reason == reason


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=64) | st.text(max_size=64).map(str.encode))
def test_any_bytes_are_a_command_or_a_refusal(payload: bytes) -> None:
    try:
        assert isinstance(parse_command(payload), DriveCommand)
    except CommandRejected as exc:
        assert exc.reason


JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=8,
)


@settings(max_examples=150, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(["run", "direction", "speed_rpm", "speed_pct", "fault_reset", "jog", "x"]),
        JSONISH,
        max_size=4,
    )
)
def test_any_json_object_is_a_command_or_a_refusal(obj: dict[str, object]) -> None:
    payload = json.dumps(obj).encode()
    try:
        assert isinstance(parse_command(payload), DriveCommand)
    except CommandRejected as exc:
        assert exc.reason


@pytest.mark.parametrize(
    ("rest", "payload", "req"),
    [
        (("100",), None, ParamRequest(100)),
        (("100",), b"", ParamRequest(100)),
        (("100", "3"), None, ParamRequest(100, 3)),
        (("101",), b'{"value": 7}', ParamRequest(101, 0, 7)),
        (("101", "0"), b'{"value": 1.5}', ParamRequest(101, 0, 1.5)),
        (("65535", "65535"), None, ParamRequest(65535, 65535)),
        (("0x6083",), None, ParamRequest(0x6083)),  # a CANopen object (issue 22)
        (("0x2000", "4"), b'{"value": 1500}', ParamRequest(0x2000, 4, 1500)),
        (("0X605a", "0x0"), None, ParamRequest(0x605A, 0)),
    ],
)
def test_parameter_requests(
    rest: tuple[str, ...], payload: bytes | None, req: ParamRequest
) -> None:
    assert parse_param_request(rest, payload) == req
    assert req.is_write is (req.value is not None)


@pytest.mark.parametrize(
    ("rest", "payload", "text"),
    [
        ((), None, "a parameter key is params/<number> or params/<number>/<subindex>"),
        (("1", "2", "3"), None, "a parameter key is params/<number> or params/<number>/<subindex>"),
        (("x",), None, "parameter number must be a decimal number, not 'x'"),
        (("-1",), None, "parameter number must be a decimal number, not '-1'"),
        (("\u0661",), None, "parameter number must be a decimal number, not '\u0661'"),
        (("65536",), None, "parameter number 65536 is beyond 65535"),
        (("0x10000",), None, "parameter number 65536 is beyond 65535"),
        (("0x",), None, "parameter number must be 0x and hexadecimal digits, not '0x'"),
        (("0x6g",), None, "parameter number must be 0x and hexadecimal digits, not '0x6g'"),
        (("1", "s"), None, "subindex must be a decimal number, not 's'"),
        (
            ("1",),
            b"{",
            "invalid JSON: Expecting property name enclosed in double quotes at position 1",
        ),
        (("1",), b"7", 'a parameter write is {"value": V}'),
        (("1",), b'{"val": 7}', 'a parameter write is {"value": V}'),
        (("1",), b'{"value": 7, "x": 1}', "unknown field(s): x"),
        (("1",), b'{"value": true}', "value must be a number, not True"),
        (("1",), b'{"value": null}', "value must be a number, not None"),
        (("1",), b'{"value": Infinity}', "value must be a finite number"),
    ],
)
def test_bad_parameter_requests(rest: tuple[str, ...], payload: bytes | None, text: str) -> None:
    with pytest.raises(BadRequest) as exc:
        parse_param_request(rest, payload)
    assert exc.value.text == text


@settings(max_examples=300, deadline=None)
@given(st.lists(st.text(max_size=6), max_size=3).map(tuple), st.none() | st.binary(max_size=32))
def test_any_parameter_request_parses_or_is_a_bad_request(
    rest: tuple[str, ...], payload: bytes | None
) -> None:
    try:
        req = parse_param_request(rest, payload)
    except BadRequest as exc:
        assert exc.text
    else:
        assert 0 <= req.number <= 65535 and 0 <= req.subindex <= 65535


def test_replies_and_error_bodies() -> None:
    req = ParamRequest(100, 0, 60)
    assert param_result(req, 60) == {"number": 100, "subindex": 0, "value": 60}
    info = ParamInfo(100, "Acceleration time", "s", 1, 0.0, 999.0, code="P0100")
    assert param_result(req, 60, info) == {
        "number": 100,
        "subindex": 0,
        "value": 60,
        "code": "P0100",
        "name": "Acceleration time",
        "unit": "s",
        "scaled": 6.0,
    }
    plain = ParamInfo(227, "Run/stop selection - remote")  # no unit, no decimals
    assert param_result(ParamRequest(227), 4, plain)["scaled"] == 4
    assert error_body(ParameterError("parameter value out of limits", 2)) == {
        "error": "parameter value out of limits",
        "code": 2,
    }
    assert error_body(ParameterNotWritable("not allowed")) == {"error": "not allowed"}
    assert error_body(UnknownDrive("no drive 'x'")) == {"error": "no drive 'x'"}
    assert error_body(GatewayTimeout("no answer in 1 s")) == {"error": "no answer in 1 s"}
    assert error_body(BadRequest("bad")) == {"error": "bad"}
    assert error_body(RuntimeError()) == {"error": "RuntimeError"}
    assert Answer.reply("k", {"a": 1}) == Answer(True, b'{"a":1}', "k")
    assert Answer.refusal("no") == Answer(False, b'{"error":"no"}')


FLOATS = st.none() | st.floats(allow_nan=False, allow_infinity=False)
STATES = st.builds(
    DriveState,
    id=st.text(min_size=1, max_size=8),
    device=st.sampled_from(Device),
    bus=st.text(max_size=8),
    address=st.integers(0, 125),
    comm=st.sampled_from(CommState),
    status=st.sampled_from(DriveStatus),
    running=st.booleans(),
    direction=st.sampled_from(Direction),
    speed_rpm=FLOATS,
    speed_pct=FLOATS,
    current_a=FLOATS,
    power_kw=FLOATS,
    fault_code=st.none() | st.integers(0, 65535),
    fault_text=st.none() | st.text(max_size=16),
    seq=st.integers(0, 2**40),
    ts=st.floats(0, 2e9),
    control_source=st.sampled_from(Source),
    speed_base=st.none() | st.text(max_size=8),
    values=st.dictionaries(
        st.text(max_size=6),
        st.integers() | st.floats(allow_nan=False, allow_infinity=False),
        max_size=3,
    ),
)


@settings(max_examples=100, deadline=None)
@given(STATES)
def test_the_state_encoder_gives_the_model_json_field_for_field_in_order(
    state: DriveState,
) -> None:
    data = strict_json(encode_state(state))
    assert data == model_doc(state)
    assert list(data) == list(state.to_json())  # the fields in their documented order


def strict_json(payload: bytes) -> Any:
    def refuse(token: str) -> None:
        raise AssertionError(f"{token} is not JSON")

    return json.loads(payload, parse_constant=refuse)


def test_a_value_json_cannot_hold_becomes_null() -> None:
    state = DriveState(id="d", device=Device.TEST, bus="b", address=1, speed_rpm=math.nan)
    bad = state.changed(fault_code=math.inf, values={"x": math.nan, "y": 1})  # wrong types
    for s in (state, bad):
        data = strict_json(encode_state(s))
        assert data["speed_rpm"] is None
    data = strict_json(encode_state(bad))
    assert (data["fault_code"], data["values"]) == (None, {"x": None, "y": 1})


def running_drive(speed_rpm: float, values: dict[str, float | int]) -> DriveState:
    return DriveState(
        id="d1",
        device=Device.CFW11,
        bus="line1",
        address=3,
        comm=CommState.ONLINE,
        status=DriveStatus.RUNNING,
        speed_rpm=speed_rpm,
        values=values,
    )


def test_the_published_state_is_the_model_json() -> None:
    state = running_drive(math.inf, {"P0002": 5})
    assert json.loads(encode_state(state)) == state.to_json()
    assert json.loads(encode_state(state))["speed_rpm"] is None
    assert encode_json({"x": {1, 2} and object}).startswith(b'{"x":"<class')


CHANGES = st.fixed_dictionaries(
    {},
    optional={
        "comm": st.sampled_from(CommState),
        "status": st.sampled_from(DriveStatus),
        "running": st.booleans(),
        "speed_rpm": FLOATS | st.just(math.nan),
        "current_a": FLOATS,
        "fault_code": st.none() | st.integers(0, 65535),
        "fault_text": st.none() | st.text(max_size=8),
        "seq": st.integers(0, 2**40),
        "ts": st.floats(0, 2e9),
        "values": st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    },
)


def model_doc(state: DriveState) -> dict[str, Any]:
    """``to_json`` with every non-finite number made null, as published."""
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in state.to_json().items()
    }


@settings(max_examples=100, deadline=None)
@given(STATES, st.lists(CHANGES, max_size=8))
def test_states_derived_as_the_hub_does_encode_like_the_model_json(
    first: DriveState, steps: list[dict[str, Any]]
) -> None:
    state = first
    for changes in steps:
        state = state.changed(**changes)
        data = strict_json(encode_state(state))
        assert data == model_doc(state)
        assert list(data) == list(state.to_json())


def test_a_state_holds_its_fields_in_their_order_however_it_was_made() -> None:
    """The encoder writes a state's ``__dict__`` as it is: its fields, nothing else,
    in the order of the JSON form."""
    import pickle

    order = list(DriveState(id="d", device=Device.TEST, bus="b", address=1).to_json())
    base = DriveState(id="d", device=Device.TEST, bus="b", address=1, values={"P1": 2})
    made = [
        base,
        base.changed(ts=2.0, speed_rpm=1.0),
        base.changed(fault_code=3),
        DriveState.from_json(base.to_json()),
        pickle.loads(pickle.dumps(base.changed(seq=7))),
    ]
    for state in made:
        assert list(state.__dict__) == order


def test_a_state_of_plain_values_never_takes_the_slow_path(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Only what orjson cannot write falls back to ``to_json`` and the json module."""
    from gateway.zenoh import requests

    def slow(obj: Any) -> bytes:
        raise AssertionError("the slow path")

    state = running_drive(math.nan, {"P0002": 5, "P0003": 1.5})
    monkeypatch.setattr(requests, "encode_json", slow)
    for s in (state, state.changed(speed_rpm=1750.0, seq=9, ts=1.5)):
        assert strict_json(encode_state(s)) == model_doc(s)
    with pytest.raises(AssertionError, match="the slow path"):
        encode_state(state.changed(seq=2**64))  # beyond what orjson writes


def test_states_still_pickle_and_compare_by_their_fields() -> None:
    import pickle

    base = DriveState(id="d", device=Device.TEST, bus="b", address=1)
    child = base.changed(speed_rpm=1.0)
    again = pickle.loads(pickle.dumps(child))
    assert again == child == base.changed(speed_rpm=1.0)
