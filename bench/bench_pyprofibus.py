"""Side by side with pyprofibus, the other Python DP master, on the same simulator and pty.

pyprofibus is GPL: it is never imported here nor a dependency of the project. The bench
makes a throwaway venv in a temporary directory, installs pyprofibus from PyPI into it
(:data:`PYPROFIBUS`, with pyserial, which it uses without declaring it) and runs a small master script of ours (:data:`PYPROFIBUS_MASTER`,
written into that directory; it drives pyprofibus through its public API) with that venv's
Python, as a separate process. If the venv or the install fails (no network, no PyPI), the
bench prints one JSON line saying it was skipped and why, and reports nothing else.

The simulator is ours, in its own process: ``drive-gateway sim profibus --port pty
--slaves 3-N:echo:8`` (echo slaves, 8 bytes in and out), one per slave count, used by every
master of that count in turn. Each master is a process of its own too (ours:
``python -m bench.bench_pyprofibus master ...``, the engine, the stream driver and the
serial link as the daemon runs them), pinned to one CPU, the simulator to another
(docs/decisions/0020-bench-cpu-placement.md). Rounds alternate the three masters:

- ``ours_timed``: drive-gateway keeping 500 kbit/s timing (TSYN and each telegram's line
  time before the next request: it caps the rate near 2,670 exchanges/s on a pty);
- ``ours_untimed``: drive-gateway with line timing off (a 12 Mbit/s setting);
- ``pyprofibus``: pyprofibus 1.13 at "500 kbit/s" (it keeps no line timing: it sends the
  next slave's request without waiting for the line to be idle, even while an earlier
  request is unanswered; its script counts how many of its requests went out so).

pyprofibus polls its port without sleeping (``pollData`` with timeout 0, ``run()`` called in a
loop), so it burns its CPU whatever the line does: its CPU per exchange is its CPU share
over its exchange rate, and it grows when the simulator is slow.

Each round: the master starts, brings its slaves to data exchange, exchanges
:data:`SETTLE` s, then :data:`MEASURE` s measured: exchanges (a Data_Exchange answered
with inputs) and the master process's CPU time (``time.process_time``) over that stretch.
A figure is the median of :data:`ROUNDS` rounds.

``python -m bench pyprofibus``, or alone: ``python -m bench.bench_pyprofibus [--slaves N ...]
[--rounds N] [--seconds S]`` (``master ...`` is our master process, which the bench starts
itself).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import select
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from bench.common import (
    Figure,
    add_counts,
    add_number,
    arg_parser,
    id_range,
    positive_float,
    print_figures,
)

PYPROFIBUS: Final = ("pyprofibus==1.13", "pyserial")  # it imports pyserial, undeclared
FIRST: Final = 3  # the first slave address (as bench_profibus)
SIZE: Final = 8  # bytes in and out per slave
ROUNDS: Final = 5
SETTLE: Final = 0.5  # s of exchange before a round is measured
MEASURE: Final = 2.0  # s measured per round
START_TIMEOUT: Final = 20.0  # s: a master or the simulator that takes longer has failed
INSTALL_TIMEOUT: Final = 300.0  # s for the venv and pip
SLAVE_COUNTS: Final = (1, 8)
MODES: Final = ("ours_untimed", "ours_timed", "pyprofibus")

# Our script for pyprofibus's venv: pyprofibus's public API (CpPhySerial, DPM1,
# DpSlaveDesc), run by that venv's Python; never imported by the project.
PYPROFIBUS_MASTER: Final = r'''
import json
import sys
import time
from collections import deque
from types import SimpleNamespace

from pyprofibus.dp import DpCfgDataElement
from pyprofibus.dp_master import DPM1, DpSlaveDesc
from pyprofibus.phy_serial import CpPhySerial

port, slaves, first, size, settle, measure = sys.argv[1:7]
slaves, first, size = int(slaves), int(first), int(size)
settle, measure = float(settle), float(measure)

sent = {"requests": 0, "overlapped": 0}
unanswered = deque()  # send times of requests not answered yet


class CountingPhy(CpPhySerial):
    """pyprofibus's serial PHY, counting requests sent while one is unanswered."""

    def sendData(self, telegramData, srd):
        now = time.monotonic()
        while unanswered and now - unanswered[0] > 0.1:  # pyprofibus's own request timeout
            unanswered.popleft()
        if srd:
            sent["requests"] += 1
            if unanswered:
                sent["overlapped"] += 1
            unanswered.append(now)
        return super().sendData(telegramData, srd)

    def pollData(self, timeout=0.0):
        got = super().pollData(timeout)
        if got and unanswered:
            unanswered.popleft()
        return got


