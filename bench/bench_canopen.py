"""CANopen PDO exchange over python-can ``virtual``: the gateway's stack against a bare
loop of the canopen library, with the same simulated CiA 402 nodes, in the same run.

Gateway: the CANopen adapter (master engine, shared CAN link and driver, CiA 402
profile, hub updates) with N simulated nodes (1 and 32) in-process, at 1 Mbit/s (the
fastest CiA 301 bit rate) with SYNC at the physical minimum for that bit rate: the bus
time of one cycle (SYNC + every node's RPDO1 and TPDO1 at their worst-case stuffed CAN
2.0A lengths, ``adapters.canopen.options.min_sync_period``, rounded up to whole us), the
shortest ``sync_period`` the configuration takes: 285 us for 1 node, 7,415 us for 32.
Every cycle is a SYNC and one RPDO1 per node out (sent on change or every 100 ms; the
drives hold the last one), one TPDO1 per node back (synchronous after the gateway's
bring-up). The figure: TPDO1s received per second divided by N (whole exchange cycles
per second); it cannot exceed 1 / sync_period (``line_ceiling`` in the note).
Reference, same run, same simulator: the canopen library's own network as a bare
closed loop, each cycle sending the same RPDO1 to every node and a SYNC, then waiting
for every node's TPDO1 before the next cycle, as fast as the nodes answer. ``virtual``
has no bit rate: the reference is bound by no line time, the gateway by its SYNC period.

The simulator runs in the same process (it shares the interpreter with both), so the
figures are the stack's cost beside a busy simulator, not line speed.
"""

from __future__ import annotations

import asyncio
import math
import struct
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor

import canopen

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.options import min_sync_period
from adapters.canopen.sim import SimNodeConfig, SimRunner
from adapters.canopen.sim.node import DEFAULT_EDS
from adapters.canopen.sim.simulated import SimulatedBus
from bench.common import Figure
from gateway.config import Config, parse
from gateway.daemon import build_hub
from gateway.model import CommState

MEASURE = 2.0  # s measured per case
SETTLE = 0.3  # s before measuring
BITRATE = 1_000_000  # bit/s: the fastest CiA 301 rate, the shortest SYNC period
NODE_COUNTS = (1, 32)


def _config(bus: dict[str, object]) -> Config:
    return parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}},
        "bench",
    )


def physical_sync(bus: dict[str, object]) -> float:
    """The shortest SYNC period the line carries for this bus's drives, in whole us."""
    parsed = _config({**bus, "sync_period": 0.05}).buses[0]
    shortest = min_sync_period(parsed.options.bitrate, [d.options for d in parsed.drives])
    return math.ceil(round(shortest * 1e6, 6)) / 1e6


async def gateway_rate(nodes: int) -> tuple[float, float, float]:
    """Exchange cycles per second through the CANopen adapter at the physical minimum
    SYNC period, that period, and the event loop thread's CPU time per cycle (the
    gateway's: the simulator runs on the notifier thread)."""
    channel = f"bench-co-{uuid.uuid4().hex[:8]}"
    drives = [
        {
            "id": f"d{n}",
            "device": "CiA 402",
            "address": n,
            "eds": "eds/cia402-drive.eds",
            "max_rpm": 1800.0,
        }
        for n in range(1, nodes + 1)
    ]
    bus = {
        "adapter": "canopen",
        "interface": "virtual",
        "channel": channel,
        "simulate": True,
        "bitrate": BITRATE,
        "drives": drives,
    }
    sync_period = physical_sync(bus)
    config = _config({**bus, "sync_period": sync_period})
    hub = build_hub(config)
    bus_config = config.buses[0]
    line = SimulatedBus(bus_config)
    adapter = CanOpenAdapter(bus_config, links=line)
    task = asyncio.create_task(adapter.run(hub))
    try:
        for d in drives:
            await asyncio.wait_for(
                hub.wait_for(str(d["id"]), lambda s: s.comm is CommState.ONLINE), 60
            )
        await asyncio.sleep(SETTLE)
        engine = adapter.engine
        if engine is None:
            raise RuntimeError("the CANopen adapter stopped")
        first = sum(n.figures["tpdo_rx"] for n in engine.nodes.values())
        started, cpu = time.perf_counter(), time.thread_time()
        await asyncio.sleep(MEASURE)
        received = sum(n.figures["tpdo_rx"] for n in engine.nodes.values()) - first
        spent, cpu = time.perf_counter() - started, time.thread_time() - cpu
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    cycles = max(received / nodes, 1.0)
    return received / nodes / spent, sync_period, cpu / cycles


