"""The soak run (``make soak``; minutes, not in CI): every demo device plus 60 more
simulated Profibus slaves and 30 more DeviceNet nodes in one daemon, commanded from
Zenoh (SCADA) and Modbus TCP (PLCs), parameters read and written, HMIs polling, bursts of
connections, with line noise on both buses and CAN error frames.

``SOAK_SECONDS`` (default 180) bounds it. At the end:

- no reordered state for any drive: the sequence numbers a Zenoh subscriber and the
  Modbus pollers see never go back; no lost state: every state the hub committed reached
  the subscriber (counted against the hub, per drive), and the newest state of every
  drive is the one the subscriber holds (checked during the run too, for every drive that
  has not changed for two heartbeats);
- no stuck command: every command and parameter query was answered; after the traffic
  every drive does what its desired command says, and a final stop stops them all;
- memory in use grew less than 10 % after the warm-up: the RSS after handing freed
  memory back to the system (glibc's ``malloc_trim``; Zenoh's threads keep per-thread
  arenas whose free pages otherwise stay in the RSS), the raw RSS reported beside it; the
  asyncio tasks, threads and file descriptors after the run are those after the warm-up
  (both counted with the traffic paused).

The figures are printed at the end (and kept in the test's tmp_path, soak.json).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import ctypes
import gc
import json
import os
import random
import sys
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import pytest
from pymodbus.client import AsyncModbusTcpClient

from gateway.hub import Hub, StateSubscription
from gateway.model import DriveState
from tests.e2e import harness
from tests.e2e.harness import PREFIX, RUN, Gateway, running_gateway
from tests.reliability.demo import (
    DEMO,
    DEVICENET,
    PROFIBUS,
    WEG_STARTUP,
    can_sim,
    demo_buses,
    devicenet_adapter,
    new_channel,
    on_line,
    sim_line,
    toml_buses,
)
from tests.zenoh.client import Got

pytestmark = pytest.mark.slow

SECONDS = float(os.environ.get("SOAK_SECONDS", "180"))
WARM_UP = min(30.0, SECONDS / 5)
EXTRA_PROFIBUS = 60
EXTRA_DEVICENET = 30
MEMORY_GROWTH = 0.10
QUERY_TIMEOUT = 10.0
PROFIBUS_NOISE = 2e-4  # bit flips per byte, both directions
CAN_DROP = 0.002  # lost replies per node
HEARTBEAT = float(DEMO["zenoh"]["heartbeat"])
SETTLE = 3.0  # s after the traffic for the drives to follow their last command
RECONNECT = 15.0  # s a drive that dropped out in the last of the noise may take to be back
START_TIMEOUT = 120.0  # s for every drive to come online

WEG_KINDS = ("CFW-11", "CFW700", "CFW320")
RAMPS = frozenset({100, 101})  # the parameters the soak writes


# ---------------------------------------------------------------- the line-up


def extra_drives() -> dict[str, list[dict[str, Any]]]:
    profibus: list[dict[str, Any]] = []
    for i in range(EXTRA_PROFIBUS):
        address = 7 + i
        drive: dict[str, Any] = {"id": f"pb{address}", "address": address, "modbus_unit": 10 + i}
        if i % 4 == 3:
            drive.update(device="MCD 600", mode="basic", sim_time_scale=20.0)
        else:
            drive.update(
                device=WEG_KINDS[i % 4],
                data_profile="manufacturer",
                words=2,
                writable_params=[100, 101],
                startup_params=WEG_STARTUP,
            )
        profibus.append(drive)
    devicenet = [
        {
            "id": f"dn{mac}",
            "device": "CFW-08",
            "address": mac,
            "modbus_unit": 100 + mac,
            "assembly": 21,
            "max_rpm": 1800,
            "writable_params": [100, 101],
            "sim_ramp_time": 0.3,
        }
        for mac in range(6, 6 + EXTRA_DEVICENET)
    ]
    return {PROFIBUS: profibus, DEVICENET: devicenet}


def soak_buses() -> dict[str, dict[str, Any]]:
    demo_line = {k: v for k, v in DEMO["buses"][DEVICENET].items() if k != "drives"}
    devicenet = {k: demo_line[k] for k in ("poll_interval", "expected_packet_rate")}
    return demo_buses(new_channel(), devicenet=devicenet, extra=extra_drives())


@dataclass(frozen=True)
class Drive:
    id: str
    device: str
    unit: int
    speed: bool  # has a speed reference (not a soft starter)
    params: tuple[int, ...]  # writable_params


def drives_of(buses: dict[str, dict[str, Any]]) -> list[Drive]:
    return [
        Drive(
            d["id"],
            d["device"],
            d["modbus_unit"],
            d["device"] != "MCD 600",
            tuple(d.get("writable_params", ())),
        )
        for bus in buses.values()
        for d in bus["drives"]
    ]


# ---------------------------------------------------------------- what is measured


class Recorder(StateSubscription):
    """Every state the hub commits, counted per drive (never conflated)."""

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.commits: collections.Counter[str] = collections.Counter()
        self.since: dict[str, int] = {}  # counting starts above this seq
        hub._state_subs = (*hub._state_subs, self)

    def start(self, hub: Hub) -> None:
        self.since = {s.id: s.seq for s in hub.states()}
        self.commits.clear()

    def _offer(self, state: DriveState) -> None:
        if state.seq > self.since.get(state.id, 1 << 62):
            self.commits[state.id] += 1

    def watch_conflation(self, front_end: Any) -> collections.Counter[str]:
        """Count, per drive, the counted states the Zenoh front end's subscription replaced
        before the front end took them (two commits of a drive in one loop turn: by design
        only the newest is published)."""
        sub = front_end.state_subscription
        assert isinstance(sub, StateSubscription)
        replaced: collections.Counter[str] = collections.Counter()
        offer = sub._offer

        def counting(state: DriveState) -> None:
            old = sub._pending.get(state.id)
            if old is not None and old.seq > self.since.get(state.id, 1 << 62):
                replaced[state.id] += 1
            offer(state)

        sub._offer = counting  # type: ignore[method-assign]
        return replaced


@dataclass
class SeqWatch:
    """Sequence numbers one client sees, per drive: new ones, repeats, and any going back."""

    since: dict[str, int] = field(default_factory=dict)
    last: dict[str, int] = field(default_factory=dict)
    new: collections.Counter[str] = field(default_factory=collections.Counter)
    reordered: list[tuple[str, int, int]] = field(default_factory=list)

    def see(self, drive: str, seq: int) -> None:
        last = self.last.get(drive)
        if last is not None and seq < last:
            self.reordered.append((drive, last, seq))
            return
        if last is None or seq > last:
            self.last[drive] = seq
            if seq > self.since.get(drive, 1 << 62):
                self.new[drive] += 1


@dataclass
class Tally:
    sent: collections.Counter[str] = field(default_factory=collections.Counter)
    answered: collections.Counter[str] = field(default_factory=collections.Counter)
    refused: collections.Counter[str] = field(default_factory=collections.Counter)
    unanswered: list[str] = field(default_factory=list)
    stale: list[str] = field(default_factory=list)

    def reply(self, kind: str, ok: bool, why: str = "") -> None:
        self.answered[kind] += 1
        if not ok:
            self.refused[f"{kind}: {why}"[:90]] += 1


def object_counts() -> collections.Counter[str]:
    """Live Python objects (those the collector tracks) by type."""
    return collections.Counter(
        f"{type(o).__module__}.{type(o).__qualname__}" for o in gc.get_objects()
    )


def object_growth(start: collections.Counter[str]) -> dict[str, int]:
    """The types whose live objects grew most since ``start`` (where memory goes)."""
    now = object_counts()
    now.subtract(start)
    return dict(now.most_common(12))


def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def _malloc_trim() -> Callable[[int], int] | None:
    try:
        trim: Callable[[int], int] = ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: the raw RSS is all there is
        return None
    return trim


MALLOC_TRIM = _malloc_trim()


def memory_kib() -> tuple[int, int]:
    """(raw RSS, RSS in use: after the freed pages went back to the system)."""
    raw = rss_kib()
    if MALLOC_TRIM is None:
        return raw, raw
    MALLOC_TRIM(0)
    return raw, rss_kib()


def resources() -> dict[str, Any]:
    tasks = [t.get_name() for t in asyncio.all_tasks() if not t.done()]
    return {
        "tasks": len(tasks),
        "task_names": collections.Counter(tasks),
        "threads": threading.active_count(),
        "fds": len(os.listdir("/proc/self/fd")),
    }


async def settled_resources(
    baseline: dict[str, Any], within: float = QUERY_TIMEOUT
) -> dict[str, Any]:
    """The resources once they are back to ``baseline`` (or after ``within`` s): jobs in
    flight end by themselves, a leak stays."""
    keys = ("tasks", "threads", "fds")
    now = resources()
    end = time.monotonic() + within
    while any(now[k] > baseline[k] for k in keys) and time.monotonic() < end:
        await asyncio.sleep(0.1)  # counts: no event to await
        now = resources()
    return now


class EventTally:
    """The hub's events, counted by kind and by the start of their text (bounded)."""

    def __init__(self, hub: Hub) -> None:
        self._sub = hub.subscribe_events()
        self.kinds: collections.Counter[str] = collections.Counter()
        self.texts: collections.Counter[str] = collections.Counter()

    def count(self) -> None:
        for event in self._sub.drain():
            self.kinds[event.kind.value] += 1
            self.texts[event.text.split(":")[0][:40]] += 1

    def close(self) -> None:
        self.count()
        self._sub.close()


