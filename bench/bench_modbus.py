"""Modbus TCP front end: status-block read rate against bare pymodbus, and command latency.

1. Reads per second of one drive's status block (function 4, input registers
   0-20) by 8 concurrent clients, against the gateway (daemon with simulated
   drives updating at 100 Hz) and against a bare pymodbus ``SimDevice`` server
   holding the same registers, in the same run. The clients run in a child
   process (raw asyncio sockets, one request in flight each) so that the
   servers, not the load generator, are measured. Rounds alternate bare /
   gateway and the best round of each counts (the machine's noise only ever
   slows a round down); the ratio target is >= 0.8. The server's CPU time per
   read is reported as well: it is steadier than wall-clock throughput when
   other processes share the machine.
2. Command latency: a function 6 write of holding register 0 until the hub's
   desired command has changed (``hub.on_command`` fires), over 1000 commands
   alternating run 1/0 (each one a run edge), p50 and p99; target p99 < 5 ms.

``python -m bench modbus``, or alone: ``python -m bench.bench_modbus [--rounds N]
[--round-seconds S] [--clients N] [--commands N]`` (``--load ...`` is the load generator
the benchmark starts itself).
"""

from __future__ import annotations

import asyncio
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from bench.common import Figure, add_number, arg_parser, positive_int, print_figures
from gateway.config import load
from gateway.modbus.frontend import ModbusFrontEnd
from gateway.modbus.map import DRIVE_HOLDINGS, DRIVE_INPUTS, MIRROR_OFFSET
from gateway.modbus.regs import block_size
from gateway.runtime.daemon import Daemon
from gateway.runtime.systemd import Notifier
from tests.support import plugins
from tests.support.net import free_port

ROOT = Path(__file__).resolve().parents[1]
UNIT = 1
CLIENTS = 8
ROUND_S = 1.0
ROUNDS = 5
COMMANDS = 1000
INPUTS = block_size(DRIVE_INPUTS)

plugins.register()

CONFIG = """
[gateway]
shutdown_timeout = 2.0
[zenoh]
enabled = false
[modbus]
enabled = false
bind = "127.0.0.1:{port}"
allow = ["127.0.0.0/8"]
[buses.line1]
adapter = "fake"  # tests/support/plugins.py
cycle = 0.01
[[buses.line1.drives]]
id = "d1"
device = "test"
address = 3
modbus_unit = {unit}
ramp_time = 0.2
"""


def frame(tid: int, unit: int, pdu: bytes) -> bytes:
    return (
        tid.to_bytes(2, "big")
        + b"\x00\x00"
        + (len(pdu) + 1).to_bytes(2, "big")
        + bytes([unit])
        + pdu
    )


READ_STATUS = b"\x04\x00\x00" + INPUTS.to_bytes(2, "big")
READ_REPLY = 7 + 2 + 2 * INPUTS


# ------------------------------------------------------------------ load generator (child)


async def _reader_loop(port: int, unit: int, deadline: float) -> int:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    done = 0
    tid = 0
    try:
        while time.monotonic() < deadline:
            tid = (tid + 1) & 0xFFFF
            writer.write(frame(tid, unit, READ_STATUS))
            reply = await reader.readexactly(READ_REPLY)
            if reply[7] != 4:
                raise RuntimeError(f"unexpected reply {reply.hex()}")
            done += 1
    finally:
        writer.close()
        await writer.wait_closed()
    return done


async def _load(port: int, unit: int, seconds: float, clients: int) -> dict[str, float]:
    started = time.monotonic()
    counts = await asyncio.gather(
        *(_reader_loop(port, unit, started + seconds) for _ in range(clients))
    )
    return {"reads": float(sum(counts)), "seconds": time.monotonic() - started}


@dataclass(frozen=True)
class Round:
    rate: float  # reads per second (wall clock)
    cpu_us: float  # this process's CPU time per read, in µs


