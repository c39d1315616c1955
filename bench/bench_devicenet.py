"""DeviceNet poll cycle over python-can ``virtual``: the gateway's stack against raw round trips.

Scanner: the DeviceNet adapter (scanner engine, link, CFW-08 profile, hub updates) polling
1 and 63 simulated CFW-08s, as fast as the line allows; the figure is the average
time of a poll cycle (every node polled and answered), as polls per second.
Reference, same run, same interface: bare python-can request/response round trips
(Notifier + AsyncBufferedReader on both ends, a responder that answers at once) with
the same traffic: one 4-byte request and one 4-byte answer per node, 8 in flight.
Also: the time the physical bus itself needs for that traffic at 500 kbit/s (two frames
per node, 111-135 bits each, fact sheet 2.13).

``python -m bench devicenet``, or alone: ``python -m bench.bench_devicenet [--nodes N ...]
[--seconds S]``.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import time
import uuid

from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.link import CanLink, LinkConfig, RxFrame
from adapters.devicenet.sim import SimRunner
from adapters.devicenet.sim.simulated import sim_configs
from bench.common import Figure, id_range, node_counts_main
from gateway.config import parse
from gateway.model import CommState
from gateway.runtime.daemon import build_hub
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import FAST, node, sim

WINDOW = 8  # the scanner's poll window
MEASURE = 2.0  # s of polling measured per case
BITRATE = 500_000
FRAME_BITS = (111, 135)  # fact sheet 2.13
NODE_COUNTS = (1, 63)  # simulated CFW-08s per case: MAC IDs 1..N (DeviceNet MAC IDs are 0-63)


async def scanner_rate(nodes: int, seconds: float = MEASURE) -> tuple[float, float]:
    """(polls per second, average cycle in s) of the full DeviceNet stack."""
    channel = f"bench-{uuid.uuid4().hex[:8]}"
    drives = [
        {"id": f"d{m}", "device": "CFW-08", "address": m, "max_rpm": 1800.0}
        for m in range(1, nodes + 1)
    ]
    bus = {
        "adapter": "devicenet",
        "interface": "virtual",
        "channel": channel,
        "poll_interval": 0.001,
        "expected_packet_rate": 0.5,
        "response_timeout": 0.5,
        "dupmac_timeout": 0.05,
        "explicit_timeout": 0.5,
        "drives": drives,
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"dn": bus}},
        "bench",
    )
    hub = build_hub(config)
    adapter = DeviceNetAdapter(config.buses[0])
    runner = SimRunner(LinkConfig("virtual", channel), sim_configs(config.buses[0]))
    sim = asyncio.create_task(runner.run())
    await runner.started.wait()
    task = asyncio.create_task(adapter.run(hub))
    try:
        for d in drives:
            await asyncio.wait_for(
                hub.wait_for(str(d["id"]), lambda s: s.comm is CommState.ONLINE), 30
            )
        engine = adapter.engine
        assert engine is not None
        await asyncio.sleep(0.3)
        first = (engine.line.cycles, engine.line.cycle_sum)
        await asyncio.sleep(seconds)
        cycles = engine.line.cycles - first[0]
        spent = engine.line.cycle_sum - first[1]
    finally:
        for t in (task, sim):
            t.cancel()
        await asyncio.gather(task, sim, return_exceptions=True)
    cycle = spent / cycles
    return nodes / cycle, cycle


async def raw_rate(nodes: int, seconds: float = MEASURE) -> tuple[float, float]:
    """(round trips per second, average cycle in s) of bare python-can on virtual."""
    channel = f"raw-{uuid.uuid4().hex[:8]}"
    async with (
        CanLink(LinkConfig("virtual", channel)) as master,
        CanLink(LinkConfig("virtual", channel)) as slave,
    ):

        async def respond() -> None:
            while True:
                for event in await slave.receive(1.0):
                    if isinstance(event, RxFrame):
                        mac = event.frame.arbitration_id >> 3 & 0x3F
                        slave.send([CanFrame(0x3C0 | mac, b"\x10\x03\x00\x00")])

        responder = asyncio.create_task(respond())
        try:
            cycles, spent = 0, 0.0
            end = time.perf_counter() + seconds + 0.3
            while time.perf_counter() < end:
                spent += await _raw_cycle(master, nodes)
                cycles += 1
        finally:
            responder.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await responder
    cycle = spent / cycles
    return nodes / cycle, cycle


async def _raw_cycle(master: CanLink, nodes: int) -> float:
    started = time.perf_counter()
    todo = list(range(1, nodes + 1))
    in_flight = 0
    answered = 0
    while answered < nodes:
        while todo and in_flight < WINDOW:
            mac = todo.pop(0)
            master.send([CanFrame(0x400 | mac << 3 | 5, b"\x00\x00\x00\x00")])
            in_flight += 1
        for event in await master.receive(1.0):
            if isinstance(event, RxFrame):
                in_flight -= 1
                answered += 1
    return time.perf_counter() - started


def bus_time(nodes: int) -> tuple[float, float]:
    """Seconds the 500 kbit/s bus needs for one cycle: best and worst case."""
    frames = 2 * nodes
    return frames * FRAME_BITS[0] / BITRATE, frames * FRAME_BITS[1] / BITRATE


def timer_step(lazy: bool, nodes: int = 63, steps: int = 2000) -> float:
    """Seconds per scanner timer step on a steady line of ``nodes`` polled CFW-08s with
    nothing due: looking at the nodes due or busy only (``lazy``), or passing over every
    node (the scanner's ``lazy_timers`` off). The line comes up on the test harness's
    ideal bus with a fake clock; the steps are then timed on the engine alone, best of
    three rounds."""
    config = dataclasses.replace(FAST, explicit_epr=2.5, poll_interval=0.001)
    macs = range(1, nodes + 1)
    line = Line(config, [node(m) for m in macs], [sim(m) for m in macs])
    line.scanner.lazy_timers = lazy
    line.power_on()
    line.run(2.0)
    scanner, now = line.scanner, line.now
    scanner.step(now)  # the pass after the last event
    best = math.inf
    for _ in range(3):
        started = time.perf_counter()
        for _ in range(steps):
            scanner.step(now)
        best = min(best, (time.perf_counter() - started) / steps)
    return best


def timer_step_figure() -> Figure:
    lazy, full = timer_step(True), timer_step(False)
    return Figure(
        name="devicenet_timer_step_63_nodes",
        value=round(lazy * 1e6, 2),
        unit="us",
        reference=round(full * 1e6, 2),
        note=(
            "engine alone, a timer step on a steady line with nothing due (best of 3); "
            "reference: the full pass over every node, as before SteadyTimers"
        ),
    )


async def _run(node_counts: tuple[int, ...], seconds: float) -> list[Figure]:
    figures: list[Figure] = [timer_step_figure()]
    for nodes in node_counts:
        raw, raw_cycle = await raw_rate(nodes, seconds)
        ours, our_cycle = await scanner_rate(nodes, seconds)
        best, worst = bus_time(nodes)
        figures.append(
            Figure(
                name=f"devicenet_poll_rate_{nodes}_nodes",
                value=round(ours, 1),
                unit="polls/s",
                reference=round(raw, 1),
                target="ratio >= 0.5",
                note=f"python-can virtual; reference: bare request/response, {WINDOW} in flight",
            )
        )
        figures.append(
            Figure(
                name=f"devicenet_poll_cycle_{nodes}_nodes",
                value=round(our_cycle * 1000, 3),
                unit="ms",
                reference=round(raw_cycle * 1000, 3),
                note="average poll cycle (every node polled and answered)",
            )
        )
        figures.append(
            Figure(
                name=f"devicenet_bus_cycle_500k_{nodes}_nodes",
                value=round(best * 1000, 3),
                unit="ms",
                note=(
                    f"physical bus time at 500 kbit/s, 2 frames x 111 bits per node; "
                    f"worst case (135 bits) {worst * 1000:.3f} ms"
                ),
            )
        )
    return figures


def run(node_counts: tuple[int, ...] = NODE_COUNTS, seconds: float = MEASURE) -> list[Figure]:
    return asyncio.run(_run(node_counts, seconds))


def main(argv: list[str] | None = None) -> int:
    return node_counts_main(
        argv,
        "bench_devicenet",
        __doc__,
        ids=id_range(1, 63, "DeviceNet node counts (MAC IDs 1..N)"),
        counts=NODE_COUNTS,
        what="simulated CFW-08s, one case per count",
        seconds=MEASURE,
        run=run,
    )


if __name__ == "__main__":
    raise SystemExit(main())
