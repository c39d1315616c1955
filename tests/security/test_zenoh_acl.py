"""The shipped config/zenoh-secure.json5 against a real gateway process.

The gateway runs as ``python -m gateway run`` with fake-adapter drives and
``zenoh.config_file`` pointing at a copy of the example in which only the
certificate paths and the listen port differ (everything on 127.0.0.1). A CA and
the certificates are made at test time (tests/security/pki.py).

Each identity is a Zenoh client session over tls/ with its certificate:
``scada-readonly`` watches and is refused control, ``scada-operator`` commands,
an identity the config does not name gets nothing, and a client without a
certificate signed by the CA does not connect at all.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import zenoh
from zenoh.ext import HistoryConfig, RecoveryConfig, declare_advanced_subscriber

from tests.security.pki import Identity, TestCA
from tests.support.net import free_port
from tests.support.plugins import pythonpath
from tests.support.timing import scaled
from tests.zenoh.client import Client, Got, Inbox

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "zenoh-secure.json5"
FAKE = "fake"  # tests/support/plugins.py
PREFIX = "plant/line3"  # the prefix the example's rules name
PLACEHOLDER_DIR = "/etc/drive-gateway/tls/"
PLACEHOLDER_LISTEN = "tls/0.0.0.0:7447"
HEARTBEAT = 0.2
READY_LINE = "zenoh front end serving"
RUN_900 = {"run": True, "speed_rpm": 900}
TIMEOUT = scaled(30.0)
DRIVES = ("d1", "d2", "d3", "d4")
READONLY_DRIVE = {"client": "d1", "peer": "d4"}  # a drive per session mode


def key(drive: str, what: str) -> str:
    return f"{PREFIX}/drives/{drive}/{what}"


# ---------------------------------------------------------------- the config under test


def secure_config_text(tls_dir: Path, port: int) -> str:
    """The shipped example with this test's certificate directory and listen port."""
    text = EXAMPLE.read_text(encoding="utf-8")
    assert text.count(PLACEHOLDER_LISTEN) == 1, "the example must listen on one tls/ endpoint"
    assert PLACEHOLDER_DIR in text
    text = text.replace(PLACEHOLDER_DIR, f"{tls_dir}/").replace(
        PLACEHOLDER_LISTEN, f"tls/127.0.0.1:{port}"
    )
    return text


def gateway_toml() -> str:
    """d1 and d4: the read-only identity tries them (as a client, as a peer); d2: the
    operator's; d3: the unknown identity's."""
    drives = "".join(
        f"""
[[buses.line1.drives]]
id = "{drive_id}"
device = "test"
address = {address}
ramp_time = 0.1
writable_params = [100, 101]
"""
        for address, drive_id in enumerate(DRIVES, start=3)
    )
    return f"""
[gateway]
shutdown_timeout = 2.0
[zenoh]
prefix = "{PREFIX}"
heartbeat = {HEARTBEAT}
config_file = "zenoh-secure.json5"
[modbus]
enabled = false
[history]
enabled = true
path = "history.sqlite"
period = 0.1
batch_interval = 0.1
[buses.line1]
adapter = "{FAKE}"
cycle = 0.01
{drives}"""


