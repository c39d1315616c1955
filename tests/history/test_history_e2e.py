"""Issue 37, through a real gateway process (``python -m gateway run``, fake-adapter
drives, a real Zenoh session on 127.0.0.1): the history across a restart and across a
SIGKILL, the history key's answers to bad parameters, and events recovered by an advanced
subscriber whose session was cut."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh
from zenoh.ext import HistoryConfig, RecoveryConfig, declare_advanced_subscriber

from gateway.history.store import HistoryDb, HistoryStore
from tests.support.net import zenoh_endpoint
from tests.support.tcpcut import TcpCut
from tests.support.timing import scaled
from tests.zenoh.client import Client, Inbox, client_config
from tests.zenoh.conftest import HEARTBEAT, READY_LINE, GatewayProcess, gateway_config

PREFIX = "demo"
TIMEOUT = scaled(30.0)
PERIOD = 0.1  # s between samples: seconds-long tests see tens of them


@dataclass(frozen=True)
class Running:
    process: GatewayProcess
    path: Path


def history_config(path: Path, cache: int = 100, heartbeat: float = HEARTBEAT) -> str:
    config = gateway_config(heartbeat).replace(
        "multicast_scouting = false", f"multicast_scouting = false\nrecovery_cache = {cache}"
    )
    return config + (
        f'\n[history]\nenabled = true\npath = "{path}"\nperiod = {PERIOD}\nbatch_interval = 0.2\n'
    )


def start(tmp: Path, path: Path, heartbeat: float = HEARTBEAT) -> GatewayProcess:
    cfg = tmp / "gateway.toml"
    cfg.write_text(history_config(path, heartbeat=heartbeat))
    gw = GatewayProcess(cfg, zenoh_endpoint())
    try:
        gw.wait_for_line(READY_LINE, TIMEOUT)
    except BaseException:
        gw.kill()
        raise
    return gw


@pytest.fixture
def running(tmp_path: Path) -> Iterator[Callable[[], GatewayProcess]]:
    started: list[GatewayProcess] = []

    def run() -> GatewayProcess:
        gw = start(tmp_path, tmp_path / "history.sqlite")
        started.append(gw)
        return gw

    yield run
    for gw in started:
        gw.stop()


def connected(endpoint: str) -> Client:
    """A client session that sees the gateway (its liveliness token): its queries and puts
    reach the gateway's queryables and subscriber."""
    client = Client(endpoint)
    try:
        with client.liveliness(f"{PREFIX}/gateway") as live:
            live.until(lambda got: got.put, TIMEOUT)
    except BaseException:
        client.close()
        raise
    return client


def until(condition: Callable[[], bool], what: str, within: float = TIMEOUT) -> None:
    """Until ``condition()`` holds (the writer's commits, seen in the file), bounded."""
    deadline = time.monotonic() + within
    while not condition():
        assert time.monotonic() < deadline, f"not within {within:g} s: {what}"
        time.sleep(0.05)


def samples(store: HistoryStore, drive: str = "d1") -> list[float]:
    return [r.t for r in store.readings(drive, 0, time.time() + 60)]


def test_history_survives_a_restart_and_is_served_on_zenoh(
    tmp_path: Path, running: Callable[[], GatewayProcess]
) -> None:
    store = HistoryStore(tmp_path / "history.sqlite")
    gw = running()
    until(lambda: len(samples(store)) >= 10, "10 samples of d1 committed")
    assert gw.stop() == 0
    before = samples(store)
    shut = [e.text for e in store.events("d1", 0, time.time() + 60)]
    assert any("gateway shutting down" in text for text in shut), shut  # the last events too
    gw = running()
    until(lambda: len(samples(store)) >= len(before) + 10, "10 more samples after a restart")
    client = connected(gw.endpoint)
    try:
        reply = client.query(f"{PREFIX}/drives/d1/history?start=0", timeout=scaled(10))
        assert len(reply) == 1 and reply[0].ok, reply
        body = reply[0].json()
        assert body["t"][: len(before)] == before  # the first run's samples, as they were
        assert len(body["t"]) > len(before)
        assert set(body["values"]) >= {"speed_rpm"}
        events = client.query(f"{PREFIX}/drives/d1/history?events;start=0", timeout=scaled(10))
        assert events[0].ok, events
        texts = [e["text"] for e in events[0].json()["events"]]
        assert any("gateway shutting down" in t for t in texts), texts  # the first run's
        step = client.query(f"{PREFIX}/drives/d1/history?start=now-1d;step=1h", timeout=scaled(10))
        assert step[0].ok and len(step[0].json()["t"]) in (1, 2)
    finally:
        client.close()


@pytest.mark.parametrize(
    ("selector", "error"),
    [
        ("d1/history?start=yesterday", "start='yesterday' is not a time: seconds since"),
        ("d1/history?start=10;end=5", "end (5) is before start (10)"),
        ("d1/history?step=0", "step='0': a duration above 0 is needed"),
        ("d1/history?step=1;start=0", "buckets of 1 s: at most 100000 per query"),
        ("d1/history?from=0", "unknown parameter(s) from"),
        ("nope/history", "no drive 'nope'"),
        ("*/history", "a history query names one drive"),
    ],
)
def test_bad_history_queries_get_an_error_reply_naming_the_problem(
    history_gateway: Running, selector: str, error: str
) -> None:
    client = connected(history_gateway.process.endpoint)
    try:
        replies = client.query(f"{PREFIX}/drives/{selector}", timeout=scaled(10))
    finally:
        client.close()
    assert len(replies) == 1, replies
    assert not replies[0].ok
    assert error in replies[0].json()["error"]