# ---------------------------------------------------------------- the clients


class Traffic:
    """The load generators; ``paused`` holds them (to count resources at rest)."""

    def __init__(self, gw: Gateway, drives: list[Drive], seed: int = 1) -> None:
        self.gw = gw
        self.drives = drives
        self.rng = random.Random(seed)
        self.tally = Tally()
        self.modbus_seqs = SeqWatch()
        self.running = asyncio.Event()
        self.running.set()
        self.stop = False
        self.zenoh_drives = [d for i, d in enumerate(drives) if i % 2 == 0]
        self.plc_drives = [d for i, d in enumerate(drives) if i % 2 == 1]
        self.plc_words: dict[str, int] = {d.id: 0 for d in self.plc_drives}
        self.plc_speeds: dict[str, int] = {d.id: 600 for d in self.plc_drives}
        self.busy = 0  # loops in the middle of an iteration
        self.clients: list[AsyncModbusTcpClient] = []
        self.tasks: list[asyncio.Task[None]] = []

    async def modbus_client(self) -> AsyncModbusTcpClient:
        port = self.gw.daemon.config.modbus.port
        client = AsyncModbusTcpClient(
            "127.0.0.1", port=port, reconnect_delay=0, retries=0, timeout=QUERY_TIMEOUT
        )
        assert await client.connect()
        self.clients.append(client)
        return client

    def spawn(self, name: str, loop: Callable[[], Awaitable[None]], every: float) -> None:
        async def run() -> None:
            while not self.stop:
                await self.running.wait()
                if self.stop:
                    return
                self.busy += 1
                try:
                    await loop()
                finally:
                    self.busy -= 1
                await asyncio.sleep(every)

        self.tasks.append(asyncio.create_task(run(), name=f"soak-{name}"))

    async def close(self) -> None:
        self.stop = True
        self.running.set()
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        for client in self.clients:
            client.close()

    # -- SCADA on Zenoh: commands (queries and puts), parameters

    async def scada_command(self) -> None:
        d = self.rng.choice(self.zenoh_drives)
        choice = self.rng.random()
        payload: dict[str, Any]
        if choice < 0.4:
            payload = {"run": True}
            if d.speed:
                payload["speed_rpm"] = self.rng.choice((300, 600, 900, 1200))
        elif choice < 0.6:
            payload = {"run": False}
        elif choice < 0.8 and d.speed:
            payload = {"speed_rpm": self.rng.choice((300, 600, 900, 1200))}
        elif d.speed:
            payload = {"direction": self.rng.choice(("forward", "reverse"))}
        else:
            payload = {}
        await self.query("command", f"{PREFIX}/drives/{d.id}/command", payload)

    async def scada_params(self) -> None:
        """Reads, and writes of the ramp times (P0100/P0101: 0.3-0.5 s), nothing else."""
        d = self.rng.choice([d for d in self.drives if RAMPS & set(d.params)])
        number = self.rng.choice(sorted(RAMPS & set(d.params)))
        key = f"{PREFIX}/drives/{d.id}/params/{number}"
        payload = None if self.rng.random() < 0.7 else {"value": self.rng.choice((3, 4, 5))}
        await self.query("param write" if payload else "param read", key, payload)

    async def query(self, kind: str, key: str, payload: Any) -> None:
        self.tally.sent[kind] += 1
        try:
            replies = await self.gw.client.aquery(key, payload, within=QUERY_TIMEOUT)
        except TimeoutError:
            self.tally.unanswered.append(f"{kind} {key}")
            return
        if len(replies) != 1:
            self.tally.unanswered.append(f"{kind} {key}: {len(replies)} replies")
            return
        body = replies[0].json()
        if kind == "command":
            self.tally.reply(kind, body.get("accepted") is True, str(body.get("error", "")))
        else:
            self.tally.reply(kind, replies[0].ok, str(body.get("error", "")))

    # -- PLCs on Modbus: cyclic command blocks, edges now and then

    def plc(self, client: AsyncModbusTcpClient, mine: list[Drive]) -> Callable[[], Awaitable[None]]:
        keep_alive = 0

        async def cycle() -> None:
            nonlocal keep_alive
            for d in mine:  # the whole block rewritten every cycle, as a PLC does
                # the PLC program changes its mind (a soft starter seldom: its motor's
                # thermal model trips on too many starts, as a real one does)
                if self.rng.random() < (0.05 if d.speed else 0.005):
                    self.plc_words[d.id] = 0 if self.plc_words[d.id] else RUN
                if self.rng.random() < 0.05:
                    self.plc_speeds[d.id] = self.rng.choice((300, 600, 900, 1200))
                keep_alive = (keep_alive + 1) & 0xFFFF
                values = [self.plc_words[d.id]]
                if d.speed:
                    values.append(self.plc_speeds[d.id])
                await self.write(client, d, values, keep_alive)

        return cycle

    async def write(
        self, client: AsyncModbusTcpClient, d: Drive, values: list[int], keep_alive: int
    ) -> None:
        self.tally.sent["modbus write"] += 1
        try:
            rr = await client.write_registers(0, values, device_id=d.unit)
            await client.write_register(3, keep_alive, device_id=d.unit)
        except Exception as exc:  # a timeout: that request is stuck
            self.tally.unanswered.append(f"modbus write {d.id}: {exc!r}")
            return
        self.tally.reply(
            "modbus write", not rr.isError(), f"exception {getattr(rr, 'exception_code', '')}"
        )

    # -- HMIs polling status blocks; bursts of connections; malformed frames

    def hmi(self, client: AsyncModbusTcpClient) -> Callable[[], Awaitable[None]]:
        async def poll() -> None:
            d = self.rng.choice(self.drives)
            self.tally.sent["modbus read"] += 1
            try:
                rr = await client.read_input_registers(0, count=21, device_id=d.unit)
            except Exception as exc:
                self.tally.unanswered.append(f"modbus read {d.id}: {exc!r}")
                return
            self.tally.reply("modbus read", not rr.isError())
            if not rr.isError():
                self.modbus_seqs.see(d.id, rr.registers[17] << 16 | rr.registers[18])

        return poll

    async def burst(self) -> None:
        """64 connections at once, a read each, then gone; one bad frame on the way."""
        port = self.gw.daemon.config.modbus.port
        self.tally.sent["burst"] += 1
        clients = [
            AsyncModbusTcpClient(
                "127.0.0.1", port=port, reconnect_delay=0, retries=0, timeout=QUERY_TIMEOUT
            )
            for _ in range(64)
        ]
        try:
            ok = await asyncio.gather(*(c.connect() for c in clients))
            reads = await asyncio.gather(
                *(c.read_input_registers(0, count=25, device_id=0) for c in clients)
            )
            self.tally.reply("burst", all(ok) and not any(r.isError() for r in reads))
        except Exception as exc:
            self.tally.unanswered.append(f"burst: {exc!r}")
        finally:
            for c in clients:
                c.close()
        _, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"\x00\x01\x12\x34\x00\x06\x01\x04\x00\x00\x00\x01")  # bad protocol id
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()

    def start(self, plcs: list[AsyncModbusTcpClient], hmis: list[AsyncModbusTcpClient]) -> None:
        for i in range(4):
            self.spawn(f"scada-command-{i}", self.scada_command, 0.02)
        for i in range(2):
            self.spawn(f"scada-params-{i}", self.scada_params, 0.02)
        for i, client in enumerate(plcs):
            self.spawn(f"plc-{i}", self.plc(client, self.plc_drives[i :: len(plcs)]), 0.1)
        for i, client in enumerate(hmis):
            self.spawn(f"hmi-{i}", self.hmi(client), 0.01)
        self.spawn("burst", self.burst, 5.0)


