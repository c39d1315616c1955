"""CANopen PDO exchange on a paced CAN line: the gateway's CANopen adapter against a bare
loop of the canopen library, on the same bus, with the same simulated nodes, in the same
run.

The line: the bench CAN bus (:mod:`bench.plant.canbus`, python-can interface ``plantcan``),
a broker process that arbitrates and delivers each frame at the end of its bit time, at
1 Mbit/s (the fastest CiA 301 bit rate). The nodes: N simulated CiA 402 drives (1 and 32)
in their own process (``drive-gateway sim canopen`` through :mod:`bench.plant.launch`).
Both cases run in this process, one after the other, against that one simulator process:

- reference: the canopen library's own ``Network`` on the bus as a bare closed loop: each
  cycle the same RPDO1 (controlword + target) to every node and a SYNC, then wait for
  every node's TPDO1 before the next cycle, as fast as the line and the nodes answer;
- gateway: the CANopen adapter (master engine, shared CAN link and driver, CiA 402
  profile, hub updates) with SYNC at the physical minimum for the line: the bus time of one
  cycle (SYNC + every node's RPDO1 and TPDO1 at their worst-case stuffed CAN 2.0A lengths,
  ``adapters.canopen.options.min_sync_period``, rounded up to whole us): 285 us for 1
  node, 7,415 us for 32. RPDO1 goes out on change (or every 100 ms), TPDO1 comes back on
  every SYNC. It brings the nodes up itself (``reset_if_operational``: the reference left
  them operational).

Only RPDO1, TPDO1 and SYNC are exchanged: both cases switch the nodes' TPDO2 off
(0x1801:1 bit 31; the gateway by ``startup_sdo``, the bare loop by SDO). The EDS enables it
on every SYNC and the gateway's bring-up leaves it as it is, but ``min_sync_period`` does
not count it: at that period the line would carry more than its bit rate (one node: 300
bits every 285 us), the simulator's transmit queue would grow without end and its
heartbeats and SDO answers would wait behind it.

The drives' heartbeat is 1 s (the gateway takes a drive offline after 3 s without one), not
the 100 ms default: on the shared two-core machine the broker or the simulator process is
now and then held off the CPU for 100-200 ms (the broker's delivery lateness shows it), a
100 ms heartbeat then misses its 300 ms and the window measures a re-bring-up of every
drive, not the PDO exchange. The gateway's "drive offline" events in the window are in
the note all the same.

The figure: TPDO1s received per second divided by N (whole exchange cycles per second),
gateway against reference. The note gives the line's physical maximum (1 / the minimum
SYNC period), the bits each case actually put on the wire per cycle (the broker's frame
log), the CPU per cycle of this process in each case (the gateway's; the simulator and the
broker are other processes), the broker's delivery lateness, and the machine's load.

``python -m bench canopen``, or alone: ``python -m bench.bench_canopen [--nodes N ...]
[--seconds S]``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import canopen

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.options import min_sync_period
from adapters.canopen.sim.node import DEFAULT_EDS
from bench.common import Figure, id_range, node_counts_main
from bench.plant import canbus
from gateway.config import Config, parse
from gateway.model import CommState
from gateway.runtime.daemon import build_hub

HERE = Path(__file__).resolve().parent.parent
PY = sys.executable
MEASURE = 3.0  # s measured per case
SETTLE = 0.5  # s before measuring
BITRATE = 1_000_000  # bit/s: the fastest CiA 301 rate, the shortest SYNC period
NODE_COUNTS = (1, 32)
HEARTBEAT_MS = 1000  # the drives' 0x1017 (the gateway's consumer: 3 x that); see the docstring
TPDO2_OFF = 0x80000280  # 0x1801:1 with bit 31 set: TPDO2 not valid (CiA 301 7.5.2.35)
START_BOUND = 40.0  # s: broker, simulator boot-up, gateway bring-up, each at most
STOP_BOUND = 10.0  # s after SIGTERM, then SIGKILL (by pid)


@dataclass
class Case:
    """One measured case: cycles/s, CPU of this process per cycle, its window."""

    rate: float
    cpu: float
    t0: float
    t1: float
    cycles: int
    host_busy: float  # fraction of all CPUs busy during the window (everything on the machine)
    online: int = 0  # drives online at the end of the window (gateway)
    offline: tuple[str, ...] = ()  # the gateway's "drive offline" events in the window
    syncs: int = 0  # SYNCs the gateway sent in the window
    sim_cpu: float = 0.0  # the simulator process's CPU time in the window, s


@dataclass
class Procs:
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    logs: list[IO[bytes]] = field(default_factory=list)


def _config(bus: dict[str, object]) -> Config:
    return parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}},
        "bench",
    )


def _bus(channel: str, nodes: int) -> dict[str, object]:
    drives = [
        {
            "id": f"d{n}",
            "device": "CiA 402",
            "address": n,
            "eds": "eds/cia402-drive.eds",
            "max_rpm": 1800.0,
            "reset_if_operational": True,
            "heartbeat": HEARTBEAT_MS,
            "startup_sdo": {"0x1801:1": TPDO2_OFF + n},
        }
        for n in range(1, nodes + 1)
    ]
    return {
        "adapter": "canopen",
        "interface": canbus.INTERFACE,
        "channel": channel,
        "bitrate": BITRATE,
        "drives": drives,
    }


def line_minimum(bus: dict[str, object]) -> float:
    """One cycle's bus time at worst-case stuffing, s (the line's physical minimum)."""
    parsed = _config({**bus, "sync_period": 0.05}).buses[0]
    return min_sync_period(parsed.options.bitrate, [d.options for d in parsed.drives])


def physical_sync(bus: dict[str, object]) -> float:
    """The shortest SYNC period the line carries for this bus's drives, in whole us."""
    return math.ceil(round(line_minimum(bus) * 1e6, 6)) / 1e6