phy = CountingPhy(port=port)
phy.setConfig(baudrate=500000)
master = DPM1(phy=phy, masterAddr=2)
gsd = SimpleNamespace(getIdentNumber=lambda: 0xEC00)
outputs = bytes(range(size))
for i in range(slaves):
    conf = SimpleNamespace(
        gsd=gsd, addr=first + i, name=f"echo{i}", index=i,
        inputSize=size, outputSize=size, diagPeriod=0,
    )
    desc = DpSlaveDesc(conf)
    desc.setCfgDataElements([DpCfgDataElement(0xB7)])  # 8 bytes in/out, consistent
    desc.setUserPrmData(b"\x00\x00\x00")  # DPV1_Status_1..3 (the echo slave is DP-V1)
    desc.setWatchdog(0)
    master.addSlave(desc)
master.initialize()
for desc in master.getSlaveList():
    desc.setMasterOutData(outputs)

exchanges = 0
started = time.monotonic()
phase = "start"
while True:
    desc = master.run()
    if desc is not None and desc.getMasterInData() is not None:
        exchanges += 1
        desc.setMasterOutData(outputs)
    now = time.monotonic()
    if phase == "start":
        if all(d.isConnected() for d in master.getSlaveList()):
            phase, until = "settle", now + settle
        elif now - started > 15:
            print(json.dumps({"error": "slaves not in data exchange after 15 s"}))
            sys.exit(1)
    elif phase == "settle" and now >= until:
        phase, until = "measure", now + measure
        first_exchanges, cpu0, wall0 = exchanges, time.process_time(), now
        first_sent = dict(sent)
    elif phase == "measure" and now >= until:
        break
cpu, wall, done = time.process_time() - cpu0, now - wall0, exchanges - first_exchanges
requests = sent["requests"] - first_sent["requests"]
overlapped = sent["overlapped"] - first_sent["overlapped"]
print(json.dumps({"exchanges": done, "seconds": wall, "cpu": cpu,
                  "requests": requests, "overlapped": overlapped}), flush=True)
