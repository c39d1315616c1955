"""CPU per steady DeviceNet poll: the gateway's line against a bare request and response loop.

The gateway's side is its DeviceNet line as the daemon runs it: the adapter with its
CFW-08 profiles on a :class:`~gateway.runtime.linethread.LineThread` (a thread and event
loop of its own), its :class:`~gateway.runtime.lineport.LinePort` to a hub built from the
config, the hub on this process's loop. The nodes are the plant bench's: simulated CFW-08s
(``drive-gateway sim devicenet``) in a child process, on the bench CAN bus
(:mod:`bench.plant.canbus`: a broker process pacing every frame at 500 kbit/s, a python-can
interface each process opens).

The reference, in the same run, on the same bus and the same child: a bare python-can
request/response loop (``bus.send`` / ``bus.recv``, nothing decoded) that allocates each
node's poll connection and sets its EPR once, then sends the very poll frames the gateway
sent (each node's last output), a cycle of ``poll_window`` polls at a time, each cycle's
responses awaited before the next. Rounds alternate, gateway then bare; each side's figure
is the median.

Figures: CPU per poll of the line's thread and of the whole process (line, hub, hand-over),
against the bare loop's CPU per poll (target: ratio <= 2, issue 34).
"""

from __future__ import annotations

import asyncio
import contextlib
import cProfile
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from bench.common import Figure, add_counts, add_number, arg_parser, id_range, print_figures
from bench.linecpu import thread_cpu

NODES: Final = (8, 63)
BITRATE: Final = 500_000
WINDOW: Final = 8  # the scanner's poll window (ScannerConfig.poll_window)
ROUNDS: Final = 3
MEASURE: Final = 3.0  # s per round and side
SETTLE: Final = 1.0  # s of polling before a gateway round is measured
ONLINE_BOUND: Final = 60.0  # s for every drive to come online
TARGET: Final = "ratio <= 2"
MASTER_MAC: Final = 0
EPR_MS: Final = 500
PY: Final = sys.executable


def config_text(sock: Path, nodes: int) -> str:
    lines = [
        "[gateway]",
        'name = "dnpoll"',
        'log_level = "WARNING"',
        "[zenoh]",
        "enabled = false",
        "[modbus]",
        "enabled = false",
        "[buses.devicenet]",
        'adapter = "devicenet"',
        'interface = "plantcan"',
        f'channel = "{sock}"',
        f"bitrate = {BITRATE}",
        f"mac = {MASTER_MAC}",
        "poll_interval = 0.001",
        f"expected_packet_rate = {EPR_MS / 1000}",
        "status_interval = 60",
    ]
    for mac in range(1, nodes + 1):
        lines += [
            "[[buses.devicenet.drives]]",
            f'id = "dn{mac}"',
            'device = "CFW-08"',
            f"address = {mac}",
            f"modbus_unit = {mac}",
            "assembly = 21",
            'connection = "polled"',
            "max_rpm = 1800",
        ]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Side:
    polls: int
    thread_cpu: float  # s
    process_cpu: float  # s

    def per_poll(self, cpu: float) -> float:
        return cpu / self.polls if self.polls else float("nan")


async def gateway_round(
    config_path: Path, seconds: float, profile: str | None = None
) -> tuple[Side, dict[int, bytes]]:
    """One measured stretch of the gateway's line; the poll data it last sent, by MAC.
    ``profile``: a cProfile of the line's thread (its CPU time) over the stretch, to that
    file."""
    from gateway.config import load, load_adapter
    from gateway.model import CommState
    from gateway.runtime.daemon import build_hub
    from gateway.runtime.linethread import LineThread

    config = load(str(config_path))
    hub = build_hub(config)
    bus = config.buses[0]
    adapter = load_adapter(bus.adapter)(bus)
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    try:
        async with asyncio.timeout(ONLINE_BOUND):
            while not all(s.comm is CommState.ONLINE for s in hub.states()):  # noqa: ASYNC110
                await asyncio.sleep(0.05)
        await asyncio.sleep(SETTLE)
        engine = adapter.engine  # type: ignore[attr-defined]

        def polled() -> int:
            return sum(n.figures.rtt_count for n in engine.nodes.values())

        profiler = cProfile.Profile(time.thread_time) if profile else None
        if profiler is not None:
            await line.call(profiler.enable)
        first, t0, p0 = polled(), thread_cpu(line.thread), time.process_time()
        await asyncio.sleep(seconds)
        done, t1, p1 = polled(), thread_cpu(line.thread), time.process_time()
        if profiler is not None and profile:
            await line.call(profiler.disable)
            profiler.dump_stats(profile)
        outputs = {mac: bytes(n.output) for mac, n in engine.nodes.items()}
        return Side(done - first, t1 - t0, p1 - p0), outputs
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


