"""The Zenoh contract against a real gateway process: two peers on tcp/127.0.0.1.

The gateway runs as ``python -m gateway run`` with fake-adapter drives; the
client session in the test connects to its endpoint. Each test uses its own
drive so the tests share one gateway process.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from gateway.model import EXTRA_JSON_FIELDS, JSON_FIELDS
from tests.support.timing import scaled
from tests.zenoh.client import Client, Got, Inbox
from tests.zenoh.conftest import HEARTBEAT, PREFIX, GatewayProcess, start_gateway

JSON_ENCODING = "application/json"


def key(drive: str, what: str) -> str:
    return f"{PREFIX}/drives/{drive}/{what}"


def states_until(
    inbox: Inbox[Got], predicate: Callable[[dict[str, Any]], bool], timeout: float = 5.0
) -> dict[str, Any]:
    state: dict[str, Any] = inbox.until(lambda s: predicate(s.json()), timeout).json()
    return state


def quiet_heartbeats(inbox: Inbox[Got], drive: str, repeats: int = 2) -> dict[str, Any]:
    """Wait until the drive's state repeats unchanged ``repeats`` times (nothing moved)."""
    last: dict[str, Any] | None = None
    same = 0
    while same < repeats:
        state = inbox.get(timeout=5 * HEARTBEAT).json()
        assert state["id"] == drive
        same = same + 1 if last is not None and state["seq"] == last["seq"] else 0
        last = state
    assert last is not None
    return last


def test_states_arrive_as_json_and_repeat_every_heartbeat(client: Client) -> None:
    with client.subscribe(key("soft", "state")) as inbox:
        # the drive settles first (its bus starts once the front ends serve): from the
        # first repeat of an online state on, every sample is a heartbeat repeat
        last = inbox.get(timeout=scaled(50 * HEARTBEAT))
        while True:
            got = inbox.get(timeout=scaled(5 * HEARTBEAT))
            if got.json()["comm"] == "online" and got.json()["seq"] == last.json()["seq"]:
                break
            last = got
        samples: list[Got] = [got] + [inbox.get(timeout=5 * HEARTBEAT) for _ in range(3)]
    first = samples[0].json()
    assert list(first) == list(JSON_FIELDS + EXTRA_JSON_FIELDS)
    assert first["id"] == "soft"
    assert first["device"] == "MCD 600"
    assert first["comm"] == "online"
    assert first["speed_rpm"] is None  # a soft starter has no speed
    assert all(s.encoding == JSON_ENCODING for s in samples)
    assert all(s.congestion == "CongestionControl.BLOCK" for s in samples)
    # nothing changes on the soft starter: the heartbeat repeats the same state
    assert len({s.json()["seq"] for s in samples}) == 1
    # a repeat per heartbeat, not a busy loop: each sample came within 5 heartbeats (the
    # wait above), and the repeats are spaced by the heartbeat on average (a client held
    # up for a moment can receive two at once, so no single gap is judged)
    span = samples[-1].at - samples[1].at
    assert span >= 0.25 * HEARTBEAT * (len(samples) - 2), [s.at for s in samples]


def test_state_query_answers_latest_states_with_wildcards(client: Client) -> None:
    replies = client.query(f"{PREFIX}/drives/*/state")
    assert sorted(str(r.key) for r in replies if r.ok) == [
        key(d, "state") for d in ("d1", "d2", "soft")
    ]
    assert all(r.json()["comm"] == "online" for r in replies)
    unknown = client.one(key("nope", "state"))
    assert not unknown.ok and "no drive state" in unknown.json()["error"]


def test_command_query_runs_the_drive_and_its_state_follows(client: Client) -> None:
    with client.subscribe(key("d1", "state")) as states:
        reply = client.one(key("d1", "command"), {"run": True, "speed_rpm": 900})
        assert reply.ok and reply.key == key("d1", "command")
        assert reply.json() == {"accepted": True}
        ramping = states_until(states, lambda s: s["running"] and 0 < s["speed_rpm"] < 900)
        assert ramping["status"] in ("starting", "running")
        state = states_until(states, lambda s: s["speed_rpm"] == 900.0 and s["at_reference"])
        assert state["control_source"] == "zenoh"
        assert state["status"] == "running"
        client.put(key("d1", "command"), {"run": False})  # a put is fire and forget
        states_until(states, lambda s: not s["running"] and s["speed_rpm"] == 0.0)


REFUSED: list[tuple[str, object, str]] = [
    ("d2", {"run": True, "bogus": 1}, "unknown field(s): bogus"),
    ("d2", {"run": "yes"}, "run must be true or false"),
    ("d2", {"run": True, "speed_rpm": 99999}, "beyond the drive's scale"),
    ("d2", {"run": True, "speed_pct": -250}, "beyond the drive's scale"),
    ("d2", {"run": True, "speed_rpm": 100, "speed_pct": 10}, "not both"),
    ("d2", {"run": True, "fault_reset": True}, "not in the same command"),
    ("d2", [1, 2], "a command is a JSON object"),
    ("d2", b'{"run": tru', "invalid JSON"),
    ("d2", b"\xff\xfe", "not UTF-8"),
    ("d2", b"", "payload is empty"),
    ("soft", {"run": True, "speed_pct": 10}, "MCD 600 has no speed reference"),
    ("soft", {"run": True, "direction": "reverse"}, "no direction"),
    ("nope", {"run": True}, "no drive 'nope'"),
]