def session_config(
    endpoint: str, ca: Path | None, identity: Identity | None, mode: str = "client"
) -> zenoh.Config:
    """A SCADA session as docs/operations.md describes it: connect only, no scouting."""
    tls: dict[str, Any] = {}
    if ca is not None:
        tls["root_ca_certificate"] = str(ca)
    if identity is not None:
        # enable_mtls on the connecting side: without it Zenoh does not send the certificate
        tls |= {
            "connect_certificate": str(identity.cert),
            "connect_private_key": str(identity.key),
            "enable_mtls": True,
        }
    doc = {
        "mode": mode,
        "connect": {"endpoints": [endpoint]},
        "listen": {"endpoints": []},
        "scouting": {"delay": 50, "multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"tls": tls}},
    }
    return zenoh.Config.from_json5(json.dumps(doc))


class Scada(Client):
    """The tests' Zenoh client (tests/zenoh/client.py), on a TLS session."""

    def __init__(self, config: zenoh.Config) -> None:
        self.loop = None
        self.session = zenoh.open(config)
        self.mode = "client"


# ---------------------------------------------------------------- the gateway process


class SecureGateway:
    """``python -m gateway run --config F`` (nothing overridden on the command line)."""

    def __init__(self, config: Path) -> None:
        env = {**os.environ, "PYTHONPATH": pythonpath()}
        env.pop("NOTIFY_SOCKET", None)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "gateway", "run", "--config", str(config)],
            cwd=ROOT,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.log: list[str] = []
        self._reader = threading.Thread(target=self._read, name="secure-gw-stderr", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.log.append(line)
            self.lines.put(line)
        self.lines.put("")

    def wait_for_line(self, text: str, timeout: float = 20.0) -> None:
        while True:
            line = self.lines.get(timeout=timeout)
            if not line:
                raise AssertionError(f"gateway exited before {text!r}:\n{''.join(self.log)}")
            if text in line:
                return

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        self._reader.join(5)
        return code


@dataclass
class Site:
    endpoint: str
    ca: TestCA
    readonly: Identity
    operator: Identity
    unknown: Identity
    gateway: SecureGateway

    def open(self, identity: Identity | None, mode: str = "client") -> Scada:
        return Scada(session_config(self.endpoint, self.ca.cert_path, identity, mode))


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Site]:
    tmp = tmp_path_factory.mktemp("secure")
    ca = TestCA(tmp / "tls")
    gateway_id = ca.issue("gateway", hosts=("127.0.0.1", "localhost"))
    # the example names the gateway's files gateway.pem and gateway.key
    assert (gateway_id.cert.name, gateway_id.key.name) == ("gateway.pem", "gateway.key")
    port = free_port()
    (tmp / "zenoh-secure.json5").write_text(secure_config_text(tmp / "tls", port))
    (tmp / "site.toml").write_text(gateway_toml())
    gw = SecureGateway(tmp / "site.toml")
    try:
        gw.wait_for_line(READY_LINE)
        yield Site(
            endpoint=f"tls/127.0.0.1:{port}",
            ca=ca,
            readonly=ca.issue("scada-readonly"),
            operator=ca.issue("scada-operator"),
            unknown=ca.issue("scada-intruder"),
            gateway=gw,
        )
    finally:
        code = gw.stop()
    assert code == 0, "".join(gw.log)


@pytest.fixture(scope="module")
def operator(site: Site) -> Iterator[Scada]:
    client = site.open(site.operator)
    try:
        with client.liveliness(f"{PREFIX}/gateway") as live:
            live.until(lambda s: s.put, timeout=10)
        yield client
    finally:
        client.close()


@pytest.fixture(params=["client", "peer"])
def readonly(site: Site, request: pytest.FixtureRequest) -> Iterator[Scada]:
    """The read-only identity, as a Zenoh client and as a peer (SCADA may be either)."""
    client = site.open(site.readonly, mode=request.param)
    client.mode = request.param
    try:
        yield client
    finally:
        client.close()


# ---------------------------------------------------------------- helpers


def states(inbox: Inbox[Got], count: int) -> list[dict[str, Any]]:
    """The next ``count`` states (one per heartbeat at least)."""
    return [inbox.get(timeout=5 * HEARTBEAT).json() for _ in range(count)]


def until(
    inbox: Inbox[Got], predicate: Callable[[dict[str, Any]], bool], timeout: float = 5.0
) -> dict[str, Any]:
    state: dict[str, Any] = inbox.until(lambda s: predicate(s.json()), timeout).json()
    return state


def quiet(inbox: Inbox[Got]) -> dict[str, Any]:
    """The drive's state once a heartbeat repeats it unchanged (same ``seq``)."""
    last: dict[str, Any] = {}
    while True:
        state: dict[str, Any] = inbox.get(timeout=5 * HEARTBEAT).json()
        if state["seq"] == last.get("seq"):
            return state
        last = state


def round_trip(client: Scada) -> None:
    """A query the identity may make: everything it sent before has reached the gateway
    and been handled (one link, in order), whatever access control did with it."""
    reply = client.one(f"{PREFIX}/gateway/health")
    assert reply.ok, reply


def untouched(state: dict[str, Any]) -> bool:
    return not state["running"] and state["speed_rpm"] == 0.0 and state["control_source"] == "none"