# ---------------------------------------------------------------- the run


async def pause(traffic: Traffic, settle: float = 1.0) -> dict[str, Any]:
    """Hold the traffic, let everything in flight finish; the resources at rest."""
    traffic.running.clear()
    async with asyncio.timeout(QUERY_TIMEOUT + 5):
        while traffic.busy:  # noqa: ASYNC110 - a count of loops, no event
            await asyncio.sleep(0.05)
    await asyncio.sleep(settle)
    return resources()


def device_view(gw: Gateway, state: DriveState) -> str:
    """What the simulated device says of itself (for the report of a drive that did not
    follow its command)."""
    if state.bus == PROFIBUS:
        return repr(vars(sim_line(gw)[state.address].device))[:1500]
    return repr(vars(can_sim(gw).node(state.address).drive))[:1500]


async def noise(gw: Gateway, profibus: float, devicenet: float) -> None:
    """Line noise on both buses, set on each line's own loop: Profibus bit flips per byte,
    DeviceNet replies lost per node."""
    faults = sim_line(gw).faults
    nodes = list(can_sim(gw).nodes.values())

    def on_profibus() -> None:
        faults.bit_error_rate = profibus

    def on_devicenet() -> None:
        for node in nodes:
            node.faults.drop_rate = devicenet

    await on_line(gw, PROFIBUS, on_profibus)
    await on_line(gw, DEVICENET, on_devicenet)