def test_refused_commands_get_the_reason_and_change_nothing(client: Client) -> None:
    with client.subscribe(key("d2", "state")) as d2, client.subscribe(key("soft", "state")) as soft:
        before = {"d2": quiet_heartbeats(d2, "d2", 1), "soft": quiet_heartbeats(soft, "soft", 1)}
        for drive, payload, reason in REFUSED:
            reply = client.one(key(drive, "command"), payload)
            assert reply.ok, (payload, reply)
            body = reply.json()
            assert body["accepted"] is False, payload
            assert reason in body["error"], (payload, body)
        # the states repeat unchanged: nothing of any refused command was applied
        after = {"d2": quiet_heartbeats(d2, "d2"), "soft": quiet_heartbeats(soft, "soft")}
    for drive in ("d2", "soft"):
        assert not after[drive]["running"]
        assert after[drive]["control_source"] == before[drive]["control_source"]


def test_refused_put_is_reported_on_the_events_key(client: Client) -> None:
    with client.subscribe(key("d2", "events")) as events:
        client.put(key("d2", "command"), {"run": True, "bogus": True})
        event = events.until(lambda e: e.json()["kind"] == "command_refused").json()
        assert event["drive"] == "d2"
        assert "unknown field(s): bogus" in event["text"]
        assert event["source"] == "zenoh"
        client.put(key("d2", "command"), b"not json")
        event = events.until(lambda e: "invalid JSON" in e.json()["text"]).json()
        assert event["kind"] == "command_refused"


def test_wildcard_command_query_is_refused(client: Client) -> None:
    replies = client.query(f"{PREFIX}/drives/*/command", {"run": True})
    assert len(replies) == 1
    assert not replies[0].ok
    assert "names one drive" in replies[0].json()["error"]


def test_parameters_read_and_write_round_trip(client: Client) -> None:
    read = client.one(key("d2", "params/100"))
    assert read.ok and read.json() == {
        "number": 100,
        "subindex": 0,
        "value": 50,
        # the drive's parameter table (Capabilities.params) names P100 and scales it
        "code": "P0100",
        "name": "Acceleration time",
        "unit": "s",
        "scaled": 5.0,
    }
    written = client.one(key("d2", "params/101"), {"value": 1234})
    assert written.ok and written.json() == {"number": 101, "subindex": 0, "value": 1234}
    again = client.one(key("d2", "params/101/0"))
    assert again.ok and again.json() == {"number": 101, "subindex": 0, "value": 1234}


@pytest.mark.parametrize(
    ("path", "payload", "error"),
    [
        ("params/100", {"value": 99999}, {"error": "parameter value out of limits", "code": 2}),
        ("params/999", None, {"error": "impermissible parameter number", "code": 0}),
        ("params/2", {"value": 1}, {"error": "parameter 2 is not in writable_params of drive d2"}),
        ("params/abc", None, {"error": "parameter number must be a decimal number, not 'abc'"}),
        ("params/100", {"value": "high"}, {"error": "value must be a number, not 'high'"}),
        (
            "params/100",
            b"{",
            {
                "error": "invalid JSON: Expecting property name enclosed in double quotes at position 1"
            },
        ),
    ],
)
def test_parameter_errors_come_back_as_error_replies(
    client: Client, path: str, payload: object, error: dict[str, Any]
) -> None:
    reply = client.one(key("d2", path), payload)
    assert not reply.ok
    assert reply.encoding == JSON_ENCODING
    assert reply.json() == error
    assert client.one(key("d2", "params/100")).json()["value"] == 50  # nothing written


def test_health_query_answers(client: Client) -> None:
    reply = client.one(f"{PREFIX}/gateway/health")
    assert reply.ok and reply.key == f"{PREFIX}/gateway/health"
    health = reply.json()
    assert health["version"]
    assert health["uptime_s"] > 0
    assert health["drives"] == 3
    assert sorted(health["buses"]["line1"]["live"]) == ["d1", "d2", "soft"]
    assert health["buses"]["line1"]["cycles"] > 0


def test_diag_is_published_every_heartbeat(client: Client) -> None:
    with client.subscribe(key("d2", "diag")) as diag:
        first, second = diag.get(5 * HEARTBEAT), diag.get(5 * HEARTBEAT)
    assert first.json()["id"] == "d2"
    assert first.json()["bus"] == "line1"
    assert second.json()["cycles"] > first.json()["cycles"]


def test_every_token_disappears_when_the_gateway_process_is_killed(tmp_path: Path) -> None:
    gw: GatewayProcess = start_gateway(tmp_path)
    c = Client(gw.endpoint)
    try:
        with c.liveliness(f"{PREFIX}/**") as live:
            expected = {
                f"{PREFIX}/gateway",
                *(f"{PREFIX}/drives/{d}" for d in ("d1", "d2", "soft")),
            }
            present: set[str] = set()
            while present != expected:
                sample = live.get(timeout=10)
                assert sample.put
                present.add(sample.key)
            gw.kill()
            while present:
                sample = live.get(timeout=10)
                assert not sample.put, sample
                present.discard(sample.key)
    finally:
        c.close()
        gw.kill()


def test_params_without_a_number_is_the_whole_backup(client: Client) -> None:
    """``<prefix>/drives/<id>/params`` (issue 24): the backup document, not an error."""
    reply = client.one(key("d2", "params"))
    assert reply.ok, reply.payload
    doc = reply.json()
    assert doc["schema"] == "drive-gateway/params-backup" and doc["version"] == 1
    assert any(p["number"] == 100 and p["raw"] == 50 for p in doc["params"])