async def library_rate(nodes: int) -> tuple[float, float]:
    """Exchange cycles per second of a bare canopen-library loop on the same nodes, and
    its thread's CPU time per cycle."""
    channel = f"bench-lib-{uuid.uuid4().hex[:8]}"
    ids = list(range(1, nodes + 1))
    runner = SimRunner("virtual", channel, [SimNodeConfig(n) for n in ids])
    sim = asyncio.create_task(runner.run())
    await runner.started.wait()
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05
    lock = threading.Lock()
    answered = threading.Event()
    seen: set[int] = set()

    def on_tpdo(can_id: int, data: bytearray, timestamp: float) -> None:
        with lock:
            seen.add(can_id)
            if len(seen) == nodes:
                answered.set()

    def loop() -> tuple[float, float]:
        network.connect(interface="virtual", channel=channel)
        try:
            for n in ids:
                node = canopen.RemoteNode(n, str(DEFAULT_EDS))
                network.add_node(node)
                node.sdo[0x1800][2].raw = 1  # TPDO1 on every SYNC, as the gateway sets it
                network.subscribe(0x180 + n, on_tpdo)
            network.nmt.send_command(0x01)  # start all
            rpdo = struct.pack("<Hh", 0x0006, 0)
            cycles = 0
            end = time.perf_counter() + SETTLE + MEASURE
            started = None
            cpu = 0.0
            while (now := time.perf_counter()) < end:
                if started is None and now >= end - MEASURE:
                    started, cycles, cpu = now, 0, time.thread_time()
                with lock:
                    seen.clear()
                    answered.clear()
                for n in ids:
                    network.send_message(0x200 + n, rpdo)
                network.sync.transmit()
                if answered.wait(1.0):
                    cycles += 1
            cpu = time.thread_time() - cpu
            return cycles / (time.perf_counter() - (started or end)), cpu / max(cycles, 1)
        finally:
            network.disconnect()

    pool = ThreadPoolExecutor(1)
    try:
        return await asyncio.get_running_loop().run_in_executor(pool, loop)
    finally:
        pool.shutdown(wait=True)
        runner.stop()
        await sim


async def _run() -> list[Figure]:
    figures: list[Figure] = []
    for nodes in NODE_COUNTS:
        reference, ref_cpu = await library_rate(nodes)
        ours, sync_period, cpu = await gateway_rate(nodes)
        ceiling = 1.0 / sync_period
        figures.append(
            Figure(
                name=f"canopen_pdo_cycles_{nodes}_nodes",
                value=round(ours, 1),
                unit="cycles/s",
                reference=round(reference, 1),
                target="ratio >= 0.5",
                note=(
                    f"python-can virtual, simulated CiA 402 nodes in-process; gateway at "
                    f"{BITRATE // 1000} kbit/s with SYNC every {sync_period * 1e6:.0f} us, the "
                    f"physical minimum (one cycle's bus time, worst-case stuffing): "
                    f"line_ceiling {ceiling:.0f} cycles/s, ratio at most "
                    f"{ceiling / reference:.2f}; reference: bare canopen-library closed loop "
                    "(RPDO1 to every node + SYNC, wait for every TPDO1), no line time; CPU per "
                    f"cycle: gateway's event loop thread {cpu * 1e6:.0f} us, reference's "
                    f"thread {ref_cpu * 1e6:.0f} us"
                ),
            )
        )
    return figures


def run() -> list[Figure]:
    return asyncio.run(_run())