def check_newest(gw: Gateway, zenoh: SeqWatch, tally: Tally, heartbeat: float) -> None:
    """Every drive that has not changed for two heartbeats: the subscriber holds its state."""
    wall = time.time()
    for state in gw.daemon.hub.states():
        settled = state.ts is not None and wall - state.ts > 2 * heartbeat
        if settled and zenoh.last.get(state.id) != state.seq:
            tally.stale.append(
                f"{state.id}: hub {state.seq}, subscriber {zenoh.last.get(state.id)}"
            )


async def test_soak(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # the demo's heartbeat (the end-to-end tests' is shorter, to be quick)
    e2e_header = harness.header
    monkeypatch.setattr(
        harness,
        "header",
        lambda *args: e2e_header(*args).replace("heartbeat = 0.2", f"heartbeat = {HEARTBEAT}"),
    )
    started_at = time.monotonic()

    def progress(text: str) -> None:
        with capsys.disabled():
            print(f"soak {time.monotonic() - started_at:6.1f} s: {text}", flush=True)

    buses = soak_buses()
    drives = drives_of(buses)
    assert len(drives) == 5 + EXTRA_PROFIBUS + EXTRA_DEVICENET
    ids = [d.id for d in drives]
    async with running_gateway(tmp_path, lambda: toml_buses(buses), []) as gw:
        hub = gw.daemon.hub
        progress("starting: waiting for every drive to come online")
        async with asyncio.timeout(START_TIMEOUT):  # 95 drives on a loaded machine
            for d in ids:
                await hub.wait_for(d, lambda s: s.online)
        heartbeat = gw.daemon.config.zenoh.heartbeat
        assert heartbeat == HEARTBEAT
        recorder = Recorder(hub)
        zenoh = SeqWatch()
        traffic = Traffic(gw, drives)
        channel = devicenet_adapter(gw).options.channel
        events = EventTally(hub)
        try:
            with gw.client.subscribe(f"{PREFIX}/drives/*/state") as states:
                await gw.client.settled(PREFIX)

                following = True

                async def follow() -> None:
                    # a flag, not only cancel(): on Python 3.11 wait_for (under aget) can
                    # swallow a cancellation that comes as a sample does
                    while following:
                        try:
                            batch: list[Got] = await states.abatch(1.0)
                        except TimeoutError:
                            continue
                        for got in batch:
                            body = got.json()
                            zenoh.see(body["id"], body["seq"])

                follower = asyncio.create_task(follow(), name="soak-subscriber")
                plcs = [await traffic.modbus_client() for _ in range(4)]
                hmis = [await traffic.modbus_client() for _ in range(3)]
                # noise on both lines for the whole run
                await noise(gw, PROFIBUS_NOISE, CAN_DROP)

                async def can_errors() -> None:
                    # a bus of its own for a moment: a virtual bus left open would queue
                    # every frame of the line for nobody
                    intruder = can.Bus(interface="virtual", channel=channel)
                    try:
                        for error_class in (0x004, 0x080):  # controller warning, bus error
                            intruder.send(
                                can.Message(
                                    arbitration_id=error_class,
                                    is_error_frame=True,
                                    is_extended_id=False,
                                    data=bytes([0, 0x04, 0, 0, 0, 0, 0, 0]),
                                )
                            )
                    finally:
                        intruder.shutdown()

                traffic.spawn("can-errors", can_errors, 2.0)
                progress("traffic and noise on; warming up")
                traffic.start(plcs, hmis)
                started = time.monotonic()
                await asyncio.sleep(WARM_UP)
                at_rest = await pause(traffic)
                raw_start, rss_start = memory_kib()
                objects_start = object_counts()
                recorder.start(hub)
                conflated = recorder.watch_conflation(gw.daemon.front_ends["zenoh"])
                zenoh.since = dict(recorder.since)
                traffic.modbus_seqs.since = dict(recorder.since)
                traffic.running.set()
                rss_trend: list[int] = []
                raw_trend: list[int] = []
                blocks_trend: list[int] = []  # Python's own allocations (all objects)
                next_sample = 0.0
                while time.monotonic() - started < SECONDS:
                    await asyncio.sleep(heartbeat)
                    check_newest(gw, zenoh, traffic.tally, heartbeat)
                    events.count()
                    if time.monotonic() >= next_sample:
                        raw, in_use = memory_kib()
                        raw_trend.append(raw)
                        rss_trend.append(in_use)
                        blocks_trend.append(sys.getallocatedblocks())
                        progress(f"RSS {raw} KiB, in use {in_use} KiB, {dict(traffic.tally.sent)}")
                        next_sample = time.monotonic() + 10.0
                progress("run over; pausing the traffic")
                raw_end, rss_end = memory_kib()
                objects_growth = object_growth(objects_start)
                at_rest_end = await pause(traffic)
                # the noise ends; the drives follow their last command, then all stop
                await noise(gw, 0.0, 0.0)
                progress("noise off; the drives settle")
                await asyncio.sleep(SETTLE)
                # a drive that left data exchange in the last seconds of noise is still
                # reconnecting: it comes back (stopped, rule 1) within its retry time
                for d in ids:
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(hub.wait_for(d, lambda s: s.online), RECONNECT)
                # at rest again, the drives back: a reconnecting drive's tasks are not a leak,
                # nor is a job that is still finishing (a fault code read after a trip, a
                # parameter query): what is left once they are done is
                at_rest_end = await settled_resources(at_rest)
                # a drive in fault cannot follow a run command (the hub takes one, and the
                # drive runs once reset): counted apart
                faulted = sorted(s.id for s in hub.states() if s.faulted)
                not_following = [
                    f"{s.id}: desired {hub.desired(s.id)}, state {s}, device {device_view(gw, s)}"
                    for s in hub.states()
                    if not s.online or (s.running != hub.desired(s.id).run and not s.faulted)
                ]
                await asyncio.sleep(2 * heartbeat)
                committed = sum(recorder.commits.values())
                received = sum(zenoh.new.values())
                # every state the front end took reached the subscriber; a state replaced
                # in its subscription before it was taken was never meant to go out
                lost = {
                    d: recorder.commits[d] - conflated[d] - zenoh.new[d]
                    for d in ids
                    if recorder.commits[d] - conflated[d] != zenoh.new[d]
                }
                newest = {
                    d: (hub.state(d).seq, zenoh.last.get(d))
                    for d in ids
                    if zenoh.last.get(d) != hub.state(d).seq
                }
                following = False
                follower.cancel()
                await asyncio.gather(follower, return_exceptions=True)
                await traffic.close()
                progress("stopping every drive")
                stop_refused = {}
                for d in ids:  # SCADA stops everything
                    reply = await gw.client.aone(f"{PREFIX}/drives/{d}/command", {"run": False})
                    if reply.json() != {"accepted": True}:
                        stop_refused[d] = reply.json()
                still_running = []
                for d in ids:
                    try:
                        await asyncio.wait_for(hub.wait_for(d, lambda s: not s.running), 10.0)
                    except TimeoutError:
                        still_running.append(d)
        finally:
            events.close()
            with contextlib.suppress(Exception):
                recorder.close()
        diag = gw.daemon.runtime.health()
        tally = traffic.tally
        growth = 100.0 * (rss_end - rss_start) / rss_start
        report = {
            "seconds": SECONDS,
            "warm_up_s": WARM_UP,
            "drives": len(ids),
            "rss_in_use_kib": {"after_warm_up": rss_start, "end": rss_end},
            "rss_raw_kib": {"after_warm_up": raw_start, "end": raw_end},
            "rss_raw_growth_pct": round(100.0 * (raw_end - raw_start) / raw_start, 2),
            "rss_in_use_growth_pct": round(growth, 2),
            "at_rest": {
                "after_warm_up": {k: v for k, v in at_rest.items() if k != "task_names"},
                "end": {k: v for k, v in at_rest_end.items() if k != "task_names"},
                "tasks_more_at_end": dict(at_rest_end["task_names"] - at_rest["task_names"]),
                "tasks_fewer_at_end": dict(at_rest["task_names"] - at_rest_end["task_names"]),
            },
            "events_by_kind": dict(events.kinds),
            "events_most_common": dict(events.texts.most_common(15)),
            "hub_states_committed": committed,
            "zenoh_states_received_new": received,
            "zenoh_reordered_count": len(zenoh.reordered),
            "zenoh_reordered": zenoh.reordered[:10],
            "hub_states_replaced_before_taken": sum(conflated.values()),
            "zenoh_lost": lost,
            "zenoh_not_newest_at_end": newest,
            "zenoh_stale_during_run": tally.stale[:10],
            "modbus_reads_new_seqs": sum(traffic.modbus_seqs.new.values()),
            "modbus_reordered_count": len(traffic.modbus_seqs.reordered),
            "modbus_reordered": traffic.modbus_seqs.reordered[:10],
            "sent": dict(tally.sent),
            "answered": dict(tally.answered),
            "refused": dict(tally.refused.most_common(12)),
            "unanswered": tally.unanswered[:10],
            "faulted_at_end": faulted,
            "not_following_their_command": not_following,
            "still_running_after_stop": still_running,
            "stop_refused": stop_refused,
            "profibus": {k: diag["buses"][PROFIBUS][k] for k in _PB_FIGURES},
            "devicenet": {k: diag["buses"][DEVICENET][k] for k in _DN_FIGURES},
            "adapter_restarts": dict(gw.daemon.runtime.restarts),
            "rss_in_use_kib_every_10_s": rss_trend,
            "rss_raw_kib_every_10_s": raw_trend,
            "python_blocks_every_10_s": blocks_trend,
            "python_objects_growth_top": objects_growth,
        }
        (tmp_path / "soak.json").write_text(json.dumps(report, indent=2))
        with capsys.disabled():
            print("\nsoak figures:\n" + json.dumps(report, indent=2))
        assert not zenoh.reordered and not traffic.modbus_seqs.reordered
        assert not lost and not newest and not tally.stale
        assert not tally.unanswered
        assert sum(tally.answered.values()) == sum(tally.sent.values())
        assert not not_following and not still_running and not stop_refused
        assert growth < 100 * MEMORY_GROWTH
        assert at_rest_end["tasks"] <= at_rest["tasks"]
        assert at_rest_end["threads"] <= at_rest["threads"]
        assert at_rest_end["fds"] <= at_rest["fds"]


_PB_FIGURES = (
    "cycles",
    "telegrams",
    "retries",
    "timeouts",
    "fcs_errors",
    "framing_errors",
    "cycle_ms",
    "reopens",
)
_DN_FIGURES = (
    "health",
    "frames_tx",
    "frames_rx",
    "tx_failures",
    "bus_conditions",
    "cycle_time_avg_ms",
    "cycle_time_max_ms",
    "error_frames",
)