# ---------------------------------------------------------------- the bare loop


def _ids(mac: int) -> tuple[int, int, int, int, int]:
    """(poll command, poll response, explicit request, explicit response, unconnected
    request) identifiers of a node (fact sheet 2.2)."""
    return (
        0x400 | mac << 3 | 5,
        0x3C0 | mac,
        0x400 | mac << 3 | 4,
        0x400 | mac << 3 | 3,
        0x400 | mac << 3 | 6,
    )


def _ask(bus: Any, ident: int, data: bytes, answer: int, bound: float = 1.0) -> bytes | None:
    import can

    bus.send(can.Message(arbitration_id=ident, data=data, is_extended_id=False))
    end = time.monotonic() + bound
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == answer:
            return bytes(msg.data)
    return None


def _connect(bus: Any, macs: list[int]) -> None:
    """Allocate each node's explicit and poll connections and set the poll EPR (what the
    scanner's bring-up does, nothing checked)."""
    from adapters.devicenet.codec.cip import CipClass
    from adapters.devicenet.codec.explicit import (
        AllocateConnectionSet,
        ExplicitMessage,
        ReleaseConnectionSet,
        SetAttributeSingle,
    )
    from adapters.devicenet.codec.objects import (
        AllocationChoice,
        ConnectionAttribute,
        ConnectionInstance,
    )

    choice = AllocationChoice.EXPLICIT | AllocationChoice.POLL
    epr = SetAttributeSingle(
        CipClass.CONNECTION,
        ConnectionInstance.POLL,
        ConnectionAttribute.EXPECTED_PACKET_RATE,
        EPR_MS.to_bytes(2, "little"),
    )
    for mac in macs:
        _, _, explicit, reply, unconnected = _ids(mac)
        release = ExplicitMessage(MASTER_MAC, False, ReleaseConnectionSet(choice)).encode()
        _ask(bus, unconnected, release, reply, 0.2)  # whatever the gateway left
        allocate = ExplicitMessage(MASTER_MAC, True, AllocateConnectionSet(choice, MASTER_MAC))
        if _ask(bus, unconnected, allocate.encode(), reply) is None:
            raise RuntimeError(f"node {mac}: no answer to Allocate")
        if _ask(bus, explicit, ExplicitMessage(MASTER_MAC, False, epr).encode(), reply) is None:
            raise RuntimeError(f"node {mac}: no answer to the EPR set")


def _release(bus: Any, macs: list[int]) -> None:
    from adapters.devicenet.codec.explicit import ExplicitMessage, ReleaseConnectionSet
    from adapters.devicenet.codec.objects import AllocationChoice

    choice = AllocationChoice.EXPLICIT | AllocationChoice.POLL
    for mac in macs:
        _, _, _, reply, unconnected = _ids(mac)
        message = ExplicitMessage(MASTER_MAC, True, ReleaseConnectionSet(choice)).encode()
        _ask(bus, unconnected, message, reply, 0.2)


def bare_round(sock: Path, outputs: dict[int, bytes], seconds: float) -> Side:
    """The bare request/response loop (see the module docstring)."""
    import can

    from bench.plant import canbus

    canbus.register()
    macs = sorted(outputs)
    bus = can.Bus(interface=canbus.INTERFACE, channel=str(sock), receive_own_messages=False)
    try:
        _connect(bus, macs)
        polls = [
            can.Message(arbitration_id=_ids(m)[0], data=outputs[m], is_extended_id=False)
            for m in macs
        ]
        cycles = [polls[i : i + WINDOW] for i in range(0, len(polls), WINDOW)]
        done = 0
        t0, p0 = time.thread_time(), time.process_time()
        end = time.monotonic() + seconds
        send, recv = bus.send, bus.recv
        while time.monotonic() < end:
            for cycle in cycles:
                for msg in cycle:
                    send(msg)
                waiting = len(cycle)
                while waiting:
                    reply = recv(1.0)
                    if reply is None:
                        break
                    if reply.arbitration_id & 0x7C0 == 0x3C0:  # a poll response
                        waiting -= 1
                        done += 1
        side = Side(done, time.thread_time() - t0, time.process_time() - p0)
        _release(bus, macs)
        return side
    finally:
        bus.shutdown()


