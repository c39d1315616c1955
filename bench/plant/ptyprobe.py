"""The plant benchmark's pty probe: what the host's ptys allow any master while the plant
runs, measured beside the Profibus line in the same window.

The master's turnaround that the slaves' simulator measures (reply written -> next request
read) crosses the pty twice: the reply to the gateway, the next request back. Each
crossing is the kernel's tty work (a pty write is handed to a kernel worker thread, which
the host schedules like any other thread) and a wake-up. Under the plant's load those
crossings have a tail of their own, whatever the master does.

This probe is a bare requester and a bare echo (:mod:`bench.bench_pty`'s, no protocol, no
event loop) on a pty pair of their own, under the same ``SCHED_FIFO`` priority as the
slaves' simulator and the master's rings (:data:`bench.plant.REALTIME_ENV`), exchanging
:data:`~bench.bench_pty.TELEGRAM` bytes each way every :data:`PACE` s for the window. Its
round trip is the same two crossings with nothing of the master's in them: the floor the
turnaround's tail is compared with (``plant_pty_round_trip_*``).

``python -m bench.plant.ptyprobe --settle S --seconds S``: one JSON line on stdout (the
round trips' figures, microseconds) at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Final

from bench.bench_pty import TELEGRAM, echo_pty, read_exactly
from bench.plant import pin_from_env, realtime_from_env
from bench.plant.pbsim import summary

PACE: Final = 0.001  # s between two exchanges' starts (a light load: about 2 % of a CPU)


def probe(settle: float, seconds: float) -> list[float]:
    """Round trips (s) over ``seconds``, after ``settle`` s of the same exchanges."""
    trips: list[float] = []
    with echo_pty() as master:  # the echo inherits this process's priority
        request = b"\xaa" * TELEGRAM
        clock = time.monotonic
        begin = clock()
        measure_from, end = begin + settle, begin + settle + seconds
        at = begin
        while True:
            now = clock()
            if now >= end:
                break
            if at > now:
                time.sleep(at - now)
            start = clock()
            os.write(master, request)
            read_exactly(master, TELEGRAM)
            if start >= measure_from:
                trips.append(clock() - start)
            at = max(at + PACE, clock())
    return trips


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.ptyprobe")
    parser.add_argument("--settle", type=float, default=0.0)
    parser.add_argument("--seconds", type=float, required=True)
    args = parser.parse_args()
    pin_from_env()
    realtime_from_env()
    trips = probe(args.settle, args.seconds)
    print(json.dumps(summary(trips)), flush=True)


if __name__ == "__main__":
    main()
