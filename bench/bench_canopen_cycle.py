"""CPU per CANopen SYNC cycle: the gateway's whole CANopen line against a bare python-can loop.

The gateway's side is its CANopen line as the daemon runs it: the CANopen adapter (master
engine, CAN link and driver, CiA 402 profile) with N CiA 402 drives on a
:class:`~gateway.runtime.linethread.LineThread` (a thread and event loop of its own), its
:class:`~gateway.runtime.lineport.LinePort` to a hub built from the config, the hub on this
process's loop. The nodes: N simulated CiA 402 drives in a child process
(``drive-gateway sim canopen`` through :mod:`bench.plant.launch`) on the bench CAN bus
(:mod:`bench.plant.canbus`: a broker process shared between processes that arbitrates and
delivers each frame at the end of its bit time, at 1 Mbit/s).

The reference, in the same run, on the same bus and against the same child: a bare
python-can loop (a blocking ``recv`` with a timeout, nothing decoded) that sends, cycle by
cycle at the same SYNC period, the very frames the gateway sent in its measured stretch
(captured from its CAN link: the SYNC, the RPDO1s, the gateway's heartbeat), sleeps until
just before the next cycle and then takes every frame waiting (the TPDO1s, the nodes'
heartbeats), as the gateway's receive hold does on a steady line. Rounds alternate,
gateway then bare; each side's figure is the median of its rounds.

Figures: CPU per SYNC cycle of the line's thread, and per node; of the whole process (line,
hub, hand-over); against the bare loop's CPU per cycle (issue 34: a steady exchange costs
next to nothing). ``--general`` measures the line without its steady fast path
(``CanOpenAdapter.fast_path`` off: every TPDO1 handled, every command read each cycle). ``--profile`` prints where the line's thread spends its CPU
(``cProfile`` with ``time.thread_time`` in that thread) in the last gateway round.
"""

from __future__ import annotations

import asyncio
import contextlib
import cProfile
import io
import pstats
import statistics
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Final

from bench.common import Figure, add_number, arg_parser, positive_int, print_figures
from bench.linecpu import thread_cpu

NODES: Final = 32
SYNC: Final = 0.01  # s: the SYNC period (100 cycles/s; 32 nodes need 7.4 ms at 1 Mbit/s)
ROUNDS: Final = 3
MEASURE: Final = 3.0  # s per round and side
SETTLE: Final = 1.0  # s of steady exchange before a round is measured
ONLINE_BOUND: Final = 60.0  # s for every drive to come online
NMT_START_ALL: Final = (0x000, b"\x01\x00")
COB_SYNC: Final = 0x080
TARGET: Final = "ratio <= 2"


class GENERAL:
    on = False  # --general: the line without its steady fast path


DRAIN_AHEAD: Final = 0.0005  # s before the next cycle the bare loop takes what came


@dataclass(frozen=True)
class Side:
    cycles: int
    thread_cpu: float  # s
    process_cpu: float  # s
    tpdos: int = 0
    hub_updates: int = 0  # the line's updates to the hub in the window

    def per_cycle(self, cpu: float) -> float:
        return cpu / self.cycles if self.cycles else float("nan")


@dataclass
class Capture:
    """The frames the gateway sends while measuring (``CanLink.send`` wrapped)."""

    on: bool = False
    frames: list[tuple[int, bytes]] = field(default_factory=list)

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        from adapters.link.can import CanLink

        original = CanLink.send

        def send(link: Any, frames: Any) -> Any:
            batch = frames if isinstance(frames, list) else list(frames)
            if self.on and len(self.frames) < 500_000:
                self.frames.extend((f.arbitration_id, bytes(f.data)) for f in batch)
            return original(link, batch)

        CanLink.send = send  # type: ignore[method-assign,assignment]
        try:
            yield
        finally:
            CanLink.send = original  # type: ignore[method-assign]

    def cycles(self) -> list[list[tuple[int, bytes]]]:
        """The captured frames cut into cycles, each starting with its SYNC."""
        out: list[list[tuple[int, bytes]]] = []
        for frame in self.frames:
            if frame[0] == COB_SYNC or not out:
                out.append([])
            out[-1].append(frame)
        return [c for c in out if c and c[0][0] == COB_SYNC]