# ---------------------------------------------------------------- the children


def _start(cmd: list[str], ready: Path, what: str) -> subprocess.Popen[bytes]:
    child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    end = time.monotonic() + 20
    while not ready.exists():
        if child.poll() is not None or time.monotonic() > end:
            raise RuntimeError(f"{what} did not start")
        time.sleep(0.05)
    return child


def _stop(child: subprocess.Popen[bytes]) -> None:
    child.send_signal(signal.SIGTERM)
    try:
        child.wait(10)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()


def measure(
    nodes: int, rounds: int, seconds: float, profile: str | None = None
) -> tuple[list[Side], list[Side]]:
    from bench.plant import canbus

    canbus.register()
    gateway: list[Side] = []
    bare: list[Side] = []
    with tempfile.TemporaryDirectory(prefix="bench-dnpoll-") as name:
        tmp = Path(name)
        sock = tmp / "can.sock"
        config = tmp / "dnpoll.toml"
        config.write_text(config_text(sock, nodes))
        broker = _start(
            [
                *(PY, "-m", "bench.plant.canbus", "--path", str(sock)),
                *("--bitrate", str(BITRATE), "--out", str(tmp / "canbus")),
            ],
            sock,
            "the CAN broker",
        )
        children = [broker]
        try:
            sim = subprocess.Popen(
                [
                    *(PY, "-m", "bench.plant.launch", "--", "sim", "devicenet"),
                    *("--interface", canbus.INTERFACE, "--channel", str(sock)),
                    *("--nodes", f"1-{nodes}" if nodes > 1 else "1", "--assembly", "21"),
                    *("--log-level", "WARNING"),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            children.append(sim)
            for _ in range(rounds):
                side, outputs = asyncio.run(gateway_round(config, seconds, profile))
                gateway.append(side)
                bare.append(bare_round(sock, outputs, seconds))
        finally:
            for child in reversed(children):
                _stop(child)
    return gateway, bare


def run(
    node_counts: tuple[int, ...] = NODES,
    rounds: int = ROUNDS,
    seconds: float = MEASURE,
    profile: str | None = None,
) -> list[Figure]:
    figures: list[Figure] = []
    med = statistics.median
    for nodes in node_counts:
        gateway, bare = measure(nodes, rounds, seconds, profile)
        bare_cpu = med(s.per_poll(s.thread_cpu) for s in bare) * 1e6
        line_cpu = med(s.per_poll(s.thread_cpu) for s in gateway) * 1e6
        whole_cpu = med(s.per_poll(s.process_cpu) for s in gateway) * 1e6
        rate = med(s.polls for s in gateway) / seconds
        bare_rate = med(s.polls for s in bare) / seconds
        note = (
            f"{nodes} CFW-08 polled at {BITRATE} bit/s on the bench CAN broker, simulated "
            f"in a child; {rounds} rounds of {seconds:g} s"
        )
        figures += [
            Figure(
                f"devicenet_line_cpu_per_poll_{nodes}_nodes",
                round(line_cpu, 2),
                "us",
                reference=round(bare_cpu, 2),
                target=TARGET,
                note="the line's thread; reference: a bare python-can request/response loop, "
                "same poll frames, same nodes, same bus; " + note,
            ),
            Figure(
                f"devicenet_gateway_cpu_per_poll_{nodes}_nodes",
                round(whole_cpu, 2),
                "us",
                reference=round(bare_cpu, 2),
                note="the whole process (line, hand-over, hub); " + note,
            ),
            Figure(
                f"devicenet_line_poll_rate_{nodes}_nodes",
                round(rate, 1),
                "1/s",
                reference=round(bare_rate, 1),
            ),
        ]
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_devicenet_poll", __doc__)
    add_counts(
        parser,
        "--nodes",
        id_range(1, 63, "DeviceNet node counts (MAC IDs 1..N)"),
        NODES,
        "simulated CFW-08s, one case per count",
    )
    add_number(parser, "--seconds", MEASURE, "seconds measured per round and side")
    add_number(parser, "--rounds", ROUNDS, "rounds of each side")
    parser.add_argument(
        "--profile", metavar="FILE", help="cProfile of the line's thread (its CPU time)"
    )
    args = parser.parse_args(argv)
    print_figures(run(tuple(args.nodes), args.rounds, args.seconds, args.profile))
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    raise SystemExit(main())
