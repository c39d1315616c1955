"""What the OPC UA server costs the daemon's loop when every drive's readings change.

In this process: a hub of :data:`DRIVES` drives online, a quarter of which
(:data:`CHANGING`) change speed and current every :data:`CHANGE_PERIOD` s (motors on the
move; the others steady), made on the loop like the lines' hand-over makes them; run
twice, for :data:`WINDOW` s each:

- the reference: the hub and its changes alone;
- with the OPC UA front end (gateway/opcua) serving them and :data:`SESSIONS` asyncua
  sessions (:data:`CLIENT_PROCESSES` processes of their own,
  :mod:`bench.plant.opcua_clients`) subscribed at
  100 ms to four variables of every drive.

Figures (``bench_opcua``): this process's CPU share in each run, their difference (the
server's cost under change), the front end's own batch time per second, the notifications
the sessions received, and the loop's lateness (the 99th percentile of how late the change
ticks ran): what a line's hand-over would see of a busy loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from typing import Any, Final

from bench.common import Figure
from gateway.config import Config
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState, DriveStatus
from gateway.opcua.frontend import OpcuaFrontEnd
from gateway.opcuaconfig import OpcuaSection
from gateway.runtime.daemon import Runtime
from tests.support.net import free_port

DRIVES: Final = 220
SESSIONS: Final = 10
CLIENT_PROCESSES: Final = (
    5  # the sessions split over these (an asyncua client process keeps up with 2-3)
)
CHANGING: Final = 0.25  # the share of the drives whose readings change every period
CHANGE_PERIOD: Final = 0.1  # s
WINDOW: Final = 10.0  # s
SETTLE: Final = 8.0  # s for the sessions to subscribe before the window


def _hub() -> Hub:
    hub = Hub()
    for i in range(DRIVES):
        hub.add_drive(DriveState(id=f"d{i}", device=Device.TEST, bus="bench", address=i % 125 + 1))
        hub.update(f"d{i}", comm=CommState.ONLINE, status=DriveStatus.RUNNING, running=True)
    return hub


async def _changes(hub: Hub, until: float, late: list[float]) -> None:
    loop = asyncio.get_running_loop()
    tick = 0
    next_at = loop.time()
    moving = range(0, DRIVES, round(1 / CHANGING))
    while loop.time() < until:
        tick += 1
        for i in moving:
            wave = math.sin(tick / 10 + i)
            hub.update(f"d{i}", speed_rpm=round(900 + 100 * wave, 1), current_a=round(5 + wave, 2))
        next_at += CHANGE_PERIOD
        await asyncio.sleep(max(0.0, next_at - loop.time()))
        late.append(max(0.0, loop.time() - next_at))


async def _run(with_opcua: bool) -> dict[str, Any]:
    hub = _hub()
    port = free_port()
    section = OpcuaSection(enabled=True, port=port, publish_interval=CHANGE_PERIOD)
    runtime = Runtime(config=replace(Config(file="bench"), opcua=section), hub=hub)
    front_end = OpcuaFrontEnd(runtime) if with_opcua else None
    task = asyncio.create_task(front_end.run()) if front_end else None
    clients: list[subprocess.Popen[bytes]] = []
    try:
        if front_end is not None:
            await asyncio.wait_for(front_end.ready.wait(), 120)
            clients = [_clients(section.endpoint) for _ in range(CLIENT_PROCESSES)]
        loop = asyncio.get_running_loop()
        late: list[float] = []
        changer = asyncio.create_task(_changes(hub, loop.time() + SETTLE + WINDOW + 1, late))
        await asyncio.sleep(SETTLE)
        busy0 = front_end.busy if front_end else 0.0
        t0, cpu0, n0 = time.monotonic(), time.process_time(), len(late)
        await asyncio.sleep(WINDOW)
        t1, cpu1 = time.monotonic(), time.process_time()
        busy = (front_end.busy - busy0) if front_end else 0.0
        window_late = late[n0:]
        await changer
        out: dict[str, Any] = {
            "cpu_share": (cpu1 - cpu0) / (t1 - t0),
            "batch_share": busy / (t1 - t0),
            "late_p99": statistics.quantiles(window_late, n=100)[98]
            if len(window_late) > 2
            else 0.0,
        }
        seen = []
        for proc in clients:
            stdout, _ = await asyncio.to_thread(proc.communicate, timeout=60)
            lines = stdout.decode().strip().splitlines()
            seen.append(json.loads(lines[-1]) if lines else {})
        if clients:
            out["clients"] = {
                "notifications_per_s": sum(c.get("notifications_per_s", 0.0) for c in seen),
                "sessions": sum(c.get("up_before_window", 0) for c in seen),
            }
        return out
    finally:
        for proc in clients:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


def _clients(endpoint: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [
            *(sys.executable, "-m", "bench.plant.opcua_clients", "--endpoint", endpoint),
            *("--sessions", str(SESSIONS // CLIENT_PROCESSES)),
            *("--interval", str(CHANGE_PERIOD), "--settle", str(SETTLE)),
            *("--seconds", str(WINDOW)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )


def measure() -> list[Figure]:
    ref = asyncio.run(_run(False))
    run = asyncio.run(_run(True))
    clients = run.get("clients", {})
    changing = len(range(0, DRIVES, round(1 / CHANGING)))
    note = (
        f"{DRIVES} drives, {changing} changing every {CHANGE_PERIOD:g} s, "
        f"{clients.get('sessions')} of {SESSIONS} sessions subscribed at 100 ms"
    )
    return [
        Figure(
            "opcua_changes_cpu_share",
            round(run["cpu_share"], 3),
            "core",
            reference=round(ref["cpu_share"], 3),
            note=f"{note}; reference: the hub and its changes without OPC UA",
        ),
        Figure(
            "opcua_changes_server_cpu_share",
            round(run["cpu_share"] - ref["cpu_share"], 3),
            "core",
            note=f"{note}; with minus without",
        ),
        Figure(
            "opcua_changes_batch_share",
            round(run["batch_share"], 4),
            "core",
            note="the front end's own batches (writing changed values, alarms)",
        ),
        Figure(
            "opcua_changes_notifications",
            round(clients.get("notifications_per_s", math.nan), 1),
            "1/s",
            reference=SESSIONS * changing * 2 / CHANGE_PERIOD,
            target="ratio >= 0.9",
            note="data changes the sessions received; reference: two changing items per "
            "drive per session per change period",
        ),
        Figure(
            "opcua_changes_loop_late_p99",
            round(run["late_p99"] * 1e3, 2),
            "ms",
            reference=round(ref["late_p99"] * 1e3, 2),
            note="p99 of how late the change ticks ran on the loop; reference: without OPC UA",
        ),
    ]


if __name__ == "__main__":
    for figure in measure():
        print(figure.line(), flush=True)
