"""What a pty between two processes allows a master, whatever its code: the floor under
every Profibus figure measured on a pty.

Two processes on one pty pair, each doing nothing but the line: a bare echo (the slave
side: read a telegram's bytes, write as many back at once) and a bare requester (write a
telegram, block until its reply has come, write the next). No protocol, no decoding, no
event loop, no timing: blocking ``os.read``/``os.write`` only. Its round trip is the least
time a master on this pty can need per exchange, and the CPU it takes per exchange the
least a master on it can burn in system calls and wake-ups.

Figures:

- ``pty_round_trip_p50_us`` / ``_p99_us``: one exchange (telegrams of
  :data:`TELEGRAM` bytes each way, a WEG CFW700's Data_Exchange), against the line time
  Felser's formula gives that exchange at 1.5 Mbit/s (request and reply at 11 bits a
  character, min TSDR 11, TSYN 33 bit times: 237 us). The issue's plant target for the
  Profibus cycle (within 5 % of Felser) leaves 12 us per exchange for everything that is
  not line time; the bare pty's round trip is all of that time, since the pty carries the
  bytes without a line time of its own.
- ``pty_requester_cpu_us``: CPU of the requester per exchange (utime + stime), the floor of
  a master's CPU per exchange on a pty.
- ``host_sleep_cpu_us``: the CPU a process is charged per blocking sleep of 66 us (TSYN at
  500 kbit/s), against the same call without a wait (:func:`bench.common.sleep_cpu`):
  what the host charges for one more sleep and wake, whatever the code.

``python -m bench.bench_pty [--exchanges N]``.
"""

from __future__ import annotations

import contextlib
import os
import resource
import statistics
import subprocess
import sys
import time
import tty
from collections.abc import Iterator
from typing import Final

from adapters.link.timer import precise_sleeps
from adapters.profibus.master.timing import BITS_PER_CHAR
from bench.common import SLEEP, Figure, arg_parser, positive_int, sleep_cpu

TELEGRAM: Final = 14  # bytes each way: SD3 Data_Exchange of 4 I/O words (bench_plant)
BAUD: Final = 1_500_000
MIN_TSDR: Final = 11  # bit times (fact sheet 1.1)
TSYN: Final = 33  # bit times
EXCHANGES: Final = 5000

ECHO = r"""
import os, sys
fd = int(sys.argv[1]); size = int(sys.argv[2])
try:
    while True:
        got = 0
        while got < size:
            chunk = os.read(fd, size - got)
            if not chunk:
                raise SystemExit(0)
            got += len(chunk)
        os.write(fd, b"\x55" * size)
except OSError:  # EIO: the requester closed its side
    pass
"""


def line_time(size: int = TELEGRAM, baud: int = BAUD) -> float:
    """Felser's time of one exchange on a line (s)."""
    return (BITS_PER_CHAR * 2 * size + MIN_TSDR + TSYN) / baud


def read_exactly(fd: int, size: int) -> None:
    got = 0
    while got < size:
        chunk = os.read(fd, size - got)
        if not chunk:
            raise EOFError("pty closed")
        got += len(chunk)


@contextlib.contextmanager
def echo_pty() -> Iterator[int]:
    """A pty pair with the bare echo on its far side (a child process, of the caller's
    scheduling policy): the near side's descriptor, closed with the echo at the end."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    echo = subprocess.Popen(
        [sys.executable, "-c", ECHO, str(slave), str(TELEGRAM)], pass_fds=(slave,)
    )
    try:
        yield master
    finally:
        os.close(master)
        echo.terminate()
        try:
            echo.wait(timeout=10)
        except subprocess.TimeoutExpired:
            echo.kill()
            echo.wait()
        os.close(slave)


def measure(exchanges: int = EXCHANGES) -> tuple[list[float], float]:
    """Round trips (s) and the requester's CPU per exchange (s)."""
    with echo_pty() as master:
        request = b"\xaa" * TELEGRAM
        for _ in range(200):  # warm up both sides
            os.write(master, request)
            read_exactly(master, TELEGRAM)
        trips: list[float] = []
        clock = time.perf_counter
        before = resource.getrusage(resource.RUSAGE_SELF)
        for _ in range(exchanges):
            start = clock()
            os.write(master, request)
            read_exactly(master, TELEGRAM)
            trips.append(clock() - start)
        after = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return trips, cpu / exchanges


def _quantile(values: list[float], q: float) -> float:
    return statistics.quantiles(values, n=1000)[int(q * 1000) - 1]


def run(exchanges: int = EXCHANGES) -> Iterator[Figure]:
    trips, cpu = measure(exchanges)
    line = line_time()
    budget = 0.05 * line
    note = (
        f"bare pty echo between two processes, {TELEGRAM} bytes each way, {exchanges} "
        f"exchanges; reference: Felser's exchange at {BAUD // 1000} kbit/s "
        f"({line * 1e6:.0f} us); 5 % of it, {budget * 1e6:.1f} us, is all the issue's plant "
        "target leaves per exchange beside the line time"
    )
    yield Figure(
        "pty_round_trip_p50_us", statistics.median(trips) * 1e6, "us", line * 1e6, note=note
    )
    yield Figure("pty_round_trip_p99_us", _quantile(trips, 0.99) * 1e6, "us", line * 1e6, note=note)
    yield Figure(
        "pty_round_trip_vs_budget",
        statistics.median(trips) * 1e6,
        "us",
        budget * 1e6,
        target="ratio <= 1 for a 1.05 x Felser cycle on a pty",
        note=note,
    )
    yield Figure(
        "pty_requester_cpu_us",
        cpu * 1e6,
        "us",
        None,
        note="CPU per exchange of the bare requester: a master's floor on a pty",
    )
    precise_sleeps()  # the stream driver's timer slack (1 us)
    sleep, call = sleep_cpu(SLEEP, max(50, exchanges // 10))
    yield Figure(
        "host_sleep_cpu_us",
        sleep * 1e6,
        "us",
        call * 1e6,
        note=f"CPU charged to a process per select(2) sleep of {SLEEP * 1e6:.0f} us (TSYN at "
        "500 kbit/s) on this host, timer slack 1 us; reference: the same call without a "
        "wait. Keeping line timing without spinning costs a master one such sleep more per "
        "exchange than keeping none (bench_profibus's timing ratio floors)",
    )


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_pty", __doc__)
    parser.add_argument(
        "--exchanges", type=positive_int, metavar="N", default=EXCHANGES, help="round trips"
    )
    args = parser.parse_args(argv)
    for fig in run(args.exchanges):
        print(fig.line(), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
