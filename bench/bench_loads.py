"""Every line's cycle rate under each front-end and bus load, against its rate without load.

The gateway is the demo (config/demo.toml: a simulated Profibus line of four slaves over a
pty, a CFW-08 on a DeviceNet line and two CiA 402 drives on a CANopen line, both on
python-can's in-process ``virtual`` bus), run in this process on its asyncio loop with its
Zenoh, Modbus and web ports moved to free loopback ports and commands from the web page on
(:mod:`bench.loads.gateway`). The network loads run in child processes, so that their own
CPU is not the gateway's; the CAN floods come from a thread of this process on the lines'
own channels (:mod:`bench.loads.kinds`). Each load, one after the other:

- ``none``: the reference, measured first and again last;
- ``pages``: 1,000 WebSocket pages on ``/ws``, 100 of them never reading, opened 100 at a
  time from 40 loopback addresses (what the gateway refuses is counted);
- ``scrape``: ``/metrics`` fetched by 4 clients at once, flat out;
- ``slow``: 1,100 connections that send a request line, then a header byte every 5 s;
- ``emcy``: EMCY frames with random data from the CANopen line's first drive, 2,000/s, up
  to 20,000;
- ``dupmac``: Duplicate MAC ID check requests for the DeviceNet scanner's MAC ID, 2,000/s,
  up to 5,000;
- ``tokens``: ``POST /api/drives/<id>/command`` with a wrong token, one client, flat out;
- ``cpu``: two CPU-bound processes.

Per load, once it is up, over a window of :data:`WINDOW` s (:data:`SHORT_WINDOW` with
``BENCH_SHORT``; a flood's window is its frames plus :data:`~bench.loads.kinds.FLOOD_TAIL`):

- ``loads.<load>.<bus>.rate_ratio``: the line's cycles per second (Profibus master cycles,
  DeviceNet poll cycles, CANopen SYNCs, from the line's diagnostics), its reference the
  first ``none`` window, before any load; target ratio >= 0.9 (for ``none``: the last
  window against the first, the reference's own drift; a line that a load left standing
  shows it there and in every load after);
- ``loads.<load>.offline_events``: hub events of drives leaving online, from the load's
  start until :data:`SETTLE` s after it ended (and its window's probes are in); target 0
  (a line whose own loop stands still reports nothing: its rate says so);
- ``loads.<load>.modbus_new_client_s``: the longest time a new Modbus TCP client (one every
  :data:`PROBE_EVERY` s, from a child process) took to connect and get its answer, of those
  begun in the window; target <= 1 s;
- ``loads.<load>.rss_mb``: this process's RSS :data:`SETTLE` s after the load ended, against
  before it began; ``loads.<load>.log_kib_per_s``: what the gateway logged meanwhile;
- what the load itself saw (pages refused, requests per second, frames sent).

Everything is on 127.0.0.1; every load ends by itself and is ended by the benchmark (child
processes by pid). The soft descriptor limit of this process is raised to its hard limit
for the run (the slow connections need more than 1,024).

``python -m bench loads``, or alone: ``python -m bench.bench_loads [--window S]
[--loads NAME ...]``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import resource
import statistics
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Protocol

from bench.common import Figure, add_number, arg_parser, print_figures
from bench.loads.clients import PROBE_TIMEOUT
from bench.loads.gateway import (
    CALL_BOUND,
    Demo,
    EventWatch,
    LogCapture,
    Reading,
    rate,
    rss_mb,
)
from bench.loads.kinds import (
    READY_BOUND,
    ChildLoad,
    Children,
    FloodLoad,
    NoLoad,
    dupmac_frame,
    emcy_frame,
    poll_until,
)

WINDOW: Final = 15.0  # s measured per load
SHORT_WINDOW: Final = 4.0  # s with BENCH_SHORT (python -m bench --short)
SETTLE: Final = 1.0  # s after a load ended before its RSS and events are read
PROBE_EVERY: Final = 0.5  # s between two new Modbus clients
LOADS: Final = ("pages", "scrape", "slow", "emcy", "dupmac", "tokens", "cpu")
PAGES, QUIET_PAGES, SLOW_CONNECTIONS, PEERS = 1000, 100, 1100, 40
EMCY_COUNT, DUPMAC_COUNT, FLOOD_RATE = 20_000, 5_000, 2000.0
CPU_PROCESSES: Final = 2
RATE_TARGET: Final = "ratio >= 0.9"


class Load(Protocol):
    name: str

    async def start(self) -> None: ...
    async def ready(self) -> bool: ...
    def window(self, default: float) -> float: ...
    async def stop(self) -> dict[str, Any]: ...


@dataclass
class Sample:
    """What one load's window gave."""

    load: str
    window: float = math.nan
    ready: bool = True
    rates: dict[str, float] = field(default_factory=dict)
    drops: dict[str, int] = field(default_factory=dict)
    stale: set[str] = field(default_factory=set)  # buses read from their last snapshot
    kinds: dict[str, int] = field(default_factory=dict)
    left_online: list[str] = field(default_factory=list)
    probes: list[float | None] = field(default_factory=list)
    rss: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # before, window end, after
    log_rate: float = math.nan  # bytes/s from the load's start until SETTLE after its end
    own: dict[str, Any] = field(default_factory=dict)
    error: str = ""
    span: tuple[float, float] | None = None  # the window's start and end (time.monotonic)