def _host_busy() -> tuple[int, int]:
    """(busy, total) jiffies of all CPUs (/proc/stat)."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle, iowait
    return sum(fields) - idle, sum(fields)


def _busy_since(before: tuple[int, int]) -> float:
    busy, total = _host_busy()
    return (busy - before[0]) / max(1, total - before[1])


# ---------------------------------------------------------------------- processes


def _start(procs: Procs, name: str, argv: list[str], tmp: Path) -> None:
    log = open(tmp / f"{name}.log", "wb")  # noqa: SIM115 - closed in _stop_all
    procs.logs.append(log)
    procs.procs[name] = subprocess.Popen(argv, cwd=HERE, stdout=log, stderr=log)


def _check_alive(procs: Procs, tmp: Path, what: str) -> None:
    for name, proc in procs.procs.items():
        if proc.poll() is not None:
            text = (tmp / f"{name}.log").read_text(errors="replace")[-2000:]
            raise RuntimeError(f"{name} ended ({proc.returncode}) before {what}:\n{text}")


def _stop_all(procs: Procs) -> None:
    """SIGTERM every process started, by pid; SIGKILL what has not ended in STOP_BOUND."""
    for proc in procs.procs.values():
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
    end = time.monotonic() + STOP_BOUND
    for proc in procs.procs.values():
        try:
            proc.wait(max(0.1, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait()
    for log in procs.logs:
        log.close()
    procs.logs.clear()


@contextlib.contextmanager
def _line(nodes: int) -> Iterator[tuple[Path, Procs]]:
    """A temporary directory with the broker running on ``can.sock``; every process
    started in it is stopped on the way out."""
    procs = Procs()
    with tempfile.TemporaryDirectory(prefix="bench-co-") as name:
        tmp = Path(name)
        try:
            sock = tmp / "can.sock"
            _start(
                procs,
                "canbus",
                [
                    *(PY, "-m", "bench.plant.canbus", "--path", str(sock)),
                    *("--bitrate", str(BITRATE), "--out", str(tmp / "canbus")),
                ],
                tmp,
            )
            end = time.monotonic() + START_BOUND
            while not sock.exists():
                _check_alive(procs, tmp, "the CAN broker's socket")
                if time.monotonic() > end:
                    raise RuntimeError("no CAN broker socket")
                time.sleep(0.05)
            yield tmp, procs
        finally:
            _stop_all(procs)


def _start_sim(procs: Procs, tmp: Path, nodes: int) -> None:
    node_args = [a for n in range(1, nodes + 1) for a in ("--node", str(n))]
    _start(
        procs,
        "canopen-sim",
        [
            *(PY, "-m", "bench.plant.launch", "--", "sim", "canopen"),
            *("--interface", canbus.INTERFACE, "--channel", str(tmp / "can.sock")),
            *node_args,
            *("--log-level", "WARNING"),
        ],
        tmp,
    )


# ---------------------------------------------------------------------- the two cases


def reference(network: canopen.Network, nodes: int, sim_pid: int, seconds: float) -> Case:
    """The bare canopen-library closed loop (see the module docstring)."""
    ids = list(range(1, nodes + 1))
    lock = threading.Lock()
    answered = threading.Event()
    seen: set[int] = set()

    def on_tpdo(can_id: int, data: bytearray, timestamp: float) -> None:
        with lock:
            seen.add(can_id)
            if len(seen) == nodes:
                answered.set()

    for n in ids:
        node = canopen.RemoteNode(n, str(DEFAULT_EDS))
        network.add_node(node)
        node.sdo[0x1800][2].raw = 1  # TPDO1 on every SYNC, as the gateway sets it
        node.sdo[0x1801][1].raw = TPDO2_OFF + n  # TPDO2 off, as the gateway's startup_sdo
        network.subscribe(0x180 + n, on_tpdo)
    network.nmt.send_command(0x01)  # start all
    rpdo = struct.pack("<Hh", 0x0006, 0)
    cycles = 0
    end = time.monotonic() + SETTLE + seconds
    started: float | None = None
    cpu = sim_cpu = 0.0
    host = _host_busy()
    while (now := time.monotonic()) < end:
        if started is None and now >= end - seconds:
            started, cycles, cpu, host = now, 0, time.process_time(), _host_busy()
            sim_cpu = _cpu_seconds(sim_pid)
        with lock:
            seen.clear()
            answered.clear()
        for n in ids:
            network.send_message(0x200 + n, rpdo)
        network.sync.transmit()
        if answered.wait(1.0):
            cycles += 1
    stopped = time.monotonic()
    cpu = time.process_time() - cpu
    sim_cpu = _cpu_seconds(sim_pid) - sim_cpu
    t0 = started if started is not None else stopped
    return Case(
        rate=cycles / max(stopped - t0, 1e-9),
        cpu=cpu / max(cycles, 1),
        t0=t0,
        t1=stopped,
        cycles=cycles,
        host_busy=_busy_since(host),
        sim_cpu=sim_cpu,
    )


async def gateway(channel: str, nodes: int, sim_pid: int, seconds: float) -> tuple[Case, float]:
    """The CANopen adapter at the physical minimum SYNC period; and that period."""
    bus = _bus(channel, nodes)
    sync_period = physical_sync(bus)
    config = _config({**bus, "sync_period": sync_period})
    hub = build_hub(config)
    adapter = CanOpenAdapter(config.buses[0])
    task = asyncio.create_task(adapter.run(hub))
    try:
        try:
            async with asyncio.timeout(START_BOUND):
                for d in config.drives:
                    await hub.wait_for(d.id, lambda s: s.comm is CommState.ONLINE)
        except TimeoutError:
            up = sum(1 for s in hub.states() if s.comm is CommState.ONLINE)
            raise RuntimeError(
                f"the gateway had {up}/{nodes} drive(s) online after {START_BOUND:g} s"
            ) from None
        await asyncio.sleep(SETTLE)
        engine = adapter.engine
        if engine is None:
            raise RuntimeError("the CANopen adapter stopped")
        first = sum(n.figures["tpdo_rx"] for n in engine.nodes.values())
        syncs = engine.figures["syncs_tx"]
        host = _host_busy()
        t0, cpu, sim_cpu = time.monotonic(), time.process_time(), _cpu_seconds(sim_pid)
        with hub.subscribe_events() as events:
            await asyncio.sleep(seconds)
            offline = tuple(e.text for e in events.drain() if "offline" in e.text)
        received = sum(n.figures["tpdo_rx"] for n in engine.nodes.values()) - first
        syncs = engine.figures["syncs_tx"] - syncs
        t1, cpu = time.monotonic(), time.process_time() - cpu
        sim_cpu = _cpu_seconds(sim_pid) - sim_cpu
        busy = _busy_since(host)
        online = sum(1 for s in hub.states() if s.comm is CommState.ONLINE)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    cycles = received / nodes
    case = Case(
        rate=cycles / (t1 - t0),
        cpu=cpu / max(cycles, 1.0),
        t0=t0,
        t1=t1,
        cycles=int(cycles),
        host_busy=busy,
        online=online,
        offline=offline,
        syncs=syncs,
        sim_cpu=sim_cpu,
    )
    return case, sync_period


def _wait_boot(network: canopen.Network, nodes: int, procs: Procs, tmp: Path) -> None:
    """Until every simulated node has sent its boot-up (the simulator is ready)."""
    booted: set[int] = set()
    lock = threading.Lock()

    def on_boot(can_id: int, data: bytearray, timestamp: float) -> None:
        if bytes(data[:1]) == b"\x00":
            with lock:
                booted.add(can_id - 0x700)

    for n in range(1, nodes + 1):
        network.subscribe(0x700 + n, on_boot)
    _start_sim(procs, tmp, nodes)
    end = time.monotonic() + START_BOUND
    while True:
        with lock:
            if len(booted) == nodes:
                break
        _check_alive(procs, tmp, "every node's boot-up")
        if time.monotonic() > end:
            raise RuntimeError(f"{nodes - len(booted)} simulated node(s) did not boot")
        time.sleep(0.05)
    for n in range(1, nodes + 1):
        network.unsubscribe(0x700 + n, on_boot)


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


def measure(nodes: int, seconds: float | None = None) -> Figure:
    """Both cases for ``nodes`` simulated nodes on one broker and one simulator process,
    each measured ``seconds`` (:data:`MEASURE` when None)."""
    seconds = MEASURE if seconds is None else seconds
    canbus.register()
    with _line(nodes) as (tmp, procs):
        channel = str(tmp / "can.sock")
        network = canopen.Network()
        network.NOTIFIER_CYCLE = 0.05
        network.connect(interface=canbus.INTERFACE, channel=channel)
        try:
            _wait_boot(network, nodes, procs, tmp)
            sim_pid = procs.procs["canopen-sim"].pid
            ref = reference(network, nodes, sim_pid, seconds)
        finally:
            network.disconnect()
        ours, sync_period = asyncio.run(gateway(channel, nodes, sim_pid, seconds))
        _stop_all(procs)
        ends, bits = canbus.load_log(str(tmp / "canbus"))
        summary = _read_summary(tmp / "canbus.json")
    line_max = 1.0 / line_minimum(_bus(channel, nodes))
    ref_bits = canbus.bits_between(ends, bits, ref.t0, ref.t1)
    our_bits = canbus.bits_between(ends, bits, ours.t0, ours.t1)
    ref_busy = ref_bits / (BITRATE * (ref.t1 - ref.t0))
    our_busy = our_bits / (BITRATE * (ours.t1 - ours.t0))
    late = summary.get("lateness_us", {})
    lost = sorted(set(ours.offline))
    load = os.getloadavg()[0]
    return Figure(
        name=f"canopen_pdo_cycles_{nodes}_nodes",
        value=round(ours.rate, 1),
        unit="cycles/s",
        reference=round(ref.rate, 1),
        target="ratio >= 0.5",
        note=(
            f"plantcan broker (frames paced at their bit time, arbitration) at "
            f"{BITRATE // 1000} kbit/s, {nodes} simulated CiA 402 node(s) in their own "
            f"process, the same one for both cases; line_max {line_max:.0f} cycles/s "
            f"(SYNC + RPDO1 + TPDO1 per node, worst-case stuffing); gateway: SYNC every "
            f"{sync_period * 1e6:.0f} us, {ours.syncs / (ours.t1 - ours.t0):.0f} SYNCs/s "
            f"sent, TPDO1s for {ours.cycles / max(ours.syncs, 1):.0%} of them (frames queued "
            f"before the window can land in it), {ours.online}/{nodes} drive(s) online "
            f"at the end, {len(ours.offline)} offline event(s) in the window {lost[:2]}, "
            f"line busy {our_busy:.0%} "
            f"({our_bits / max(ours.cycles, 1):.0f} bits per cycle), "
            f"{ours.cpu * 1e6:.0f} us CPU per cycle, the simulator's "
            f"{ours.sim_cpu / max(ours.cycles, 1) * 1e6:.0f} us; reference (bare canopen-library "
            f"closed loop, RPDO1 to every node + SYNC, wait for every TPDO1): line busy "
            f"{ref_busy:.0%} ({ref_bits / max(ref.cycles, 1):.0f} bits per cycle), "
            f"{ref.cpu * 1e6:.0f} us CPU per cycle, the simulator's "
            f"{ref.sim_cpu / max(ref.cycles, 1) * 1e6:.0f} us; broker delivery lateness "
            f"p50 {late.get('p50', 'n/a')} us p99 {late.get('p99', 'n/a')} us; machine: "
            f"CPUs busy {ref.host_busy:.0%} (reference) {ours.host_busy:.0%} (gateway), "
            f"load average {load:.1f}; TPDO2 off in both cases (not in the line's "
            "budget); the in-process virtual figures are gone (no line time there: they "
            "measured the reference's CPU, not the line)"
        ),
    )


def _read_summary(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def run(node_counts: tuple[int, ...] = NODE_COUNTS, seconds: float | None = None) -> list[Figure]:
    return [measure(n, seconds) for n in node_counts]


def main(argv: list[str] | None = None) -> int:
    return node_counts_main(
        argv,
        "bench_canopen",
        __doc__,
        ids=id_range(1, 127, "CANopen node counts (node ids 1..N)"),
        counts=NODE_COUNTS,
        what="simulated CiA 402 drives, one case per count",
        seconds=MEASURE,
        run=run,
    )


if __name__ == "__main__":
    raise SystemExit(main())