@pytest.fixture(scope="module")
def history_gateway(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Running]:
    tmp = tmp_path_factory.mktemp("history")
    gw = start(tmp, tmp / "history.sqlite")
    yield Running(gw, tmp / "history.sqlite")
    gw.stop()


def test_a_sigkill_loses_at_most_the_last_batch(tmp_path: Path) -> None:
    path = tmp_path / "history.sqlite"
    store = HistoryStore(path)
    gw = start(tmp_path, path)
    try:
        until(lambda: len(samples(store)) >= 20, "20 samples of d1 committed")
        seen = samples(store)
    finally:
        gw.kill()  # SIGKILL: no shutdown, no last batch
    after = samples(store)
    assert after[: len(seen)] == seen  # every committed batch is there, in order
    HistoryDb.open_checked(path).close()  # and the file is sound (quick_check)


def advanced(session: zenoh.Session, key: str, inbox: Inbox[str]) -> object:
    return declare_advanced_subscriber(
        session,
        key,
        lambda sample: inbox.push(json.loads(sample.payload.to_string())["text"]),
        history=HistoryConfig(detect_late_publishers=True, max_samples=100),
        recovery=RecoveryConfig(periodic_queries=None, heartbeat=True),
        subscriber_detection=True,
    )


def refuse(endpoint: str, texts: list[str]) -> None:
    """One refused command per text (each its own event: no two fold into one)."""
    commander = connected(endpoint)
    try:
        for text in texts:
            commander.put(f"{PREFIX}/drives/d2/command", {text: 1})
    finally:
        commander.close()


def test_an_advanced_subscriber_gets_the_events_it_missed_while_away(
    history_gateway: Running,
) -> None:
    """An advanced subscriber gets an event live; its session is closed; N events happen
    (seen committed in the gateway's history, so they were published while it was away);
    a new session's advanced subscriber gets all N, in order, from the gateway's cache.
    The cut's length does not matter to the cache, which keeps the last
    ``recovery_cache`` events whatever their age: the cut lasts until the N are
    published and recorded."""
    key = f"{PREFIX}/drives/d2/events"
    endpoint = history_gateway.process.endpoint
    marker = f"m{time.monotonic_ns()}"
    live: Inbox[str] = Inbox()
    session = zenoh.open(client_config(endpoint))
    try:
        advanced(session, key, live)
        refuse(endpoint, [f"{marker}_live"])
        live.until(lambda text: f"{marker}_live" in text, TIMEOUT)
    finally:
        session.close()  # the cut
    n = 20
    refuse(endpoint, [f"{marker}_{i}" for i in range(n)])
    store = HistoryStore(history_gateway.path)

    def recorded() -> int:
        return sum(marker in e.text for e in store.events("d2", 0, time.time() + 60))

    until(lambda: recorded() == n + 1, f"{n} refusals recorded")
    back: Inbox[str] = Inbox()
    session = zenoh.open(client_config(endpoint))
    try:
        advanced(session, key, back)
        got: list[str] = []
        while sum(f"{marker}_" in t and "_live" not in t for t in got) < n:
            got.append(back.get(timeout=TIMEOUT))
    finally:
        session.close()
    missed = [t for t in got if marker in t and "_live" not in t]
    assert [t.split(": ")[-1] for t in missed] == [f"{marker}_{i}" for i in range(n)], missed


CUT = 30.0  # s the network is cut for (issue 37): longer than Zenoh's lease (10 s)


def test_an_advanced_subscriber_cut_off_for_30_s_gets_what_it_missed(
    history_gateway: Running,
) -> None:
    """The subscriber's session stays open while the network between it and the gateway
    is cut for 30 s (longer than Zenoh's 10 s lease: both ends drop the link); N events
    happen meanwhile (seen committed in the history, so published while it was cut off).
    When the network is back, the session connects again by itself and the same advanced
    subscriber gets all N, in order, and then the live ones."""
    key = f"{PREFIX}/drives/d2/events"
    endpoint = history_gateway.process.endpoint
    marker = f"c{time.monotonic_ns()}"
    store = HistoryStore(history_gateway.path)

    def recorded() -> int:
        return sum(marker in e.text for e in store.events("d2", 0, time.time() + 60))

    n = 20
    inbox: Inbox[str] = Inbox()
    with TcpCut(int(endpoint.rsplit(":", 1)[1])) as network:
        session = zenoh.open(client_config(f"tcp/127.0.0.1:{network.port}"))
        try:
            advanced(session, key, inbox)
            refuse(endpoint, [f"{marker}_live"])  # the commander is not behind the cut
            inbox.until(lambda text: f"{marker}_live" in text, TIMEOUT)
            network.cut()
            cut_at = time.monotonic()
            refuse(endpoint, [f"{marker}_{i}" for i in range(n)])
            until(lambda: recorded() == n + 1, f"{n} refusals recorded")
            time.sleep(max(0.0, CUT - (time.monotonic() - cut_at)))  # the cut's length
            assert network.accepted == 1  # nothing got through meanwhile
            network.restore()
            got: list[str] = []
            while sum(f"{marker}_" in t and "_live" not in t for t in got) < n:
                got.append(inbox.get(timeout=TIMEOUT))
            refuse(endpoint, [f"{marker}_after"])
            inbox.until(lambda text: f"{marker}_after" in text, TIMEOUT)
        finally:
            session.close()
    assert network.accepted >= 2  # the session connected again through the network
    missed = [t.split(": ")[-1] for t in got if marker in t and "_live" not in t]
    assert missed == [f"{marker}_{i}" for i in range(n)], missed
