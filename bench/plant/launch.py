"""Run ``drive-gateway`` for the plant benchmark, with the bench CAN bus registered.

``python -m bench.plant.launch [--record JSON] [--profile FILE] -- <drive-gateway args>``

- registers :class:`bench.plant.canbus.PlantCanBus` as python-can interface
  ``plantcan`` (a config's ``interface = "plantcan"``, ``channel = <broker socket>``),
  then runs the command line of ``drive-gateway`` (``run --config ...`` or
  ``sim devicenet ...``);
- ``--record``, for ``run`` only: every bus cycle of each line (Profibus master: first
  request to end of the cycle, :class:`~adapters.profibus.master.figures.LineFigures`.cycle;
  DeviceNet scanner: poll cycle; CANopen master: time between two SYNC cycles,
  ``Master._cycle``), as (monotonic end time, seconds) pairs, and twice a
  second the number of drives online; written at ``--record`` (the status part every
  0.5 s, the cycles when the daemon ends), and every garbage collection's pause. The
  recording is a list append per cycle and per collection; at the end also each Profibus
  line's error counters (retries, timeouts, bad telegrams: whole run, come-up included),
  and every 0.5 s the CPU time of each part of the gateway (:mod:`bench.plant.cpusplit`:
  each line's thread, the daemon's loop split by what it runs, Zenoh's threads);
- ``--profile``: the whole run under cProfile, its stats written to FILE at the end, and
  each line's thread in CPU time to FILE.line-NAME (``BENCH_PROFILE_AFTER=S``: a line's
  stats from S seconds after its start, without the come-up; ``BENCH_PROFILE_FOR=T``: for
  T seconds, without the shutdown);
- ``BENCH_PROFIBUS_BURSTS=0`` in the environment: the Profibus line without its bursts of
  steady exchanges (docs/decisions/0101), to compare; ``DRIVE_GATEWAY_RING=off`` (or
  ``python``): without its steady rings (or with them in Python; docs/decisions/0103).

The daemon is the real one (``gateway.runtime.daemon.Daemon``), set up as ``drive-gateway run``
sets it up; only the two figure hooks above are added.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import gc
import json
import logging
import marshal
import math
import os
import sys
import threading
import time
from typing import Any

from bench.plant import canbus, cpusplit, pin_from_env

CYCLES: dict[str, list[tuple[float, float]]] = {"profibus": [], "devicenet": [], "canopen": []}
GC_PAUSES: list[tuple[float, int, float]] = []  # (monotonic end, generation, seconds)
PROFIBUS_LINES: list[Any] = []  # each Profibus master's LineFigures (its error counters)
CPU: list[dict[str, Any]] = []  # every 0.5 s: the CPU by thread group (bench.plant.cpusplit)
ACCOUNT = cpusplit.LoopAccount()


def _hook_gc() -> None:
    """Record every garbage collection's pause (its generation, its duration)."""
    started = [0.0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        now = time.perf_counter()
        if phase == "start":
            started[0] = now
        else:
            GC_PAUSES.append((time.monotonic(), info["generation"], now - started[0]))

    gc.callbacks.append(on_gc)


def _hook_cycles() -> None:
    """Record each line's cycles (see the module docstring)."""
    from adapters.devicenet.scanner.scheduler import Scheduler
    from adapters.profibus.master.figures import LineFigures, Samples

    profibus = CYCLES["profibus"]

    class RecordingSamples(Samples):
        def add(self, value: float) -> None:
            super().add(value)
            profibus.append((time.monotonic(), value))

    init = LineFigures.__init__

    def line_figures_init(self: LineFigures, *args: Any, **kwargs: Any) -> None:
        init(self, *args, **kwargs)
        self.cycle = RecordingSamples()
        PROFIBUS_LINES.append(self)

    LineFigures.__init__ = line_figures_init  # type: ignore[method-assign]

    devicenet = CYCLES["devicenet"]
    done = Scheduler._cycle_done

    def cycle_done(self: Scheduler, seconds: float) -> None:
        done(self, seconds)
        devicenet.append((time.monotonic(), seconds))

    Scheduler._cycle_done = cycle_done  # type: ignore[method-assign]

    from adapters.canopen.master.engine import Master

    canopen = CYCLES["canopen"]
    last = [math.nan]
    sync_cycle = Master._cycle

    def master_cycle(self: Master, now: float, out: list[Any]) -> None:
        sync_cycle(self, now, out)
        at = time.monotonic()
        if not math.isnan(last[0]):
            canopen.append((at, at - last[0]))
        last[0] = at

    Master._cycle = master_cycle  # type: ignore[method-assign]


def _write(path: str, online: dict[str, int], total: int, final: bool) -> None:
    doc: dict[str, Any] = {
        "online": sum(online.values()),
        "online_by_bus": online,
        "drives": total,
        "final": final,
        "pid": os.getpid(),
    }
    if final:
        doc["cycles"] = CYCLES
        doc["gc"] = GC_PAUSES
        doc["profibus_errors"] = [line.counters() for line in PROFIBUS_LINES]
        doc["cpu"] = CPU
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(doc, f)
    os.replace(tmp, path)


async def _daemon(config_path: str, record: str | None) -> int:
    from gateway.config import load
    from gateway.model import CommState
    from gateway.runtime.daemon import Daemon

    daemon = Daemon(load(config_path))
    total = len(daemon.config.drives)

    def online() -> dict[str, int]:
        by_bus = {bus.name: 0 for bus in daemon.config.buses}
        for s in daemon.hub.states():
            if s.comm is CommState.ONLINE:
                by_bus[s.bus] = by_bus.get(s.bus, 0) + 1
        return by_bus

    async def report() -> None:
        while record is not None:
            CPU.append(cpusplit.sample(ACCOUNT))
            _write(record, online(), total, final=False)
            await asyncio.sleep(0.5)

    reporter = asyncio.create_task(report())
    try:
        return await daemon.run()
    finally:
        reporter.cancel()
        if record is not None:
            _write(record, online(), total, final=True)


def _bursts_from_env() -> None:
    """``BENCH_PROFIBUS_BURSTS=0``: the Profibus line without its bursts of steady
    exchanges (docs/decisions/0101), for a comparison with them."""
    if os.environ.get("BENCH_PROFIBUS_BURSTS") == "0":
        from adapters.link.serial import SerialPort

        SerialPort.far_end_apart = lambda self: False  # type: ignore[method-assign]


def _snapshot(profiler: cProfile.Profile) -> dict[Any, Any]:
    profiler.snapshot_stats()
    return dict(profiler.stats)


def _less(stats: dict[Any, Any], before: dict[Any, Any]) -> dict[Any, Any]:
    """The stats gathered since ``before`` (``BENCH_PROFILE_AFTER``: without the come-up)."""

    def minus(a: tuple[Any, ...], b: tuple[Any, ...] | None) -> tuple[Any, ...]:
        return a if b is None else tuple(x - y for x, y in zip(a, b, strict=True))

    out: dict[Any, Any] = {}
    for func, (cc, nc, tt, ct, callers) in stats.items():
        old = before.get(func)
        if old is None:
            out[func] = (cc, nc, tt, ct, callers)
            continue
        counts = minus((cc, nc, tt, ct), old[:4])
        if counts[1] <= 0:
            continue
        out[func] = (*counts, {c: minus(v, old[4].get(c)) for c, v in callers.items()})
    return out


def _profile_lines(path: str) -> None:
    """``--profile``: each line's thread under a cProfile of its own in CPU time, written
    at ``PATH.line-NAME`` when the line ends (the main one profiles the daemon's loop)."""
    from gateway.runtime.linethread import LineThread

    original = LineThread._thread_main

    after = float(os.environ.get("BENCH_PROFILE_AFTER", "0"))
    span = float(os.environ.get("BENCH_PROFILE_FOR", "0"))

    def profiled(self: LineThread, *args: Any) -> None:
        profiler = cProfile.Profile(time.thread_time)
        before: dict[Any, Any] = {}
        end: dict[Any, Any] = {}
        for at, into in ((after, before), (after + span, end) if span > 0 else (0.0, end)):
            if at > 0:
                timer = threading.Timer(at, lambda into=into: into.update(_snapshot(profiler)))
                timer.daemon = True
                timer.start()
        profiler.enable()
        try:
            original(self, *args)
        finally:
            profiler.disable()
            with open(f"{path}.line-{self.name}", "wb") as out:
                marshal.dump(_less(end or _snapshot(profiler), before), out)

    LineThread._thread_main = profiled  # type: ignore[method-assign,assignment]


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.launch")
    parser.add_argument("--record", help="JSON: drives online, then each line's cycles")
    parser.add_argument("--profile", help="cProfile stats file")
    parser.add_argument("--log-level", default="WARNING")
    parser.add_argument("argv", nargs=argparse.REMAINDER, help="-- drive-gateway arguments")
    args = parser.parse_args()
    pin_from_env()
    _bursts_from_env()
    argv = [a for a in args.argv if a != "--"] if args.argv[:1] == ["--"] else args.argv
    canbus.register()
    profiler = cProfile.Profile() if args.profile else None
    status = 0
    if profiler is not None:
        _profile_lines(args.profile)
        profiler.enable()
    try:
        if argv[:1] == ["run"] and "--config" in argv:
            from gateway.cli.run import setup_logging

            setup_logging(args.log_level)
            _hook_cycles()
            _hook_gc()
            if args.record:
                ACCOUNT.install()
            status = asyncio.run(_daemon(argv[argv.index("--config") + 1], args.record))
        else:
            from gateway.cli import main as gateway_main

            status = gateway_main(argv)
    finally:
        if profiler is not None:
            profiler.disable()
            profiler.dump_stats(args.profile)
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # Zenoh's native threads: leave as drive-gateway run does


if __name__ == "__main__":
    main()
