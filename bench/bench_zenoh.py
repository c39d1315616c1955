"""Zenoh front end: state fan-out to a subscriber in another process, and command latency.

- State fan-out: the bench drives a hub flat out (``hub.update`` on 10 drives, the
  loop turning once per round of 10, as a fieldbus adapter updates every drive of
  its line in one cycle; each drive's state differs from its last); the front end publishes; a subscriber in another process counts the states it gets
  per second. Reference, in the same run and to the same subscriber, measured just
  before the gateway's run: raw zenoh-python puts of the same JSON payload
  (pre-encoded, one publisher per drive, zenoh-python's default QoS: CongestionControl
  .DROP, the QoS the gateway puts a change with), counted as they arrive. Also
  reported: the same raw puts with CongestionControl.BLOCK, where the putter waits
  for the subscriber, loses nothing and leaves it the CPU meanwhile (the gateway may
  not wait; docs/decisions/0011-zenoh-bench-references.md). Two more references: a naive bridge (the same hub
  updates, each state taken off a hub subscription, ``json.dumps(state.to_json())``
  and put at once on the loop: the least any front end must do), the hub
  alone (``hub.update`` with a conflating subscription drained, no Zenoh): the
  ceiling the core sets before any front end, and the floor of the work per state
  (``hub.update``, ``encode_state`` and a DROP put inline in a plain loop, no event
  loop, no subscription): what one interpreter delivers when it does nothing but
  the three calls every state needs. Against raw puts the floor shows how much of
  the target the three calls alone leave.
- Command latency: another process puts 1000 commands (one every 2 ms) on
  ``<prefix>/drives/d0/command``; the latency is from just before the put to the
  moment the hub's desired command changes (CLOCK_MONOTONIC is one clock for both
  processes). Reference, in the same run: between the commands, the same puts to a
  plain subscriber's callback in the gateway's process (what Zenoh and the host take
  alone; the gateway adds the hand-over to its loop and its own work). Also the round
  trip of a command query, seen by the client.

Run: ``.venv/bin/python -m bench zenoh``, or alone: ``python -m bench.bench_zenoh
[--seconds S] [--commands N]``. Everything stays on 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from bench.common import Figure, arg_parser, positive_float, positive_int, print_figures
from gateway.adapter import Capabilities
from gateway.config import Config, ZenohSection
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState, SpeedScale
from gateway.runtime.daemon import Runtime
from gateway.zenoh import link
from gateway.zenoh.frontend import ZenohFrontEnd
from gateway.zenoh.requests import encode_state
from gateway.zenoh.session import zenoh_config

ROOT = Path(__file__).resolve().parents[1]
PREFIX = "bench"
DRIVES = 10
DRIVE_IDS = tuple(f"d{i}" for i in range(DRIVES))  # as an adapter holds them
FANOUT_SECONDS = 2.0
COMMANDS = 1000
COMMAND_PERIOD = 0.002
QUERIES = 200
SENTINEL = -1.0  # speed_rpm of the last state of a run
REFERENCE_QOS = link.DROP  # the raw puts of the target's reference: the gateway's for a change


def _free_endpoint() -> str:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def _session(listen: tuple[str, ...] = (), connect: tuple[str, ...] = ()) -> zenoh.Session:
    return zenoh.open(zenoh_config(ZenohSection(listen=listen, connect=connect)))


def _hub() -> Hub:
    hub = Hub()
    for i in range(DRIVES):
        drive_id = f"d{i}"
        hub.add_drive(DriveState(id=drive_id, device=Device.CFW11, bus="line1", address=i + 1))
        hub.set_capabilities(drive_id, Capabilities(speed_scale=SpeedScale(1800.0)))
        hub.update(drive_id, comm=CommState.ONLINE, current_a=3.2, voltage_v=380.0, power_kw=1.5)
    return hub


def _percentile(values: list[float], pct: float) -> float:
    ordered = sorted(values)
    index = min(len(ordered) - 1, round(pct / 100 * (len(ordered) - 1)))
    return ordered[index]


class Peer:
    """The other process: a line protocol on its stdin and stdout."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "bench.bench_zenoh", *args],
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    def read(self) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the bench peer exited")
        return line.strip()

    def write(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


# ---------------------------------------------------------------- the bench process


async def _serve(hub: Hub, endpoint: str) -> tuple[ZenohFrontEnd, asyncio.Task[None]]:
    section = ZenohSection(prefix=PREFIX, listen=(endpoint,), heartbeat=60.0)
    fe = ZenohFrontEnd(Runtime(config=Config(file="bench", zenoh=section), hub=hub))
    task = asyncio.create_task(fe.run())
    await asyncio.wait_for(fe.ready.wait(), 10)
    return fe, task


async def _stop(task: asyncio.Task[None]) -> None:
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task


def _ping(session: zenoh.Session) -> Any:
    """The raw session's queryable that the peer settles its declarations with."""
    return session.declare_queryable(
        f"{PREFIX}/raw/ping", lambda q: (q.reply(f"{PREFIX}/raw/ping", b"{}"), q.drop())
    )


def _ask_ready(peer: Peer) -> None:
    if peer.read() != "ready":
        raise RuntimeError("the bench peer did not get ready")


def _publishers(
    session: zenoh.Session, part: str, congestion: zenoh.CongestionControl
) -> dict[str, Any]:
    """Drive id -> a publisher of its state under ``<prefix>/<part>/drives/``."""
    return {drive_id: _publisher(session, part, drive_id, congestion) for drive_id in DRIVE_IDS}


def _publisher(
    session: zenoh.Session, part: str, drive_id: str, congestion: zenoh.CongestionControl
) -> Any:
    return session.declare_publisher(
        f"{PREFIX}/{part}/drives/{drive_id}/state",
        encoding=zenoh.Encoding.APPLICATION_JSON,
        congestion_control=congestion,
    )


def _raw_phase(
    session: zenoh.Session, part: str, congestion: zenoh.CongestionControl, seconds: float
) -> int:
    """Raw puts of the same payload, one publisher per drive, for ``seconds``; puts made."""
    state = _hub().state("d0")
    payload = encode_state(state)
    pubs = list(_publishers(session, part, congestion).values())
    end = time.monotonic() + seconds
    i = 0
    while time.monotonic() < end:
        for _ in range(100):
            pubs[i % DRIVES].put(payload)
            i += 1
    for pub in pubs:
        pub.undeclare()
    _last_word(session, part, encode_state(state.changed(speed_rpm=SENTINEL)))
    return i


def _last_word(session: zenoh.Session, part: str, payload: bytes) -> None:
    """A run's sentinel state, put with BLOCK: a congested link cannot drop it."""
    pub = _publisher(session, part, "d0", zenoh.CongestionControl.BLOCK)
    pub.put(payload)
    pub.undeclare()


def _floor_phase(session: zenoh.Session, seconds: float) -> int:
    """hub.update, encode_state and a DROP put inline, for ``seconds``; updates made."""
    hub = _hub()
    pubs = _publishers(session, "floor", zenoh.CongestionControl.DROP)
    end = time.monotonic() + seconds
    n = 0
    while time.monotonic() < end:
        for _ in range(100):
            drive_id = DRIVE_IDS[n % DRIVES]
            pubs[drive_id].put(encode_state(hub.update(drive_id, speed_rpm=float(n % 1800))))
            n += 1
    for pub in pubs.values():
        pub.undeclare()
    _last_word(session, "floor", encode_state(hub.update("d0", speed_rpm=SENTINEL)))
    return n


async def _naive_phase(session: zenoh.Session, seconds: float) -> int:
    """The least a front end must do: hub -> subscription -> to_json -> put, on the loop."""
    hub = _hub()
    pubs = _publishers(session, "naive", zenoh.CongestionControl.DROP)
    with hub.subscribe_states() as sub:

        async def bridge() -> None:
            while True:
                for state in (await sub.get(), *sub.drain()):
                    pubs[state.id].put(json.dumps(state.to_json()).encode())

        task = asyncio.create_task(bridge())
        n = await _gateway_phase(hub, seconds)
        await asyncio.sleep(0.1)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    for pub in pubs.values():
        pub.undeclare()
    _last_word(session, "naive", encode_state(hub.state("d0")))  # if DROP lost the bridge's
    return n


async def _gateway_phase(hub: Hub, seconds: float) -> int:
    """hub.update flat out on every drive for ``seconds``; returns the updates made."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    n = 0
    while loop.time() < end:
        n = _line_cycle(hub, n)
        await asyncio.sleep(0)
    hub.update("d0", speed_rpm=SENTINEL)
    return n


def _line_cycle(hub: Hub, n: int) -> int:
    """One cycle of a line: every drive updated, each to a speed other than its last
    (``n`` counts the updates; returned grown by one cycle). The loop turns between."""
    update = hub.update
    for drive_id in DRIVE_IDS:
        update(drive_id, speed_rpm=float(n % 1800))
        n += 1
    return n


async def _hub_alone(seconds: float) -> float:
    """The ceiling: hub.update with a conflating subscription drained, no front end."""
    hub = _hub()
    loop = asyncio.get_running_loop()
    with hub.subscribe_states() as sub:

        async def drain() -> None:
            while True:
                await sub.get()
                sub.drain()

        drainer = asyncio.create_task(drain())
        start = loop.time()
        end = start + seconds
        n = 0
        while loop.time() < end:
            n = _line_cycle(hub, n)
            await asyncio.sleep(0)
        rate = n / (loop.time() - start)
        drainer.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await drainer
    return rate


async def _fanout(seconds: float | None = None) -> list[Figure]:
    """The state fan-out figures, each phase ``seconds`` long (:data:`FANOUT_SECONDS` when
    None)."""
    seconds = FANOUT_SECONDS if seconds is None else seconds
    hub = _hub()
    gw_endpoint, raw_endpoint = _free_endpoint(), _free_endpoint()
    fe, task = await _serve(hub, gw_endpoint)
    raw = _session(listen=(raw_endpoint,))
    raw_ping = _ping(raw)
    peer = Peer("count", gw_endpoint, raw_endpoint)
    try:
        await asyncio.to_thread(_ask_ready, peer)
        _raw_phase(raw, "rawblock", zenoh.CongestionControl.BLOCK, seconds)
        _floor_phase(raw, seconds)
        await _naive_phase(raw, seconds)
        raw_puts = _raw_phase(raw, "raw", REFERENCE_QOS, seconds)  # next to the gateway's run
        updates = await _gateway_phase(hub, seconds)
        await asyncio.to_thread(peer.write, "report")
        report = json.loads(await asyncio.to_thread(peer.read))
    finally:
        peer.close()
        raw_ping.undeclare()
        raw.close()
        await _stop(task)
    ceiling = await _hub_alone(seconds)
    gw, rw, nv, fl = report["gateway"], report["raw"], report["naive"], report["floor"]
    gw_rate = gw["n"] / gw["seconds"]
    raw_rate = rw["n"] / rw["seconds"]
    block_rate = report["rawblock"]["n"] / report["rawblock"]["seconds"]
    naive_rate = nv["n"] / nv["seconds"]
    floor_rate = fl["n"] / fl["seconds"]
    note = (
        f"{DRIVES} drives; {updates} hub updates in {seconds:g} s, {gw['n']} states "
        f"delivered ({fe.worker.replaced} replaced in the I/O slot); raw: {rw['n']} of "
        f"{raw_puts} puts of the same {len(encode_state(hub.state('d0')))}-byte payload "
        "delivered, put with zenoh-python's default QoS (CongestionControl.DROP), as the "
        "gateway puts a change"
    )
    return [
        Figure(
            "zenoh state fan-out (vs raw puts)",
            round(gw_rate),
            "states/s",
            reference=round(raw_rate),
            target="ratio >= 0.5",
            note=note,
        ),
        Figure(
            "zenoh state fan-out (vs raw BLOCK puts)",
            round(gw_rate),
            "states/s",
            reference=round(block_rate),
            note="reference: the same raw puts with CongestionControl.BLOCK: the putter waits "
            "for the subscriber instead of losing puts, and leaves it the CPU while it waits "
            "(the gateway may not wait: a change is put with DROP)",
        ),
        Figure(
            "zenoh state fan-out (vs naive bridge)",
            round(gw_rate),
            "states/s",
            reference=round(naive_rate),
            note="reference: hub subscription -> json.dumps(to_json()) -> DROP put on the loop, "
            "no liveliness, heartbeat, last-word or command handling",
        ),
        Figure(
            "zenoh state fan-out (vs floor)",
            round(gw_rate),
            "states/s",
            reference=round(floor_rate),
            note="reference: hub.update + encode_state + DROP put inline in a plain loop (no "
            f"event loop, no subscription); the floor against raw puts: "
            f"{floor_rate / raw_rate:.3f}",
        ),
        Figure(
            "zenoh state fan-out (vs hub alone)",
            round(gw_rate),
            "states/s",
            reference=round(ceiling),
            note="reference: hub.update rate with a drained subscription and no front end",
        ),
    ]


def _latencies_ms(sent: dict[str, float], arrived: dict[float, float]) -> list[float]:
    """Put to arrival, in ms, of each speed that arrived (CLOCK_MONOTONIC in both)."""
    return [(arrived[float(rpm)] - t) * 1000 for rpm, t in sent.items() if float(rpm) in arrived]


async def _commands(commands: int = COMMANDS) -> list[Figure]:
    hub = _hub()
    endpoint, raw_endpoint = _free_endpoint(), _free_endpoint()
    _, task = await _serve(hub, endpoint)
    arrived: dict[float, float] = {}
    raw_arrived: dict[float, float] = {}

    def on_command(drive_id: str) -> None:
        rpm = hub.desired(drive_id).speed_rpm
        if rpm is not None and rpm not in arrived:
            arrived[rpm] = time.monotonic()

    def on_raw(sample: zenoh.Sample) -> None:  # on Zenoh's callback thread, as the gateway's
        raw_arrived[json.loads(sample.payload.to_bytes())["speed_rpm"]] = time.monotonic()

    hub.on_command(on_command)
    raw = _session(listen=(raw_endpoint,))
    raw_ping = _ping(raw)
    raw_sub = raw.declare_subscriber(f"{PREFIX}/raw/command", on_raw)
    peer = Peer("command", endpoint, raw_endpoint, str(commands))
    try:
        await asyncio.to_thread(_ask_ready, peer)
        await asyncio.to_thread(peer.write, "go")
        report = json.loads(await asyncio.to_thread(peer.read))
    finally:
        peer.close()
        raw_sub.undeclare()
        raw_ping.undeclare()
        raw.close()
        await _stop(task)
    latencies = _latencies_ms(report["sent"], arrived)
    raw_latencies = _latencies_ms(report["raw_sent"], raw_arrived)
    rtt: list[float] = report["query_ms"]
    note = (
        f"{len(latencies)} of {commands} commands arrived; reference: {len(raw_latencies)} "
        "of the same puts, sent between them, to a plain subscriber's callback in the "
        "gateway's process (Zenoh and the host alone)"
    )
    return [
        Figure(
            "zenoh command latency p50",
            round(statistics.median(latencies), 3),
            "ms",
            reference=round(statistics.median(raw_latencies), 3),
            note=note,
        ),
        Figure(
            "zenoh command latency p99",
            round(_percentile(latencies, 99), 3),
            "ms",
            reference=round(_percentile(raw_latencies, 99), 3),
            target="p99 < 5 ms",
            note=note,
        ),
        Figure(
            "zenoh command query round trip p50",
            round(statistics.median(rtt), 3),
            "ms",
            note=f"{len(rtt)} queries, reply {{'accepted': true}} seen by the client",
        ),
        Figure("zenoh command query round trip p99", round(_percentile(rtt, 99), 3), "ms"),
    ]


def run(seconds: float = FANOUT_SECONDS, commands: int = COMMANDS) -> list[Figure]:
    async def main() -> list[Figure]:
        return [*(await _fanout(seconds)), *(await _commands(commands))]

    return asyncio.run(main())


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_zenoh", __doc__)
    parser.add_argument(
        "--seconds",
        type=positive_float,
        metavar="S",
        default=FANOUT_SECONDS,
        help="seconds of each state fan-out phase",
    )
    parser.add_argument(
        "--commands",
        type=positive_int,
        metavar="N",
        default=COMMANDS,
        help=f"commands put for the latency, one every {COMMAND_PERIOD * 1000:g} ms",
    )
    # the other process of the benchmark (Peer), started by the benchmark itself
    peers = parser.add_subparsers(
        dest="peer",
        metavar="{count,command}",
        title="peer modes (the benchmark starts these itself)",
    )
    for mode, what in (
        ("count", "count the states of every run (the subscriber the benchmark starts)"),
        ("command", "put the commands and queries (the client the benchmark starts)"),
    ):
        peer = peers.add_parser(mode, help=what, description=what)
        peer.add_argument("gw_endpoint", help="the gateway's Zenoh endpoint")
        peer.add_argument("raw_endpoint", help="the reference session's endpoint")
        if mode == "command":
            peer.add_argument("commands", type=positive_int, nargs="?", default=COMMANDS)
    args = parser.parse_args(argv)
    if args.peer == "count":
        _peer_count(args.gw_endpoint, args.raw_endpoint)
    elif args.peer == "command":
        _peer_command(args.gw_endpoint, args.raw_endpoint, args.commands)
    else:
        print_figures(run(args.seconds, args.commands))
    return 0


# ---------------------------------------------------------------- the other process


def _settle(session: zenoh.Session, selector: str) -> None:
    """A round trip: the declarations made before it have reached that peer."""
    for _ in range(100):
        if any(r.ok is not None for r in session.get(selector, timeout=1.0)):
            return
    raise RuntimeError(f"no answer from {selector}")


class RunCounts:
    """What the counting peer keeps of each run: the states, the first and the last
    arrival. A run ends at its sentinel state; a repeat of it (a settle put) is not
    counted. Runs are told apart by the key's second level (``bench/raw/...``); the
    gateway's keys (``bench/drives/...``) count as "gateway"."""

    RUNS = ("gateway", "raw", "rawblock", "naive", "floor")
    _SENTINEL = f'"speed_rpm":{SENTINEL}'.encode()
    _SENTINEL_SPACED = f'"speed_rpm": {SENTINEL}'.encode()  # json.dumps' default separators

    def __init__(self) -> None:
        self.stats = {name: {"n": 0, "first": 0.0, "last": 0.0} for name in self.RUNS}
        self.ended = {name: threading.Event() for name in self.RUNS}

    def add(self, key: str, payload: bytes, now: float) -> None:
        part = key.split("/")[1]
        name = part if part in self.stats else "gateway"
        if self.ended[name].is_set():
            return
        entry = self.stats[name]
        if entry["n"] == 0:
            entry["first"] = now
        entry["n"] += 1
        entry["last"] = now
        if self._SENTINEL in payload or self._SENTINEL_SPACED in payload:
            self.ended[name].set()

    def report(self) -> dict[str, dict[str, float]]:
        return {
            name: {"n": e["n"], "seconds": max(e["last"] - e["first"], 1e-9)}
            for name, e in self.stats.items()
        }


def _peer_count(gw_endpoint: str, raw_endpoint: str) -> None:
    session = _session(connect=(gw_endpoint, raw_endpoint))
    counts = RunCounts()

    def on_sample(sample: zenoh.Sample) -> None:
        counts.add(str(sample.key_expr), sample.payload.to_bytes(), time.monotonic())

    sub = session.declare_subscriber(f"{PREFIX}/**/state", on_sample)
    _settle(session, f"{PREFIX}/gateway/health")
    _settle(session, f"{PREFIX}/raw/ping")
    print("ready", flush=True)
    sys.stdin.readline()  # "report": every run is over
    for event in counts.ended.values():
        event.wait(30)  # the sentinel state is the last word of each run
    print(json.dumps(counts.report()), flush=True)
    sub.undeclare()
    session.close()


def _peer_command(endpoint: str, raw_endpoint: str, commands: int = COMMANDS) -> None:
    session = _session(connect=(endpoint, raw_endpoint))
    key, raw_key = f"{PREFIX}/drives/d0/command", f"{PREFIX}/raw/command"
    _settle(session, f"{PREFIX}/gateway/health")
    _settle(session, f"{PREFIX}/raw/ping")
    print("ready", flush=True)
    sys.stdin.readline()
    sent: dict[str, float] = {}
    raw_sent: dict[str, float] = {}
    for i in range(1, commands + 1):
        payload = json.dumps({"run": True, "speed_rpm": float(i)}).encode()
        for to, times in ((key, sent), (raw_key, raw_sent)):  # one period: one of each
            times[str(float(i))] = time.monotonic()
            session.put(to, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(COMMAND_PERIOD / 2)
    query_ms = []
    for i in range(QUERIES):
        payload = json.dumps({"speed_rpm": float(1000 + i)}).encode()
        start = time.monotonic()
        replies = list(session.get(key, payload=payload, timeout=5.0))
        query_ms.append((time.monotonic() - start) * 1000)
        if not replies or replies[0].ok is None:
            raise RuntimeError("a command query got no reply")
    print(json.dumps({"sent": sent, "raw_sent": raw_sent, "query_ms": query_ms}), flush=True)
    session.close()


if __name__ == "__main__":
    raise SystemExit(main())