async def measure_reads(port: int, seconds: float = ROUND_S, clients: int = CLIENTS) -> Round:
    """One round of load on the server at ``port`` from a child process."""
    cpu0 = time.process_time()
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bench.bench_modbus",
        "--load",
        str(port),
        str(UNIT),
        str(seconds),
        str(clients),
        cwd=ROOT,
        stdout=asyncio.subprocess.PIPE,
    )
    out, _ = await proc.communicate()
    cpu = time.process_time() - cpu0
    if proc.returncode != 0:
        raise RuntimeError(f"load generator failed ({proc.returncode})")
    result = json.loads(out)
    reads = float(result["reads"])
    return Round(rate=reads / float(result["seconds"]), cpu_us=1e6 * cpu / max(reads, 1.0))


# ------------------------------------------------------------------ servers


async def bare_server(port: int, registers: list[int]) -> ModbusTcpServer:
    """pymodbus alone: a SimDevice with the same blocks, no action."""
    bits = [SimData(0, datatype=DataType.BITS)]
    holdings = [SimData(h.address, datatype=DataType.REGISTERS) for h in DRIVE_HOLDINGS]
    holdings.append(SimData(MIRROR_OFFSET, values=registers, datatype=DataType.REGISTERS))
    inputs = [SimData(0, values=registers, datatype=DataType.REGISTERS)]
    device = SimDevice(id=UNIT, simdata=(bits, list(bits), holdings, inputs))
    server = ModbusTcpServer([device], address=("127.0.0.1", port))
    await server.serve_forever(background=True)
    return server


class Gateway:
    """The daemon with one simulated drive and the Modbus front end."""

    def __init__(self, tmp: Path) -> None:
        self.port = free_port()
        cfg = tmp / "bench.toml"
        cfg.write_text(CONFIG.format(port=self.port, unit=UNIT))
        self.daemon = Daemon(load(cfg), notifier=Notifier({}))
        self.frontend = ModbusFrontEnd(self.daemon.runtime)

    async def __aenter__(self) -> Gateway:
        self._daemon_task = asyncio.create_task(self.daemon.run())
        self._fe_task = asyncio.create_task(self.frontend.run())
        await asyncio.wait_for(self.frontend.ready.wait(), 10)
        await asyncio.wait_for(self.daemon.hub.wait_for("d1", lambda s: s.online), 10)
        return self

    async def __aexit__(self, *exc: object) -> None:
        self._fe_task.cancel()
        await asyncio.gather(self._fe_task, return_exceptions=True)
        self.daemon.request_stop()
        await self._daemon_task


# ------------------------------------------------------------------ command latency


async def command_latency(gw: Gateway, commands: int = COMMANDS) -> tuple[list[float], list[float]]:
    """(write -> hub desired changed, write -> response), in ms, per command."""
    hub = gw.daemon.hub
    changed: list[float] = []
    hub.on_command(lambda drive_id: changed.append(time.perf_counter()))
    reader, writer = await asyncio.open_connection("127.0.0.1", gw.port)
    to_hub: list[float] = []
    round_trip: list[float] = []
    try:
        writer.write(frame(1, UNIT, b"\x06\x00\x00\x00\x00"))  # first word: run 0
        await reader.readexactly(12)
        for i in range(commands):
            word = 1 - (i % 2)  # 1, 0, 1, ...: every write is a run edge
            changed.clear()
            t0 = time.perf_counter()
            writer.write(frame(i + 2, UNIT, b"\x06\x00\x00" + word.to_bytes(2, "big")))
            reply = await reader.readexactly(12)
            t2 = time.perf_counter()
            if reply[7] != 6 or not changed or hub.desired("d1").run != bool(word):
                raise RuntimeError(f"command {i} not applied: {reply.hex()}")
            to_hub.append((changed[0] - t0) * 1000)
            round_trip.append((t2 - t0) * 1000)
    finally:
        writer.close()
        await writer.wait_closed()
    return to_hub, round_trip