@dataclass
class Bench:
    """The running parts: the gateway, its event watch, the children, the Modbus probe."""

    demo: Demo
    events: EventWatch
    children: Children
    probe: Any
    log: LogCapture
    window: float


# ---------------------------------------------------------------------- the loads


def child_seconds(window: float) -> float:
    """A child's own bound: up, a window and its end, with room to spare."""
    return READY_BOUND + window + 20.0


def make_load(name: str, bench: Bench) -> Load:
    demo, children = bench.demo, bench.children
    seconds = ["--seconds", f"{child_seconds(bench.window):g}"]
    web = ["--port", str(demo.web)]
    if name == "pages":
        argv = ["pages", *web, "--count", str(PAGES), "--quiet", str(QUIET_PAGES)]
        return ChildLoad(name, children, [[*argv, "--peers", str(PEERS), *seconds]])
    if name == "scrape":
        return ChildLoad(name, children, [["scrape", *web, "--workers", "4", *seconds]])
    if name == "slow":
        argv = ["slow", *web, "--count", str(SLOW_CONNECTIONS), "--every", "5"]
        return ChildLoad(name, children, [[*argv, "--peers", str(PEERS), *seconds]])
    if name == "tokens":
        drive = demo.config.drives[0].id
        return ChildLoad(name, children, [["tokens", *web, "--drive", drive, *seconds]])
    if name == "cpu":
        return ChildLoad(name, children, [["spin", *seconds]] * CPU_PROCESSES)
    if name == "emcy":
        bus = demo.bus("canopen")
        node = bus.drives[0].address
        return FloodLoad(name, bus.options.channel, emcy_frame(node), EMCY_COUNT, FLOOD_RATE)
    if name == "dupmac":
        bus = demo.bus("devicenet")
        frame = dupmac_frame(bus.options.mac)
        return FloodLoad(name, bus.options.channel, frame, DUPMAC_COUNT, FLOOD_RATE)
    raise ValueError(f"no load {name!r}")


def can_run(name: str, demo: Demo) -> str:
    """Why the load cannot run on this config ('' if it can)."""
    needs = {"emcy": "canopen", "dupmac": "devicenet"}.get(name)
    if needs is not None and demo.bus(needs) is None:
        return f"the config has no {needs} line"
    return ""


# ---------------------------------------------------------------------- one window


def _probes(bench: Bench, t0: float, t1: float) -> list[float | None]:
    """The new-client times of the probes begun between t0 and t1 (None: no answer)."""
    out: list[float | None] = []
    for doc in bench.probe.lines():
        if "t" in doc and t0 <= doc["t"] <= t1:
            value = doc.get("s")
            out.append(float(value) if isinstance(value, int | float) else None)
    return out


async def _window(bench: Bench, sample: Sample) -> None:
    """The window itself: readings of every line at its start and its end."""
    before = await bench.demo.readings()
    t0 = time.monotonic()
    await asyncio.sleep(sample.window)
    sample.span = (t0, time.monotonic())
    after = await bench.demo.readings()
    sample.rss = (sample.rss[0], rss_mb(), math.nan)
    _rates(sample, before, after)


async def _probed(bench: Bench, sample: Sample) -> None:
    """The probes begun in the window, once each has its outcome: the probe's clients come
    one after the other, so one begun after the window means every earlier one is in."""
    if sample.span is None:
        return
    t1 = sample.span[1]

    def after_window() -> bool:
        return any(doc.get("t", 0) > t1 for doc in bench.probe.lines())

    await poll_until(after_window, PROBE_TIMEOUT + PROBE_EVERY + 1.0, 0.25)
    sample.probes = _probes(bench, *sample.span)


def _rates(sample: Sample, before: dict[str, Reading], after: dict[str, Reading]) -> None:
    for bus, first in before.items():
        last = after[bus]
        sample.rates[bus] = rate(first, last)
        sample.drops[bus] = last.drops - first.drops
        if not (first.fresh and last.fresh):
            sample.stale.add(bus)