'''


@dataclass(frozen=True)
class Round:
    exchanges: int
    seconds: float
    cpu: float  # s, the master process
    requests: int = 0
    overlapped: int = 0  # requests sent while an earlier one was unanswered

    @property
    def rate(self) -> float:
        return self.exchanges / self.seconds if self.seconds else 0.0

    @property
    def cpu_per_exchange(self) -> float:
        return self.cpu / self.exchanges if self.exchanges else float("nan")


class Skipped(Exception):
    """pyprofibus could not be installed: the comparison is skipped (the reason)."""


# ---------------------------------------------------------------------------------------
# pyprofibus in a throwaway venv


def install_pyprofibus(where: Path) -> Path:
    """A venv under ``where`` with pyprofibus installed from PyPI; its Python."""
    venv = where / "venv"
    steps = [
        [sys.executable, "-m", "venv", str(venv)],
        [str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", *PYPROFIBUS],
    ]
    for cmd in steps:
        try:
            done = subprocess.run(
                cmd, check=False, capture_output=True, text=True, timeout=INSTALL_TIMEOUT
            )
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise Skipped(f"{' '.join(cmd[-3:])}: {exc}") from None
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise Skipped(f"{' '.join(cmd[-3:])} failed ({done.returncode}): {last}")
    return venv / "bin" / "python"


# ---------------------------------------------------------------------------------------
# processes


def _cpus() -> tuple[set[int], set[int]] | None:
    cpus = sorted(os.sched_getaffinity(0))
    return ({cpus[0]}, {cpus[1]}) if len(cpus) >= 2 else None


def _pin(pid: int, cpus: set[int] | None) -> None:
    if cpus is not None:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(pid, cpus)


def _stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def _read_line(proc: subprocess.Popen[str], timeout: float) -> str:
    """The next line of ``proc``'s stdout within ``timeout`` s."""
    assert proc.stdout is not None
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ready, _, _ = select.select([proc.stdout], [], [], end - time.monotonic())
        if ready:
            line = proc.stdout.readline()
            if not line:
                break
            return line
    raise RuntimeError(f"no line from {proc.args!r} within {timeout:g} s (exit {proc.poll()})")


@contextlib.contextmanager
def simulator(slaves: int, cpus: set[int] | None) -> Iterator[str]:
    """``drive-gateway sim profibus`` on a new pty, its own process: the pty's path."""
    cmd = [
        sys.executable,
        "-c",
        "from gateway.cli import main; raise SystemExit(main())",
        "sim",
        "profibus",
        "--port",
        "pty",
        "--slaves",
        f"{FIRST}-{FIRST + slaves - 1}:echo:{SIZE}",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        _pin(proc.pid, cpus)
        line = _read_line(proc, START_TIMEOUT)  # "simulating N slave(s) on PATH: [...]"
        yield line.split(" on ", 1)[1].split(":", 1)[0].strip()
    finally:
        _stop(proc)


def run_master(cmd: list[str], cpus: set[int] | None, seconds: float = MEASURE) -> Round:
    """One round of a master process (``seconds`` measured); it prints one JSON line with
    its figures."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _pin(proc.pid, cpus)
        end = time.monotonic() + START_TIMEOUT + SETTLE + seconds
        line = ""
        while not line.startswith("{"):  # pyprofibus prints its warnings to stdout
            line = _read_line(proc, max(0.0, end - time.monotonic()))
    finally:
        _stop(proc)
    result = json.loads(line)
    if "error" in result:
        raise RuntimeError(f"{cmd[0]}: {result['error']}")
    return Round(**result)


def _ours(port: str, slaves: int, timed: bool, seconds: float = MEASURE) -> list[str]:
    return [
        sys.executable,
        "-m",
        "bench.bench_pyprofibus",
        "master",
        port,
        str(slaves),
        "--timed" if timed else "--untimed",
        "--seconds",
        repr(seconds),
    ]


def _theirs(
    python: Path, script: Path, port: str, slaves: int, seconds: float = MEASURE
) -> list[str]:
    args = (port, slaves, FIRST, SIZE, SETTLE, seconds)
    return [str(python), str(script), *map(str, args)]


# ---------------------------------------------------------------------------------------
# our master, as its own process


async def our_round(port: str, slaves: int, timed: bool, seconds: float | None = None) -> Round:
    """One round of our master, ``seconds`` measured (:data:`MEASURE` when None)."""
    from bench import bench_profibus as ours

    bus = ours.TIMED_BUS if timed else ours.BUS
    seconds = MEASURE if seconds is None else seconds
    run = await ours.run_master(port, slaves, seconds, bus, settle=SETTLE)
    return Round(run.exchanges, run.seconds, run.cpu)


def _master(args: argparse.Namespace) -> int:
    r = asyncio.run(our_round(args.port, args.slaves, args.timed, args.seconds))
    print(json.dumps({"exchanges": r.exchanges, "seconds": r.seconds, "cpu": r.cpu}), flush=True)
    return 0


# ---------------------------------------------------------------------------------------
# figures


def compare(
    python: Path, script: Path, slaves: int, count: int = ROUNDS, seconds: float = MEASURE
) -> dict[str, list[Round]]:
    """``count`` rounds of every master, ``seconds`` measured each."""
    placement = _cpus()
    master_cpus, sim_cpus = placement if placement is not None else (None, None)
    rounds: dict[str, list[Round]] = {mode: [] for mode in MODES}
    with simulator(slaves, sim_cpus) as port:
        for _ in range(count):
            for mode in MODES:
                if mode == "pyprofibus":
                    cmd = _theirs(python, script, port, slaves, seconds)
                else:
                    cmd = _ours(port, slaves, mode == "ours_timed", seconds)
                rounds[mode].append(run_master(cmd, master_cpus, seconds))
    return rounds


def _figures(slaves: int, rounds: dict[str, list[Round]], seconds: float = MEASURE) -> list[Figure]:
    median = statistics.median
    rate = {m: median(r.rate for r in rs) for m, rs in rounds.items()}
    cpu = {m: _median_cpu(rs) * 1e6 for m, rs in rounds.items()}
    empty = {m: sum(1 for r in rs if not r.exchanges) for m, rs in rounds.items()}
    theirs = rounds["pyprofibus"]
    requests = sum(r.requests for r in theirs)
    overlapped = sum(r.overlapped for r in theirs)
    cond = (
        f"{slaves} echo slave(s), 8 bytes I/O, drive-gateway's simulator in its own process on "
        f"a pty; each master its own process on one CPU; median of "
        f"{len(rounds['pyprofibus'])} rounds of {seconds:g} s"
    )
    if any(empty.values()):
        cond += f"; rounds without an exchange (left out of the CPU medians): {empty}"
    timing = {
        "ours_untimed": "line timing off (12 Mbit/s setting)",
        "ours_timed": "500 kbit/s line timing kept (TSYN, line time: slept in the step "
        "under 100 us, else on a timerfd)",
    }
    figures: list[Figure] = []
    for mode in ("ours_untimed", "ours_timed"):
        figures.append(
            Figure(
                f"pyprofibus_cmp_{mode}_exchanges_per_s_{slaves}_slaves",
                rate[mode],
                "1/s",
                reference=rate["pyprofibus"],
                target="ratio >= 1" if mode == "ours_untimed" else None,
                note=f"drive-gateway, {timing[mode]}; reference: pyprofibus 1.13 (no line "
                f"timing); {cond}",
            )
        )
        figures.append(
            Figure(
                f"pyprofibus_cmp_{mode}_cpu_per_exchange_{slaves}_slaves",
                cpu[mode],
                "us",
                reference=cpu["pyprofibus"],
                target="ratio < 1",
                note=f"master process CPU time per exchange, drive-gateway {timing[mode]}; "
                f"reference: pyprofibus; {cond}",
            )
        )
    figures.append(
        Figure(
            f"pyprofibus_cmp_pyprofibus_exchanges_per_s_{slaves}_slaves",
            rate["pyprofibus"],
            "1/s",
            note=f"pyprofibus 1.13, its CPU per exchange {cpu['pyprofibus']:.1f} us; {cond}",
        )
    )
    figures.append(
        Figure(
            f"pyprofibus_cmp_pyprofibus_overlapped_requests_{slaves}_slaves",
            overlapped / requests if requests else float("nan"),
            "ratio",
            note=f"share of pyprofibus's requests ({requests} in the measured stretches) sent "
            "while an earlier one was still unanswered (its 0.1 s timeout not over): on a "
            "half-duplex bus they would collide. drive-gateway sends none so",
        )
    )
    return figures


def _median_cpu(rounds: list[Round]) -> float:
    """The median CPU per exchange of the rounds that exchanged (NaN: none did)."""
    values = [r.cpu_per_exchange for r in rounds if r.exchanges]
    return statistics.median(values) if values else float("nan")


def run(
    slave_counts: tuple[int, ...] = SLAVE_COUNTS, rounds: int = ROUNDS, seconds: float = MEASURE
) -> list[Figure]:
    where = Path(tempfile.mkdtemp(prefix="drive-gateway-pyprofibus-"))
    try:
        try:
            python = install_pyprofibus(where)
        except Skipped as exc:
            skipped = {"name": "pyprofibus_comparison", "skipped": True, "why": str(exc)}
            print(json.dumps(skipped), flush=True)
            return []
        script = where / "pyprofibus_master.py"
        script.write_text(PYPROFIBUS_MASTER)
        figures: list[Figure] = []
        for slaves in slave_counts:
            figures += _figures(slaves, compare(python, script, slaves, rounds, seconds), seconds)
        return figures
    finally:
        shutil.rmtree(where, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    slave_count = id_range(1, 126 - FIRST, f"slave counts (addresses {FIRST}..{FIRST}+N-1)")
    parser = arg_parser("bench_pyprofibus", __doc__)
    add_counts(
        parser, "--slaves", slave_count, SLAVE_COUNTS, "echo slaves, one comparison per count"
    )
    add_number(parser, "--rounds", ROUNDS, "rounds of each master (the median counts)")
    add_number(parser, "--seconds", MEASURE, "seconds measured per round")
    sub = parser.add_subparsers(dest="command", title="the bench's own child process")
    what = "our master for one round on PORT, its figures as one JSON line (the bench starts it)"
    master = sub.add_parser("master", help=what, description=what)
    master.add_argument("port", help="the simulator's pty")
    master.add_argument("slaves", type=slave_count, help=f"echo slaves at {FIRST}..{FIRST}+N-1")
    master.add_argument("--timed", action="store_true", help="500 kbit/s line timing kept")
    master.add_argument("--untimed", dest="timed", action="store_false", help="timing off")
    master.add_argument(
        "--seconds", type=positive_float, metavar="S", default=MEASURE, help="seconds measured"
    )
    args = parser.parse_args(argv)
    if args.command == "master":
        return _master(args)
    print_figures(run(tuple(args.slaves), args.rounds, args.seconds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
