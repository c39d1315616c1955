"""The status page under load: 20 WebSocket clients on the demo daemon (issue 23).

The demo daemon (config/demo.toml, every device simulated) runs in a process of its own,
its Zenoh, Modbus and web ports moved to free loopback ports. Two drives run all the
time, their speed reference changed over Modbus every :data:`STEP` seconds, so states,
trends and events keep flowing in every window.

Windows alternate: without web clients (the reference) and with :data:`CLIENTS` WebSocket
clients connected to ``/ws``, each reading every message as a page would. A window lasts
:data:`WINDOW` seconds; :data:`ROUNDS` of each, so the clients are connected for a minute
in all. Per window, from ``/api/buses`` at its start and end: the Profibus line's and the
DeviceNet line's cycles per second, and the Profibus median cycle time (the master's own
median of its last 256 cycles); from /proc: the daemon's CPU time. A side's figure is the
median of its windows. The issue's target: the cycle figures unchanged within noise
(ratio to the reference of the same run), and the daemon's CPU cost per client.

Everything runs on 127.0.0.1 and ends by itself (bounded windows, a bounded start and stop).

``python -m bench web``, or alone: ``python -m bench.bench_web [--clients N] [--window S]
[--rounds N]``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import aiohttp
from prometheus_client.parser import text_string_to_metric_families
from pymodbus.client import AsyncModbusTcpClient

from bench.common import Figure, add_number, arg_parser, print_figures

CLIENTS = 20
WINDOW = 20.0  # s per window
ROUNDS = 3  # windows with clients (and as many without): a minute with clients
SETTLE = 1.0  # s after the clients connect before a window starts
STEP = 2.0  # s between speed reference changes of the running drives
START_BOUND = 60.0  # s the daemon may take to have every drive online
STOP_BOUND = 20.0
ROOT = Path(__file__).resolve().parents[1]
RUNNING = {1: (600, 1200), 5: (300, 900)}  # Modbus unit -> the two references it alternates
TICK = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # utime, stime


@dataclass
class Window:
    profibus_cps: float
    devicenet_cps: float
    profibus_median_ms: float
    cpu_pct: float
    messages_per_client_s: float = 0.0


class Demo:
    def __init__(self) -> None:
        self.web = free_port()
        self.modbus = free_port()
        self.zenoh = free_port()
        self.url = f"http://127.0.0.1:{self.web}/"
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        command = [
            sys.executable,
            "-m",
            "gateway",
            "run",
            "--config",
            str(ROOT / "config" / "demo.toml"),
            "--zenoh-endpoint",
            f"tcp/127.0.0.1:{self.zenoh}",
            "--modbus-bind",
            f"127.0.0.1:{self.modbus}",
            "--web-bind",
            f"127.0.0.1:{self.web}",
            "--log-level",
            "WARNING",
        ]
        self.process = subprocess.Popen(command, cwd=ROOT)

    def stop(self) -> None:
        process = self.process
        if process is None:
            return
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(STOP_BOUND)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()

    @property
    def pid(self) -> int:
        assert self.process is not None
        return self.process.pid


async def get_json(http: aiohttp.ClientSession, url: str) -> Any:
    async with http.get(url) as r:
        r.raise_for_status()
        return await r.json()


async def wait_online(http: aiohttp.ClientSession, demo: Demo) -> None:
    deadline = time.monotonic() + START_BOUND
    while time.monotonic() < deadline:
        with contextlib.suppress(aiohttp.ClientError, OSError):
            health = await get_json(http, f"{demo.url}api/health")
            # every drive of the demo (7 since its CANopen line), however many it has
            if health["drives"] > 0 and health["online"] == health["drives"]:
                return
        await asyncio.sleep(0.5)
    raise RuntimeError("the demo daemon did not bring its drives online")


async def drive_load(port: int, stop: asyncio.Event) -> None:
    """Two drives running, their reference changed every STEP s (the same in every window)."""
    client = AsyncModbusTcpClient("127.0.0.1", port=port, retries=0, timeout=5)
    await client.connect()
    try:
        for unit in RUNNING:
            await client.write_register(0, 0, device_id=unit)
            await client.write_register(1, RUNNING[unit][0], device_id=unit)
            await client.write_register(0, 1, device_id=unit)
        i = 0
        while not stop.is_set():
            i += 1
            for unit, refs in RUNNING.items():
                await client.write_register(1, refs[i % 2], device_id=unit)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), STEP)
    finally:
        client.close()


async def bus_counts(http: aiohttp.ClientSession, demo: Demo) -> dict[str, dict[str, float]]:
    buses = await get_json(http, f"{demo.url}api/buses")
    return {b["name"]: b["figures"] for b in buses["buses"]}


async def measure(http: aiohttp.ClientSession, demo: Demo, window: float = WINDOW) -> Window:
    before = await bus_counts(http, demo)
    cpu0, t0 = cpu_seconds(demo.pid), time.monotonic()
    await asyncio.sleep(window)
    after = await bus_counts(http, demo)
    cpu1, t1 = cpu_seconds(demo.pid), time.monotonic()
    span = t1 - t0

    def rate(bus: str) -> float:
        return (after[bus]["cycles"] - before[bus]["cycles"]) / span

    return Window(
        profibus_cps=rate("profibus"),
        devicenet_cps=rate("devicenet"),
        profibus_median_ms=after["profibus"]["cycle_median_ms"],
        cpu_pct=100.0 * (cpu1 - cpu0) / span,
    )


async def page(http: aiohttp.ClientSession, demo: Demo, counts: list[int], i: int) -> None:
    async with http.ws_connect(f"{demo.url}ws") as ws:
        async for msg in ws:
            if msg.type is aiohttp.WSMsgType.TEXT:
                counts[i] += 1
            else:
                break


async def with_clients(
    http: aiohttp.ClientSession, demo: Demo, clients: int = CLIENTS, seconds: float = WINDOW
) -> Window:
    counts = [0] * clients
    tasks = [asyncio.create_task(page(http, demo, counts, i)) for i in range(clients)]
    try:
        await asyncio.sleep(SETTLE)
        start = list(counts)
        window = await measure(http, demo, seconds)
        got = [c - s for c, s in zip(counts, start, strict=True)]
        window.messages_per_client_s = statistics.mean(got) / seconds
        return window
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def dropped(http: aiohttp.ClientSession, demo: Demo) -> float:
    async with http.get(f"{demo.url}metrics") as r:
        text = await r.text()
    for family in text_string_to_metric_families(text):
        if family.name == "drive_gateway_web_messages_dropped":
            return float(family.samples[0].value)
    return float("nan")


def _median(windows: list[Window], name: str) -> float:
    values: list[float] = [getattr(w, name) for w in windows]
    return statistics.median(values)


async def _run(clients: int, seconds: float, rounds: int) -> list[Figure]:
    demo = Demo()
    demo.start()
    stop = asyncio.Event()
    try:
        async with aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=30)) as http:
            await wait_online(http, demo)
            load = asyncio.create_task(drive_load(demo.modbus, stop))
            await asyncio.sleep(SETTLE)
            without: list[Window] = []
            with_: list[Window] = []
            for _ in range(rounds):
                without.append(await measure(http, demo, seconds))
                with_.append(await with_clients(http, demo, clients, seconds))
            lost = await dropped(http, demo)
            stop.set()
            await load
    finally:
        demo.stop()
    note = f"{clients} WebSocket clients, {rounds} windows of {seconds:g} s each side, medians"
    cpu_with, cpu_without = _median(with_, "cpu_pct"), _median(without, "cpu_pct")
    spread = max(w.cpu_pct for w in without) - min(w.cpu_pct for w in without)
    return [
        Figure(
            "web_profibus_cycles_per_s",
            _median(with_, "profibus_cps"),
            "cycles/s",
            _median(without, "profibus_cps"),
            "ratio >= 0.9 (unchanged within noise)",
            note,
        ),
        Figure(
            "web_devicenet_cycles_per_s",
            _median(with_, "devicenet_cps"),
            "cycles/s",
            _median(without, "devicenet_cps"),
            "ratio >= 0.9 (unchanged within noise)",
            note,
        ),
        Figure(
            "web_profibus_cycle_median_ms",
            _median(with_, "profibus_median_ms"),
            "ms",
            _median(without, "profibus_median_ms"),
            "ratio <= 1.1 (unchanged within noise)",
            note,
        ),
        Figure("web_daemon_cpu_pct", cpu_with, "% of a core", cpu_without, None, note),
        Figure(
            "web_daemon_cpu_pct_per_client",
            (cpu_with - cpu_without) / clients,
            "% of a core",
            None,
            None,
            "daemon CPU with the clients minus without, per client (see the noise figure)",
        ),
        Figure(
            "web_daemon_cpu_noise_pct",
            spread,
            "% of a core",
            None,
            None,
            "spread of the daemon's CPU between windows without clients: the noise band",
        ),
        Figure(
            "web_messages_per_client_per_s",
            _median(with_, "messages_per_client_s"),
            "msg/s",
            None,
            "<= 4 (PUSH_PERIOD 0.25 s)",
            note,
        ),
        Figure("web_messages_dropped", lost, "messages", None, "0 (no client fell behind)"),
    ]


def run(clients: int = CLIENTS, seconds: float = WINDOW, rounds: int = ROUNDS) -> list[Figure]:
    return asyncio.run(_run(clients, seconds, rounds))


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_web", __doc__)
    add_number(parser, "--clients", CLIENTS, "WebSocket clients")
    add_number(parser, "--window", WINDOW, "seconds per window")
    add_number(parser, "--rounds", ROUNDS, "windows with the clients (and as many without)")
    args = parser.parse_args(argv)
    print_figures(run(args.clients, args.window, args.rounds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
