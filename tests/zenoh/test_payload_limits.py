"""Issue 18, memory and load on the Zenoh side, against a gateway process.

- shared memory is off in the gateway's session unless the user's config file asks;
- command and parameter payloads over MAX_PAYLOAD are refused before they are parsed;
- deeply nested JSON is refused like any other bad command (put and query);
- a same-host client that puts large payloads (its own session with Zenoh's shared
  memory on, as by default) does not make the gateway grow.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gateway.config import ZenohSection
from gateway.zenoh.requests import MAX_PAYLOAD
from gateway.zenoh.session import SHARED_MEMORY_KEY, zenoh_config
from tests.support.timing import scaled
from tests.zenoh.client import Client
from tests.zenoh.conftest import PREFIX, GatewayProcess

CMD = f"{PREFIX}/drives/d2/command"


def shared_memory(section: ZenohSection) -> object:
    return json.loads(zenoh_config(section).get_json(SHARED_MEMORY_KEY))


def test_the_gateways_session_has_shared_memory_off(tmp_path: Path) -> None:
    assert shared_memory(ZenohSection(listen=("tcp/127.0.0.1:7447",))) is False
    plain = tmp_path / "plain.json5"
    plain.write_text('{ mode: "peer", scouting: { multicast: { enabled: false } } }')
    assert shared_memory(ZenohSection(config_file=plain)) is False
    asks = tmp_path / "shm.json5"
    asks.write_text("{ transport: { shared_memory: { enabled: true } } }")
    assert shared_memory(ZenohSection(config_file=asks)) is True


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        (b"{" + b" " * MAX_PAYLOAD + b"}", f"payload of {MAX_PAYLOAD + 2} bytes is over the limit"),
        (b"[" * 100_000, "payload of 100000 bytes is over the limit"),
        (b"[" * 4000, "invalid JSON: nested too deeply"),
        (b'{"run": ' + b"[" * 2000 + b"]" * 2000 + b"}", "invalid JSON: nested too deeply"),
    ],
)
def test_a_large_or_deep_command_query_is_refused(
    client: Client, payload: bytes, error: str
) -> None:
    reply = client.one(CMD, payload)
    body = reply.json()
    assert body["accepted"] is False and error in body["error"], body


def test_a_deep_command_put_is_refused_with_an_event(client: Client) -> None:
    with client.subscribe(f"{PREFIX}/drives/d2/events") as inbox:
        client.query(f"{PREFIX}/gateway/health")  # a round trip: the subscriber is declared there
        client.put(CMD, b"[" * 4000)
        got = inbox.until(lambda g: g.json()["kind"] == "command_refused", scaled(10.0))
    assert "nested too deeply" in got.json()["text"]


def test_a_large_parameter_write_is_refused(client: Client) -> None:
    reply = client.one(f"{PREFIX}/drives/d2/params/100", b"1" * (MAX_PAYLOAD + 1))
    assert not reply.ok
    assert f"payload of {MAX_PAYLOAD + 1} bytes is over the limit" in reply.payload.decode()


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def test_large_payloads_from_same_host_sessions_leave_rss_flat(
    gateway: GatewayProcess, client: Client
) -> None:
    """Sessions with Zenoh's defaults (shared memory on), each with its own 16 MB pool,
    put and query with payloads over 3 KB. Before the fix the gateway mapped each
    session's segment and never gave it back."""
    big = b"x" * 8192

    def session_round() -> None:
        other = Client(gateway.endpoint)
        try:
            for _ in range(20):
                other.put(CMD, big)
                other.one(CMD, big)
        finally:
            other.close()

    session_round()  # warm-up
    before = rss_kib(gateway.proc.pid)
    for _ in range(12):
        session_round()
    after = rss_kib(gateway.proc.pid)
    assert after - before < 40 * 1024, (before, after)