class _Counting:
    """Counts the hub updates the line hands over (``Hub.update`` wrapped)."""

    def __init__(self, hub: Any) -> None:
        self.count = 0
        original = hub.update

        def update(drive_id: str, **changes: Any) -> Any:
            self.count += 1
            return original(drive_id, **changes)

        hub.update = update


async def gateway_round(
    channel: str, nodes: int, sync: float, capture: Capture, seconds: float, *, profile: bool
) -> tuple[Side, str]:
    from bench.bench_canopen import _bus, _config
    from gateway.config import load_adapter
    from gateway.model import CommState
    from gateway.runtime.daemon import build_hub
    from gateway.runtime.linethread import LineThread

    config = _config({**_bus(channel, nodes), "sync_period": sync})
    hub = build_hub(config)
    counting = _Counting(hub)
    bus = config.buses[0]
    adapter = load_adapter(bus.adapter)(bus)
    if GENERAL.on:
        adapter.fast_path = False  # type: ignore[attr-defined]
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    report = ""
    try:
        try:
            async with asyncio.timeout(ONLINE_BOUND):
                while not all(s.comm is CommState.ONLINE for s in hub.states()):  # noqa: ASYNC110
                    await asyncio.sleep(0.05)
        except TimeoutError:
            up = sum(1 for s in hub.states() if s.comm is CommState.ONLINE)
            raise RuntimeError(f"{up}/{nodes} drive(s) online after {ONLINE_BOUND:g} s") from None
        await asyncio.sleep(SETTLE)
        engine = adapter.engine  # type: ignore[attr-defined]

        def figures() -> tuple[int, int]:
            tpdos = sum(n.figures["tpdo_rx"] for n in engine.nodes.values())
            return engine.figures["syncs_tx"], tpdos

        prof = cProfile.Profile(time.thread_time) if profile else None
        if prof is not None:
            await line.call(prof.enable)
        capture.frames.clear()
        capture.on = True
        (s0, r0), t0, p0, u0 = figures(), thread_cpu(line.thread), time.process_time(), 0
        u0 = counting.count
        await asyncio.sleep(seconds)
        (s1, r1), t1, p1 = figures(), thread_cpu(line.thread), time.process_time()
        u1 = counting.count
        capture.on = False
        if prof is not None:
            await line.call(prof.disable)
            text = io.StringIO()
            pstats.Stats(prof, stream=text).sort_stats("tottime").print_stats(35)
            report = text.getvalue()
        return Side(s1 - s0, t1 - t0, p1 - p0, r1 - r0, u1 - u0), report
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def bare_round(
    channel: str, cycles: list[list[tuple[int, bytes]]], sync: float, seconds: float
) -> Side:
    """The captured cycles sent again at the same period by a bare blocking python-can loop
    that receives everything in between (see the module docstring)."""
    import can

    from bench.plant import canbus

    if not cycles:
        raise RuntimeError("no SYNC cycle captured from the gateway")
    bus = can.Bus(interface=canbus.INTERFACE, channel=channel)
    try:
        message, recv = can.Message, bus.recv
        bus.send(
            message(arbitration_id=NMT_START_ALL[0], data=NMT_START_ALL[1], is_extended_id=False)
        )
        prepared = [
            [message(arbitration_id=i, data=d, is_extended_id=False) for i, d in cycle]
            for cycle in cycles
        ]
        done = tpdos = 0
        warm = time.monotonic() + SETTLE
        end = 0.0
        t0 = p0 = 0.0
        at = time.monotonic()
        k = 0
        measuring = False
        while True:
            now = time.monotonic()
            if not measuring and now >= warm:
                measuring, done, tpdos = True, 0, 0
                end = now + seconds
                t0, p0 = time.thread_time(), time.process_time()
            if measuring and now >= end:
                break
            for out in prepared[k % len(prepared)]:
                bus.send(out)
            k += 1
            done += 1
            at += sync
            if at < now:
                at = now + sync
            # asleep until just before the next cycle, then everything waiting taken at
            # once (the gateway's receive hold does the same on a steady line)
            left = at - DRAIN_AHEAD - time.monotonic()
            if left > 0:
                time.sleep(left)
            while (msg := recv(0)) is not None:
                if 0x180 < msg.arbitration_id < 0x200:
                    tpdos += 1
            left = at - time.monotonic()
            if left > 0:
                time.sleep(left)
        return Side(done, time.thread_time() - t0, time.process_time() - p0, tpdos)
    finally:
        bus.shutdown()