def percentile(values: list[float], p: float) -> float:
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, round(p / 100 * (len(ordered) - 1))))
    return ordered[k]


# ------------------------------------------------------------------ run


async def _main(rounds: int, seconds: float, clients: int, commands: int) -> list[Figure]:
    with tempfile.TemporaryDirectory() as tmp:
        async with Gateway(Path(tmp)) as gw:
            registers = list(gw.frontend.drives["d1"].inputs)
            bare_port = free_port()
            bare = await bare_server(bare_port, registers)
            bare_rounds: list[Round] = []
            gw_rounds: list[Round] = []
            try:
                for _ in range(rounds):
                    bare_rounds.append(await measure_reads(bare_port, seconds, clients))
                    gw_rounds.append(await measure_reads(gw.port, seconds, clients))
            finally:
                await bare.shutdown()
            to_hub, round_trip = await command_latency(gw, commands)
    bare_rate = max(r.rate for r in bare_rounds)
    gw_rate = max(r.rate for r in gw_rounds)
    bare_cpu = min(r.cpu_us for r in bare_rounds)
    gw_cpu = min(r.cpu_us for r in gw_rounds)
    note = f"{clients} clients, FC4 x{INPUTS} registers, best of {rounds} x {seconds:g} s rounds"
    return [
        Figure(
            "modbus status reads/s (gateway vs bare pymodbus)",
            round(gw_rate, 1),
            "reads/s",
            reference=round(bare_rate, 1),
            target="ratio >= 0.8",
            note=f"{note}; reference: bare pymodbus SimDevice server, same registers, same run",
        ),
        Figure(
            "modbus server CPU per status read (gateway vs bare)",
            round(gw_cpu, 1),
            "us/read",
            reference=round(bare_cpu, 1),
            note="this process's CPU time per read, best round; steadier than reads/s on a "
            "busy machine (the ratio is the gateway's cost relative to bare pymodbus)",
        ),
        Figure(
            "modbus command latency p50 (write -> hub)",
            round(percentile(to_hub, 50), 4),
            "ms",
            note=f"FC6 holding 0 -> hub desired command changed, {commands} commands",
        ),
        Figure(
            "modbus command latency p99 (write -> hub)",
            round(percentile(to_hub, 99), 4),
            "ms",
            target="< 5 ms",
            note=f"FC6 holding 0 -> hub desired command changed, {commands} commands",
        ),
        Figure(
            "modbus command round trip p99",
            round(percentile(round_trip, 99), 4),
            "ms",
            note="FC6 write until its response is received (loopback)",
        ),
    ]


def run(
    rounds: int = ROUNDS,
    seconds: float = ROUND_S,
    clients: int = CLIENTS,
    commands: int = COMMANDS,
) -> list[Figure]:
    return asyncio.run(_main(rounds, seconds, clients, commands))


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_modbus", __doc__)
    add_number(parser, "--rounds", ROUNDS, "read rounds on each server (the best counts)")
    add_number(parser, "--round-seconds", ROUND_S, "seconds per read round")
    parser.add_argument(
        "--clients", type=positive_int, metavar="N", default=CLIENTS, help="concurrent readers"
    )
    add_number(parser, "--commands", COMMANDS, "FC6 commands for the latency")
    parser.add_argument(
        "--load",
        nargs=4,
        metavar=("PORT", "UNIT", "SECONDS", "CLIENTS"),
        help="be the load generator the benchmark starts in a child process, and only that",
    )
    args = parser.parse_args(argv)
    if args.load is not None:
        port, unit, seconds, clients = args.load
        result = asyncio.run(_load(int(port), int(unit), float(seconds), int(clients)))
        sys.stdout.write(json.dumps(result) + "\n")
        return 0
    print_figures(run(args.rounds, args.round_seconds, args.clients, args.commands))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
