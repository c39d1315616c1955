"""CPU per steady Profibus exchange: the gateway's whole line against a bare requester.

The gateway's side is its Profibus line as the daemon runs it: the adapter with its CFW700
profiles on a :class:`~gateway.runtime.linethread.LineThread` (a thread and event loop of
its own), its :class:`~gateway.runtime.lineport.LinePort` to a hub built from the config,
the hub on this process's loop. The slaves are the plant bench's paced line
(:mod:`bench.plant.pbsim`: the config's device simulators in a child process on a pty,
each reply held until its last byte would leave a real slave at the line's baud rate).

The reference, in the same run and against the same child: a bare requester (a blocking
``write``/``read`` loop, nothing decoded) sending the very telegrams the gateway sent in
its measured stretch (captured from its serial link) in the same order, each once its
reply is in. Rounds alternate, gateway then bare; each side's figure is the median.

Figures: CPU per exchange of the line's thread, and of the whole process (line, hub,
hand-over), against the bare requester's CPU per exchange (target: ratio <= 2, issue 34).

The steady exchanges go round in steady rings (docs/decisions/0103), compiled where
``adapters/link/_ring.c`` is built; ``DRIVE_GATEWAY_RING=python`` measures the rings in
Python, ``DRIVE_GATEWAY_RING=off`` the line without rings (each exchange through the
engine, in bursts). For comparisons: ``BENCH_NO_BURST=1`` measures the line without its bursts of steady
exchanges (docs/decisions/0101); ``BENCH_LINE_PROFILE=FILE`` writes a CPU-time profile of
the line's thread over the measured stretch (:mod:`bench.linecpu`).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import tty
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from adapters.link.ring import ring_mode
from bench.common import Figure, add_number, arg_parser, print_figures
from bench.linecpu import line_profile, thread_cpu, thread_system

SLAVES: Final = 8
BAUD: Final = 1_500_000
WORDS: Final = 4
ROUNDS: Final = 3
MEASURE: Final = 3.0  # s per round and side
SETTLE: Final = 1.0  # s of data exchange before a gateway round is measured
ONLINE_BOUND: Final = 30.0  # s for every drive to come online
TARGET: Final = "ratio <= 2"
PY: Final = sys.executable


def config_text(link: Path) -> str:
    lines = [
        "[gateway]",
        'name = "exchange"',
        'log_level = "WARNING"',
        "[buses.profibus]",
        'adapter = "profibus"',
        f'port = "{link}"',
        f"baudrate = {BAUD}",
        "master_address = 0",
        "cycle_time = 0.0",
        "watchdog = 2",
        "latency = 0.05",
        "live_list_period = 0.0",
    ]
    for address in range(1, SLAVES + 1):
        lines += [
            "[[buses.profibus.drives]]",
            f'id = "pb{address}"',
            'device = "CFW700"',
            f"address = {address}",
            f"modbus_unit = {address}",
            'data_profile = "manufacturer"',
            f"words = {WORDS}",
        ]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Side:
    exchanges: int
    thread_cpu: float  # s
    process_cpu: float  # s
    system_cpu: float = math.nan  # s of the thread's CPU in the kernel

    def per_exchange(self, cpu: float) -> float:
        return cpu / self.exchanges if self.exchanges else float("nan")


class Capture:
    """The requests the gateway writes while measuring (SerialLink.write wrapped)."""

    def __init__(self) -> None:
        self.on = False
        self.frames: list[bytes] = []

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        from adapters.link.serial import SerialLink

        original = SerialLink.write

        def write(link: Any, data: bytes) -> None:
            if self.on and len(self.frames) < 200_000:
                self.frames.append(bytes(data))
            original(link, data)

        SerialLink.write = write  # type: ignore[method-assign,assignment]
        try:
            yield
        finally:
            SerialLink.write = original  # type: ignore[method-assign]


def _asks_reply(frame: bytes) -> bool:
    """A Data_Exchange request (SD2 or SD3, no SAPs), not a Global_Control broadcast."""
    da = {0x68: 4, 0xA2: 1}.get(frame[0]) if frame else None
    return da is not None and len(frame) > da and not frame[da] & 0x80 and frame[da] != 127


async def gateway_round(config_path: Path, capture: Capture, seconds: float) -> Side:
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
        master = adapter.master  # type: ignore[attr-defined]

        def exchanged() -> int:
            return sum(master.slave_figures(a).exchanges for a in master.addresses)

        if os.environ.get("BENCH_NO_BURST"):
            adapter._driver._bursts = False  # type: ignore[attr-defined]
        capture.frames.clear()
        capture.on = True
        tid = line.thread.native_id if line.thread is not None else None
        async with line_profile(line):
            first, t0, p0 = exchanged(), thread_cpu(line.thread), time.process_time()
            s0 = thread_system(tid)
            await asyncio.sleep(seconds)
            done, t1, p1 = exchanged(), thread_cpu(line.thread), time.process_time()
            s1 = thread_system(tid)
        capture.on = False
        return Side(done - first, t1 - t0, p1 - p0, s1 - s0)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def _read_reply(fd: int, deadline: float) -> bool:
    """One reply off the pty: SD2 by its length byte, SC (E5) or SD1 (6 bytes)."""
    buf = b""
    while time.monotonic() < deadline:
        try:
            buf += os.read(fd, 512)
        except BlockingIOError:
            import select

            select.select([fd], [], [], 0.05)
            continue
        if buf[:1] == b"\xe5":
            return True
        if buf[:1] == b"\x10" and len(buf) >= 6:
            return True
        if buf[:1] == b"\xa2" and len(buf) >= 14:
            return True
        if buf[:1] == b"\x68" and len(buf) >= 4 and len(buf) >= buf[1] + 6:
            return True
    return False


def bare_round(link: Path, frames: list[bytes], seconds: float) -> Side:
    if not frames:
        raise RuntimeError("no Data_Exchange request captured from the gateway")
    fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    try:
        done = 0
        t0, p0 = time.thread_time(), time.process_time()
        s0 = thread_system(threading.get_native_id())
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for frame in frames:
                os.write(fd, frame)
                if not _read_reply(fd, time.monotonic() + 1.0):
                    break
                done += 1
        system = thread_system(threading.get_native_id()) - s0
        return Side(done, time.thread_time() - t0, time.process_time() - p0, system)
    finally:
        os.close(fd)


async def loop_bare_round(link: Path, frames: list[bytes], seconds: float) -> Side:
    """The bare requester on an event loop (``add_reader``): the floor of any asyncio line."""
    loop = asyncio.get_running_loop()
    fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    done = 0
    buf = b""
    i = 0
    finished: asyncio.Future[None] = loop.create_future()
    end = time.monotonic() + seconds

    def readable() -> None:
        nonlocal buf, done, i
        try:
            buf += os.read(fd, 512)
        except BlockingIOError:
            return
        if buf[:1] == b"\x68" and len(buf) >= 4 and len(buf) < buf[1] + 6:
            return
        if buf[:1] == b"\xa2" and len(buf) < 14:
            return
        buf = b""
        done += 1
        if time.monotonic() >= end:
            if not finished.done():
                finished.set_result(None)
            return
        i = (i + 1) % len(frames)
        os.write(fd, frames[i])

    t0, p0 = time.thread_time(), time.process_time()
    loop.add_reader(fd, readable)
    try:
        os.write(fd, frames[0])
        await asyncio.wait_for(finished, seconds + 5)
        return Side(done, time.thread_time() - t0, time.process_time() - p0)
    finally:
        loop.remove_reader(fd)
        os.close(fd)


def _start_slaves(tmp: Path, config: Path, link: Path) -> subprocess.Popen[bytes]:
    child = subprocess.Popen(
        [
            *(PY, "-m", "bench.plant.pbsim", "--config", str(config), "--baud", str(BAUD)),
            *("--link", str(link), "--out", str(tmp / "pbsim.json")),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    end = time.monotonic() + 20
    while not link.exists():
        if child.poll() is not None or time.monotonic() > end:
            raise RuntimeError("the simulated Profibus line did not start")
        time.sleep(0.05)
    return child


def measure(rounds: int, seconds: float) -> tuple[list[Side], list[Side], list[Side]]:
    gateway: list[Side] = []
    bare: list[Side] = []
    loop_bare: list[Side] = []
    capture = Capture()
    with tempfile.TemporaryDirectory(prefix="bench-exchange-") as name:
        tmp = Path(name)
        link = tmp / "profibus.tty"
        config = tmp / "exchange.toml"
        config.write_text(config_text(link))
        child = _start_slaves(tmp, config, link)
        try:
            with capture.installed():
                for _ in range(rounds):
                    gateway.append(asyncio.run(gateway_round(config, capture, seconds)))
                    frames = [f for f in capture.frames if _asks_reply(f)]
                    bare.append(bare_round(link, frames, seconds))
                    loop_bare.append(asyncio.run(loop_bare_round(link, frames, seconds)))
        finally:
            child.send_signal(signal.SIGTERM)
            try:
                child.wait(10)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
    return gateway, bare, loop_bare


def run(rounds: int = ROUNDS, seconds: float = MEASURE) -> list[Figure]:
    gateway, bare, loop_bare = measure(rounds, seconds)
    med = statistics.median
    bare_cpu = med(s.per_exchange(s.thread_cpu) for s in bare) * 1e6
    line_cpu = med(s.per_exchange(s.thread_cpu) for s in gateway) * 1e6
    whole_cpu = med(s.per_exchange(s.process_cpu) for s in gateway) * 1e6
    loop_cpu = med(s.per_exchange(s.thread_cpu) for s in loop_bare) * 1e6
    line_sys = med(s.per_exchange(s.system_cpu) for s in gateway) * 1e6
    bare_sys = med(s.per_exchange(s.system_cpu) for s in bare) * 1e6
    rate = med(s.exchanges for s in gateway) / seconds
    bare_rate = med(s.exchanges for s in bare) / seconds
    note = (
        f"{SLAVES} CFW700 at {BAUD} bit/s, paced slaves in a child; {rounds} rounds of"
        f" {seconds:g} s; steady rings: {ring_mode()}"
    )
    return [
        Figure(
            "profibus_line_cpu_per_exchange",
            round(line_cpu, 2),
            "us",
            reference=round(bare_cpu, 2),
            target=TARGET,
            note="the line's thread; reference: a bare requester, same telegrams, same slaves; "
            + note,
        ),
        Figure(
            "profibus_gateway_cpu_per_exchange",
            round(whole_cpu, 2),
            "us",
            reference=round(bare_cpu, 2),
            target=TARGET,
            note="the whole process (line, hand-over, hub); " + note,
        ),
        Figure(
            "profibus_loop_bare_cpu_per_exchange",
            round(loop_cpu, 2),
            "us",
            reference=round(bare_cpu, 2),
            note="a bare requester on an event loop (add_reader), the floor of an asyncio line; "
            + note,
        ),
        Figure(
            "profibus_line_system_cpu_per_exchange",
            round(line_sys, 2),
            "us",
            reference=round(bare_sys, 2),
            note="of the line's thread, the part in the kernel (stime, 10 ms ticks); reference: "
            "the bare requester's; " + note,
        ),
        Figure("profibus_line_exchange_rate", round(rate, 1), "1/s", reference=round(bare_rate, 1)),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_exchange", __doc__)
    add_number(parser, "--seconds", MEASURE, "seconds measured per round and side")
    add_number(parser, "--rounds", ROUNDS, "rounds of each side")
    args = parser.parse_args(argv)
    print_figures(run(args.rounds, args.seconds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
