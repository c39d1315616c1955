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
else); the devices tick every 10 ms, one slave at a time between telegrams (each slave's
application runs beside its own line interface; a pass over every device at once would
hold a request meanwhile, counted as the master's turnaround). Recorded for the report:
how late each reply went out against its moment, and the master's turnaround as seen from
the line (reply written -> next request read), against TSYN.

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
from collections.abc import Iterable
from typing import Any, Final

from adapters.profibus.cli import build_line
from adapters.profibus.master.timing import BITS_PER_CHAR, BusParams
from adapters.profibus.sim.slave import DpSlave
from bench.plant import pin_from_env, realtime_from_env
from bench.plant.canbus import fine_timer_slack
from gateway.config import load

TICK: Final = 0.01  # s between device ticks
IDLE_AFTER: Final = 0.002  # s of silence that ends a partial telegram
KEEP: Final = 200_000  # samples kept of each figure


def _pct(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(p * len(ordered)))] if ordered else 0.0


def summary(values: Iterable[float]) -> dict[str, float]:
    """n, p50, p99, max and mean of ``values`` (s), in microseconds."""
    data = list(values)
    return {
        "n": len(data),
        "p50_us": round(_pct(data, 0.5) * 1e6, 1),
        "p99_us": round(_pct(data, 0.99) * 1e6, 1),
        "max_us": round(max(data, default=0.0) * 1e6, 1),
        "mean_us": round(sum(data) / len(data) * 1e6, 1) if data else 0.0,
    }


class PacedLine:
    """The simulated line on its pty, replies held for their line time (module docstring)."""

    def __init__(self, config_path: str, baud: int, link: str) -> None:
        self.line = build_line([], load(config_path))
        self.bus = BusParams.for_baudrate(baud)
        self.t_bit = 1.0 / baud
        self.link = link
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        os.set_blocking(self.master_fd, False)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(link)
        os.symlink(os.ttyname(self.slave_fd), link)
        self.stop = False
        self.lateness: deque[float] = deque(maxlen=KEEP)
        self.turnaround: deque[float] = deque(maxlen=KEEP)
        self.replies = 0
        self.request_bytes = 0  # of the request being received
        self.last_rx = 0.0
        self.last_reply: float | None = None

    def run(self) -> None:
        """Telegrams first; the slaves' devices tick one slave at a time between them
        (module docstring): a pass over 125 devices at once takes 1-2 ms, which a
        request arriving meanwhile would wait, counted as the master's turnaround."""
        next_tick = time.monotonic() + TICK
        due: deque[DpSlave] = deque()  # slaves still to tick in this pass
        while not self.stop:
            timeout = 0.0 if due else max(0.0, next_tick - time.monotonic())
            try:
                ready, _, _ = select.select([self.master_fd], [], [], timeout)
            except InterruptedError:
                continue
            now = time.monotonic()
            if ready:
                self._readable(now)
                continue
            if due:
                due.popleft().tick(now)
                continue
            if now >= next_tick:
                due.extend(self.line.slaves.values())
                if self.line.decoder.buffered and now - self.last_rx >= IDLE_AFTER:
                    self.line.idle()
                    self.request_bytes = 0
                next_tick = now + TICK

    def _readable(self, now: float) -> None:
        try:
            data = os.read(self.master_fd, 4096)
        except BlockingIOError:
            return
        if not data:
            return
        if self.request_bytes == 0 and self.last_reply is not None:
            self.turnaround.append(now - self.last_reply)
            self.last_reply = None
        self.request_bytes += len(data)
        self.last_rx = now
        outgoing = self.line.receive(data, now)
        if not outgoing and self.line.decoder.buffered:
            return  # the rest of the request is still to come
        sent, self.request_bytes = self.request_bytes, 0
        for reply in outgoing:
            bits = BITS_PER_CHAR * (sent + len(reply.data)) + self.bus.min_tsdr
            due = max(reply.at, now + bits * self.t_bit)
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)  # the line is busy with this reply: nothing else to do
            os.write(self.master_fd, reply.data)
            written = time.monotonic()
            self.lateness.append(written - due)
            self.last_reply = written
            self.replies += 1
            sent = 0  # a second reply (none in DP) would follow the first

    def summary(self) -> dict[str, Any]:
        return {
            "slaves": len(self.line.slaves),
            "replies": self.replies,
            "reply_lateness": summary(self.lateness),
            "master_turnaround": summary(self.turnaround),
            "tsyn_us": round(self.bus.tsyn * 1e6, 2),
        }

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.unlink(self.link)
        os.close(self.master_fd)
        os.close(self.slave_fd)


def serve(config_path: str, baud: int, link: str, out: str) -> None:
    fine_timer_slack()
    paced = PacedLine(config_path, baud, link)

    def on_term(*_: object) -> None:
        paced.stop = True

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    try:
        paced.run()
    finally:
        with open(out, "w") as f:
            json.dump(paced.summary(), f)
        paced.close()


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.pbsim")
    parser.add_argument("--config", required=True)
    parser.add_argument("--baud", type=int, required=True)
    parser.add_argument("--link", required=True, help="symlink to create to the pty")
    parser.add_argument("--out", required=True, help="JSON written at the end")
    args = parser.parse_args()
    pin_from_env()
    realtime_from_env()
    serve(args.config, args.baud, args.link, args.out)


if __name__ == "__main__":
    main()