# ---------------------------------------------------------------- the example itself


def test_the_example_loads_and_asks_for_mtls_and_deny_by_default(tmp_path: Path) -> None:
    path = tmp_path / "zenoh-secure.json5"
    path.write_text(secure_config_text(tmp_path, 7447))
    config = zenoh.Config.from_file(str(path))
    tls = json.loads(config.get_json("transport/link/tls"))
    assert tls["enable_mtls"] is True
    assert tls["root_ca_certificate"] == f"{tmp_path}/ca.pem"
    assert tls["listen_certificate"] == f"{tmp_path}/gateway.pem"
    assert tls["listen_private_key"] == f"{tmp_path}/gateway.key"
    assert json.loads(config.get_json("transport/link/protocols")) == ["tls"]
    assert json.loads(config.get_json("listen/endpoints")) == ["tls/127.0.0.1:7447"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    acl = json.loads(config.get_json("access_control"))
    assert acl["enabled"] is True
    assert acl["default_permission"] == "deny"
    names = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert names == {"scada-readonly": ["scada-readonly"], "scada-operator": ["scada-operator"]}


# ---------------------------------------------------------------- identities


def test_read_only_identity_watches_states_liveliness_and_health(
    site: Site, readonly: Scada
) -> None:
    with readonly.liveliness(f"{PREFIX}/**") as live:
        tokens: set[str] = set()
        while len(tokens) < len(DRIVES) + 1:
            tokens.add(live.until(lambda s: s.put).key)
    assert tokens == {f"{PREFIX}/gateway", *(f"{PREFIX}/drives/{d}" for d in DRIVES)}
    with readonly.subscribe(f"{PREFIX}/drives/*/state") as inbox:
        seen = {s["id"] for s in states(inbox, 3 * len(DRIVES))}
    assert seen == set(DRIVES)
    replies = readonly.query(f"{PREFIX}/drives/*/state")
    assert sorted(str(r.key) for r in replies if r.ok) == [key(d, "state") for d in DRIVES]
    health = readonly.one(f"{PREFIX}/gateway/health")
    assert health.ok and health.json()["drives"] == len(DRIVES)


def test_read_only_identity_commands_and_parameter_writes_are_never_applied(
    site: Site, readonly: Scada, operator: Scada
) -> None:
    drive = READONLY_DRIVE[readonly.mode]
    with readonly.subscribe(key(drive, "state")) as inbox:
        before = quiet(inbox)
        assert untouched(before), before
        # a query is not even routed to the gateway: no reply at all, not a refusal
        assert readonly.query(key(drive, "command"), RUN_900) == []
        readonly.put(key(drive, "command"), RUN_900)
        assert readonly.query(key(drive, "params/100"), {"value": 1234}) == []
        assert readonly.query(key(drive, "params/100")) == []  # a read is the same query
        round_trip(readonly)
        # the drive's desired command is unchanged: control would pass to zenoh at once
        now = operator.one(key(drive, "state")).json()
        assert untouched(now) and now["seq"] == before["seq"], now
        # and stays so, heartbeat after heartbeat
        assert all(untouched(s) for s in states(inbox, 3))
        assert operator.one(key(drive, "params/100")).json()["value"] == 50
        # the very same command from the operator runs the drive, and the read-only
        # identity sees it: the check above could have failed
        assert operator.one(key(drive, "command"), RUN_900).json() == {"accepted": True}
        running = until(inbox, lambda s: s["running"] and s["speed_rpm"] == 900.0)
        assert running["control_source"] == "zenoh"
        operator.put(key(drive, "command"), {"run": False})
        until(inbox, lambda s: not s["running"] and s["speed_rpm"] == 0.0)


def test_operator_identity_writes_allowed_parameters_and_events_reach_read_only(
    site: Site, readonly: Scada, operator: Scada
) -> None:
    with readonly.subscribe(key("d2", "events")) as events:
        round_trip(readonly)  # the subscription is in place at the gateway
        written = operator.one(key("d2", "params/101"), {"value": 1234})
        assert written.ok and written.json() == {"number": 101, "subindex": 0, "value": 1234}
        event = events.until(lambda e: e.json()["kind"] == "parameter").json()
    assert event["drive"] == "d2"
    # access control lets the operator ask; writable_params still refuses parameter 2
    refused = operator.one(key("d2", "params/2"), {"value": 1})
    assert not refused.ok
    assert refused.json() == {"error": "parameter 2 is not in writable_params of drive d2"}
    assert operator.one(key("d2", "params/2")).json()["value"] == 0


def test_read_only_identity_recovers_missed_events_and_reads_the_history(
    site: Site, readonly: Scada, operator: Scada
) -> None:
    """Events the read-only identity was away for come back to its advanced subscriber
    from the gateway's cache (the @adv keys the example allows), and it may query the
    history key."""
    marker = f"acl{time.monotonic_ns()}"
    texts = [f"{marker}_{i}" for i in range(5)]
    with operator.subscribe(key("d2", "events")) as published:
        round_trip(operator)
        for text in texts:  # each refused with its own text: an event each
            operator.put(key("d2", "command"), {text: 1})
        seen: list[str] = []  # published while the read-only identity had no subscriber
        while sum(marker in t for t in seen) < len(texts):
            seen.append(published.get(timeout=TIMEOUT).json()["text"])
    back: Inbox[str] = Inbox()
    sub = declare_advanced_subscriber(
        readonly.session,
        key("d2", "events"),
        lambda sample: back.push(json.loads(sample.payload.to_string())["text"]),
        history=HistoryConfig(detect_late_publishers=True, max_samples=100),
        recovery=RecoveryConfig(periodic_queries=None, heartbeat=True),
        subscriber_detection=True,
    )
    try:
        got: list[str] = []
        while sum(marker in t for t in got) < len(texts):
            got.append(back.get(timeout=TIMEOUT))
    finally:
        sub.undeclare()
    assert [t.split(": ")[-1] for t in got if marker in t] == texts
    history = readonly.one(f"{key('d1', 'history')}?start=now-1h")
    assert history.ok and history.json()["drive"] == "d1", history


def test_each_links_certificate_name_is_on_the_audit_trail(
    site: Site, readonly: Scada, operator: Scada
) -> None:
    round_trip(readonly)  # both links are up
    records = operator.one(f"{PREFIX}/gateway/audit").json()["records"]
    opened = [r for r in records if r["type"] == "link_open"]
    assert {"scada-operator", "scada-readonly"} <= {r["identity"] for r in opened}
    mine = next(r for r in opened if r["identity"] == "scada-operator")
    assert (mine["interface"], mine["category"], mine["event_id"]) == ("zenoh", "access", 1005)
    assert mine["detail"].endswith(", certificate scada-operator")
    # the audit trail is not for the read-only identity: the access control stops the query
    assert readonly.query(f"{PREFIX}/gateway/audit") == []


def test_an_identity_the_config_does_not_name_gets_nothing(site: Site, operator: Scada) -> None:
    intruder = site.open(site.unknown)  # a valid certificate: the TLS link is accepted
    try:
        with intruder.subscribe(key("d3", "state")) as inbox:
            assert intruder.query(f"{PREFIX}/gateway/health") == []
            assert intruder.query(key("d3", "state")) == []
            assert intruder.query(key("d3", "command"), RUN_900) == []
            intruder.put(key("d3", "command"), RUN_900)
            with operator.subscribe(key("d3", "state")) as d3:
                # three heartbeats reach the operator, none the intruder
                assert all(untouched(s) for s in states(d3, 3))
            with pytest.raises(queue.Empty):
                inbox.get(timeout=0)
    finally:
        intruder.close()


@pytest.mark.parametrize(
    "how",
    ["without a certificate", "with a certificate of another CA", "over plain tcp"],
)
def test_a_client_without_a_certificate_of_the_ca_cannot_connect(
    site: Site, tmp_path: Path, how: str
) -> None:
    endpoint = site.endpoint
    ca: Path | None = site.ca.cert_path
    identity: Identity | None = None
    if how == "with a certificate of another CA":
        identity = TestCA(tmp_path / "other").issue("scada-operator")  # the right name, too
    elif how == "over plain tcp":
        endpoint, ca = endpoint.replace("tls/", "tcp/"), None
    config = session_config(endpoint, ca, identity)
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        zenoh.open(config)
    assert site.gateway.proc.poll() is None  # the gateway shrugs it off