async def measure(bench: Bench, load: Load) -> Sample:
    """One load: started, up, measured over its window, ended; then SETTLE s."""
    sample = Sample(load.name, window=load.window(bench.window))
    sample.rss = (rss_mb(), math.nan, math.nan)
    mark = bench.events.mark()
    log0, started = bench.log.size(), time.monotonic()
    try:
        await load.start()
        sample.ready = await load.ready()
        await _window(bench, sample)
    except Exception as exc:  # the other loads still run; this one says why it has none
        sample.error = f"{type(exc).__name__}: {exc}"
        traceback.print_exc(file=sys.stderr)
    finally:
        sample.own = await load.stop()
    await asyncio.sleep(SETTLE)
    await _probed(bench, sample)
    sample.kinds, sample.left_online = bench.events.since(mark)
    sample.rss = (sample.rss[0], sample.rss[1], rss_mb())
    sample.log_rate = (bench.log.size() - log0) / (time.monotonic() - started)
    return sample


# ---------------------------------------------------------------------- the figures


def _mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return statistics.fmean(finite) if finite else math.nan


def _round(value: float, digits: int = 3) -> float:
    return round(value, digits) if math.isfinite(value) else value


def _probe_max(probes: list[float | None]) -> float:
    if not probes:
        return math.nan
    return max(PROBE_TIMEOUT if p is None else p for p in probes)


def _probe_note(probes: list[float | None]) -> str:
    answered = sorted(p for p in probes if p is not None)
    if not answered:
        return f"{len(probes)} new clients in the window, none answered within {PROBE_TIMEOUT:g} s"
    return (
        f"{len(probes)} new clients in the window (one every {PROBE_EVERY:g} s, a child "
        f"process), {len(probes) - len(answered)} unanswered within {PROBE_TIMEOUT:g} s; "
        f"answered: median {statistics.median(answered) * 1e3:.1f} ms, max "
        f"{answered[-1] * 1e3:.1f} ms"
    )


_STALE: Final = (
    "; the line did not answer a reading within "
    f"{CALL_BOUND:g} s: its last snapshot was read (its loop held up)"
)


def _rate_figures(sample: Sample, reference: dict[str, float], note: str) -> list[Figure]:
    return [
        Figure(
            f"loads.{sample.load}.{bus}.rate_ratio",
            _round(value, 2),
            "cycles/s",
            _round(reference.get(bus, math.nan), 2),
            RATE_TARGET,
            f"{note}; window {sample.window:.1f} s; the drives' own drop counts on the line "
            f"(left data exchange, offline, heartbeat lost): {sample.drops.get(bus)}"
            + (_STALE if bus in sample.stale else ""),
        )
        for bus, value in sample.rates.items()
    ]


def _sample_figures(sample: Sample, ref: Sample, reference: dict[str, float]) -> list[Figure]:
    name = f"loads.{sample.load}"
    own = _own_figure(sample)
    if sample.span is None and sample.error and own is not None:
        return [own]  # it never got to its window: nothing else was measured
    ref_note = "reference: the first window without load"
    if sample.load == "none":
        ref_note = "the last window without load against the first (the reference's drift)"
    figures = _rate_figures(sample, reference, ref_note)
    left = dict(Counter(sample.left_online))
    figures += [
        Figure(
            f"{name}.offline_events",
            len(sample.left_online),
            "events",
            len(ref.left_online),
            "0",
            f"drives that left online: {left}; hub events by kind: {sample.kinds}; "
            f"from the load's start to {SETTLE:g} s after its end or more",
        ),
        Figure(
            f"{name}.modbus_new_client_s",
            _round(_probe_max(sample.probes)),
            "s",
            _round(_probe_max(ref.probes)),
            "<= 1 s",
            _probe_note(sample.probes),
        ),
        Figure(
            f"{name}.rss_mb",
            _round(sample.rss[2], 1),
            "MiB",
            _round(sample.rss[0], 1),
            note=f"this process's VmRSS {SETTLE:g} s after the load ended, against before it "
            f"began; {sample.rss[1]:.1f} MiB at the window's end",
        ),
        Figure(
            f"{name}.log_kib_per_s",
            _round(sample.log_rate / 1024, 2),
            "KiB/s",
            _round(ref.log_rate / 1024, 2),
            note="what the gateway logged (at the config's level) from the load's start "
            f"to {SETTLE:g} s after its end",
        ),
    ]
    if own is not None:
        figures.append(own)
    return figures