def measure(
    nodes: int, sync: float, rounds: int, seconds: float, profile: bool
) -> tuple[list[Side], list[Side], str]:
    from bench.bench_canopen import _line, _start_sim
    from bench.plant import canbus

    canbus.register()
    gateway: list[Side] = []
    bare: list[Side] = []
    capture = Capture()
    report = ""
    with _line(nodes) as (tmp, procs):
        channel = str(tmp / "can.sock")
        _start_sim(procs, tmp, nodes)
        with capture.installed():
            for i in range(rounds):
                last = profile and i == rounds - 1
                side, text = asyncio.run(
                    gateway_round(channel, nodes, sync, capture, seconds, profile=last)
                )
                gateway.append(side)
                report = text or report
                bare.append(bare_round(channel, capture.cycles(), sync, seconds))
    return gateway, bare, report


def run(
    nodes: int = NODES,
    sync: float = SYNC,
    rounds: int = ROUNDS,
    seconds: float = MEASURE,
    profile: bool = False,
) -> list[Figure]:
    gateway, bare, report = measure(nodes, sync, rounds, seconds, profile)
    if report:
        print(report, flush=True)
    med = statistics.median
    bare_cpu = med(s.per_cycle(s.thread_cpu) for s in bare) * 1e6
    line_cpu = med(s.per_cycle(s.thread_cpu) for s in gateway) * 1e6
    whole_cpu = med(s.per_cycle(s.process_cpu) for s in gateway) * 1e6
    updates = med(s.hub_updates / s.cycles for s in gateway if s.cycles)
    tpdos = med(s.tpdos / s.cycles for s in gateway if s.cycles)
    bare_tpdos = med(s.tpdos / s.cycles for s in bare if s.cycles)
    note = (
        f"{nodes} simulated CiA 402 nodes in a child, plantcan broker at 1 Mbit/s, SYNC every "
        f"{sync * 1e3:g} ms; {rounds} rounds of {seconds:g} s; TPDO1s per cycle: gateway "
        f"{tpdos:.1f}, bare {bare_tpdos:.1f}; hub updates per cycle {updates:.2f}"
    )
    return [
        Figure(
            "canopen_line_cpu_per_cycle",
            round(line_cpu, 1),
            "us",
            reference=round(bare_cpu, 1),
            target=TARGET,
            note="the line's thread; reference: a bare python-can loop, same frames, same "
            "nodes; " + note,
        ),
        Figure(
            "canopen_line_cpu_per_node",
            round(line_cpu / nodes, 2),
            "us",
            reference=round(bare_cpu / nodes, 2),
            target=TARGET,
            note="the line's thread per SYNC cycle and node; " + note,
        ),
        Figure(
            "canopen_gateway_cpu_per_cycle",
            round(whole_cpu, 1),
            "us",
            reference=round(bare_cpu, 1),
            target=TARGET,
            note="the whole process (line, hand-over, hub); " + note,
        ),
        Figure(
            "canopen_line_cycle_rate",
            round(med(s.cycles for s in gateway) / seconds, 1),
            "1/s",
            reference=round(med(s.cycles for s in bare) / seconds, 1),
        ),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_canopen_cycle", __doc__)
    parser.add_argument("--nodes", type=positive_int, default=NODES, metavar="N", help="nodes")
    add_number(parser, "--sync", SYNC, "SYNC period, s")
    add_number(parser, "--seconds", MEASURE, "seconds measured per round and side")
    add_number(parser, "--rounds", ROUNDS, "rounds of each side")
    parser.add_argument("--profile", action="store_true", help="profile the line's thread")
    parser.add_argument("--general", action="store_true", help="without the steady fast path")
    args = parser.parse_args(argv)
    GENERAL.on = args.general
    print_figures(run(args.nodes, args.sync, args.rounds, args.seconds, args.profile))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
