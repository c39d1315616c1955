"""The plant benchmark's Profibus slaves: a config's simulated line on a pty, paced.

The line is the one ``drive-gateway sim profibus --config FILE`` simulates
(:func:`adapters.profibus.cli.build_line`: every drive of the config's Profibus buses, its
device simulator). That command answers each request as soon as it has read it: a pty has
no bit rate, so its line is paced only by the master's own timing (its request's line time
and TSYN). Here each reply is held until the moment its last byte would leave a real slave:

    reply written at = request read + (11 x request bytes + min TSDR + 11 x reply bytes) x t_bit

(fact sheet 1.1: 11 bits per character; the slave answers min TSDR bit times after the
request's last bit at the earliest). The master then sees the whole reply at the end of
its line time, as from a UART, and adds TSYN before its next request itself.

One blocking loop (``select`` on the pty, 1 us timer slack, ``time.sleep`` to the reply's
moment: this process does nothing else meanwhile, as a half-duplex line carries nothing
else); the devices' tick every 10 ms. Recorded for the report: how late each reply went
out against its moment, and the master's turnaround as seen from the line (reply written ->
next request read), against TSYN.

``python -m bench.plant.pbsim --config FILE --baud B --link PATH --out JSON``: the pty's
path is symlinked at PATH (the config's ``port``); SIGTERM ends it and writes JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import select
import signal
import time
import tty
from collections import deque
from typing import Any, Final

from adapters.profibus.cli import build_line
from adapters.profibus.timing import BITS_PER_CHAR, BusParams
from bench.plant.canbus import fine_timer_slack
from gateway.config import load

TICK: Final = 0.01  # s between device ticks
IDLE_AFTER: Final = 0.002  # s of silence that ends a partial telegram
KEEP: Final = 200_000  # samples kept of each figure


def _pct(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(p * len(ordered)))] if ordered else 0.0


def _summary(values: deque[float]) -> dict[str, float]:
    data = list(values)
    return {
        "n": len(data),
        "p50_us": round(_pct(data, 0.5) * 1e6, 1),
        "p99_us": round(_pct(data, 0.99) * 1e6, 1),
        "max_us": round(max(data, default=0.0) * 1e6, 1),
    }


def serve(config_path: str, baud: int, link: str, out: str) -> None:
    fine_timer_slack()
    config = load(config_path)
    line = build_line([], config)
    bus = BusParams.for_baudrate(baud)
    t_bit = 1.0 / baud
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    os.set_blocking(master_fd, False)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(link)
    os.symlink(os.ttyname(slave_fd), link)
    stop = False

    def on_term(*_: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    lateness: deque[float] = deque(maxlen=KEEP)
    turnaround: deque[float] = deque(maxlen=KEEP)
    replies = 0
    request_bytes = 0
    last_rx = 0.0
    last_reply: float | None = None
    next_tick = time.monotonic() + TICK
    try:
        while not stop:
            now = time.monotonic()
            try:
                ready, _, _ = select.select([master_fd], [], [], max(0.0, next_tick - now))
            except InterruptedError:
                continue
            now = time.monotonic()
            if ready:
                try:
                    data = os.read(master_fd, 4096)
                except BlockingIOError:
                    data = b""
                if data:
                    if request_bytes == 0 and last_reply is not None:
                        turnaround.append(now - last_reply)
                        last_reply = None
                    request_bytes += len(data)
                    last_rx = now
                    outgoing = line.receive(data, now)
                    if outgoing or not line.decoder.buffered:
                        sent = request_bytes
                        request_bytes = 0
                        for reply in outgoing:
                            bits = BITS_PER_CHAR * (sent + len(reply.data)) + bus.min_tsdr
                            due = max(reply.at, now + bits * t_bit)
                            wait = due - time.monotonic()
                            if wait > 0:
                                time.sleep(wait)
                            os.write(master_fd, reply.data)
                            written = time.monotonic()
                            lateness.append(written - due)
                            last_reply = written
                            replies += 1
                            sent = 0  # a second reply (none in DP) follows the first
            if now >= next_tick:
                line.tick(now)
                if line.decoder.buffered and now - last_rx >= IDLE_AFTER:
                    line.idle()
                    request_bytes = 0
                next_tick = now + TICK
    finally:
        result: dict[str, Any] = {
            "slaves": len(line.slaves),
            "replies": replies,
            "reply_lateness": _summary(lateness),
            "master_turnaround": _summary(turnaround),
            "tsyn_us": round(bus.tsyn * 1e6, 2),
        }
        with open(out, "w") as f:
            json.dump(result, f)
        with contextlib.suppress(OSError):
            os.unlink(link)
        os.close(master_fd)
        os.close(slave_fd)


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.pbsim")
    parser.add_argument("--config", required=True)
    parser.add_argument("--baud", type=int, required=True)
    parser.add_argument("--link", required=True, help="symlink to create to the pty")
    parser.add_argument("--out", required=True, help="JSON written at the end")
    args = parser.parse_args()
    serve(args.config, args.baud, args.link, args.out)


if __name__ == "__main__":
    main()