def _own_figure(sample: Sample) -> Figure | None:
    """What the load itself saw (its child's or flood's own counts)."""
    own, name = sample.own, f"loads.{sample.load}"
    note = json.dumps(own, sort_keys=True)
    if not sample.ready:
        note = "not fully up within its bound; " + note
    if sample.error:
        return Figure(f"{name}.load", math.nan, "", note=f"failed: {sample.error}; {note}")
    if sample.load == "pages":
        refused = own.get("attempted", 0) - own.get("opened", 0)
        return Figure(f"{name}.refused", refused, "pages", PAGES, None, note)
    if sample.load in ("scrape", "tokens"):
        value = float(own.get("requests_per_s_since_ready", math.nan))
        return Figure(f"{name}.requests_per_s", value, "requests/s", None, None, note)
    if sample.load == "slow":
        return Figure(
            f"{name}.held_open",
            own.get("open_at_stop", math.nan),
            "connections",
            SLOW_CONNECTIONS,
            None,
            f"still open when the load ended; {note}",
        )
    if sample.load in ("emcy", "dupmac"):
        value = float(own.get("frames_per_s", math.nan))
        return Figure(f"{name}.frames_per_s", value, "frames/s", FLOOD_RATE, None, note)
    if not sample.ready:
        return Figure(f"{name}.load", math.nan, "", note=note)
    return None


def figures(samples: list[Sample]) -> list[Figure]:
    """Every figure: the two reference windows first and last in ``samples``."""
    first, last = samples[0], samples[-1]
    buses = list(first.rates)
    none = Sample(
        "none",
        window=last.window,
        rates=last.rates,
        drops={b: first.drops.get(b, 0) + last.drops.get(b, 0) for b in buses},
        stale=first.stale | last.stale,
        kinds=dict(Counter(first.kinds) + Counter(last.kinds)),
        left_online=first.left_online + last.left_online,
        probes=first.probes + last.probes,
        rss=(first.rss[0], last.rss[1], last.rss[2]),
        log_rate=_mean([first.log_rate, last.log_rate]),
    )
    none.span = first.span
    out = _sample_figures(none, none, first.rates)
    for sample in samples[1:-1]:
        out += _sample_figures(sample, none, first.rates)
    return out


# ---------------------------------------------------------------------- the run


@contextlib.contextmanager
def descriptors_raised() -> Iterator[int]:
    """The soft RLIMIT_NOFILE at the hard limit for the run (restored after): the limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    try:
        yield hard
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


async def _measure_all(bench: Bench, loads: tuple[str, ...]) -> list[Sample]:
    samples = [await measure(bench, NoLoad())]
    for name in loads:
        why = can_run(name, bench.demo)
        if why:
            samples.append(Sample(name, error=why))
            continue
        samples.append(await measure(bench, make_load(name, bench)))
    samples.append(await measure(bench, NoLoad()))
    return samples


async def _until_ready(child: Any) -> None:
    """Until the child says it is up (bounded), then SETTLE s more."""
    await poll_until(lambda: child.ready() or child.proc.poll() is not None, READY_BOUND, 0.1)
    await asyncio.sleep(SETTLE)


async def _run(window: float, loads: tuple[str, ...]) -> list[Figure]:
    with contextlib.ExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="loads-")))
        limit = stack.enter_context(descriptors_raised())
        demo = Demo(tmp)
        log = stack.enter_context(
            LogCapture(tmp / "gateway.log", demo.config.gateway.log_level).installed()
        )
        children = Children(tmp)
        stack.callback(children.kill_all)
        try:
            await demo.start()
            bound = (len(loads) + 2) * (READY_BOUND + window + 30.0)
            probe = children.start(
                "probe",
                [
                    *("probe", "--port", str(demo.modbus), "--every", f"{PROBE_EVERY:g}"),
                    *("--seconds", f"{bound:g}"),
                ],
            )
            await _until_ready(probe)
            events = EventWatch(demo.daemon.hub)
            bench = Bench(demo, events, children, probe, log, window)
            try:
                samples = await _measure_all(bench, loads)
            finally:
                await events.close()
                await Children.end(probe)
        finally:
            await demo.stop()
    print(f"# bench_loads: descriptor limit {limit} for the run", file=sys.stderr)
    return figures(samples)


def default_window() -> float:
    return SHORT_WINDOW if os.environ.get("BENCH_SHORT") else WINDOW


def run(window: float | None = None, loads: tuple[str, ...] = LOADS) -> list[Figure]:
    return asyncio.run(_run(window or default_window(), loads))


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser(
        "bench_loads",
        __doc__,
        epilog=f"make bench (python -m bench) runs every load with {WINDOW:g} s windows "
        f"(python -m bench --short: {SHORT_WINDOW:g} s).",
    )
    add_number(parser, "--window", WINDOW, "seconds measured per load")
    parser.add_argument(
        "--loads",
        nargs="+",
        choices=LOADS,
        default=list(LOADS),
        metavar="NAME",
        help=f"the loads to run, of {', '.join(LOADS)}",
    )
    args = parser.parse_args(argv)
    print_figures(run(args.window, tuple(args.loads)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
