"""Profibus DP master: message cycles over a pty against the transport's own limit.

Master: the engine, the driver and the serial link (pyserial on the pty's slave side) in
this process, exchanging data as fast as the line allows (``cycle_time = 0``) with 1 and
32 simulated DP slaves (echo devices, 8 bytes in and out, like a drive's 4 words) that run
in a child process on the pty's other side. The figure is message cycles (Data_Exchange
request and reply) per second, and the master's CPU time per message cycle.

The child answers every telegram through the simulated slaves (start-up, diagnosis,
Global_Control, Data_Exchange) and keeps the reply of each Data_Exchange telegram it has
answered: the same telegram again (same slave, FCB, outputs: an echo device's answer cannot
change, no watchdog runs) gets that reply at once. So the other end costs what a bare
responder costs, and the run measures the master, not the simulator. A check figure shows
it: a bare requester against that child is as fast as against the bare responder.

Reference, same run, same kind of pty, same sizes (a Data_Exchange with 8 bytes is an SD3
telegram of 14 bytes, its reply too): raw request/response round trips between a bare
requester here and a bare responder in a child process. The target ratio (>= 0.66) is
against a bare requester on the event loop (``loop.add_reader``, the I/O any master on
the loop has to do, and what this one does); the ratio against a blocking requester (no
event loop at all) is reported too. Rounds alternate reference / master, so both sides
meet the same mix of the host's conditions. A round's rate is its best window of
:data:`WINDOW` seconds (counted the same way at each side's own completions, see
:class:`Windows`), and a side's figure is the median of its rounds.

CPU placement: on a machine with two or more CPUs, every requester (master or bare) runs
on one CPU and every responder child on another, the same two for reference and master.
Left to the scheduler, a round trip's cost depends on where the two ends happen to run:
the same bare requester measured 1,700 to 9,300 round trips/s between runs on the 2-CPU
test machine, and the ratio swung from 0.52 to 0.92 with the code unchanged. Pinned, both
sides see the same placement in every round (docs/decisions/0020-bench-cpu-placement.md).

The master's own time per message cycle (engine, decoder, driver) is also timed without
the pty and the event loop, replaying the simulated slaves' replies: the steadiest figure
on a machine shared with other work.

Line timing honoured against timing off (:func:`measure_timing`): the master's CPU per
exchange at 500 kbit/s against 12 Mbit/s (TSYN 2.75 us), on the slaves above and on slaves
paced like a 500 kbit/s line (:func:`_serve_paced`: each reply written when its last byte
would come in on the line), and each request's lateness against its ``not_before``. With
each, the floor this host puts under that ratio (:func:`_floor_figures`): timing off's CPU
plus the CPU of the extra sleeps keeping the timing takes, counted in the same rounds.

From the measured turnaround (reply in -> next request out, inside the master) comes what
the master could sustain on a real line: the Felser estimate of a DP cycle,
T = (380 + 300 x slaves + 11 x bytes) x t_bit + 75 us (bytes: all the I/O bytes of the
slaves), against the same estimate plus the master's turnaround for every message cycle,
at 500 and 187.5 kbit/s.

``python -m bench profibus``, or alone: ``python -m bench.bench_profibus [--slaves N ...]
[--timing-slaves N ...] [--rounds N] [--seconds S]``.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import itertools
import math
import multiprocessing
import os
import resource
import select
import statistics
import termios
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from adapters.link.stream import Transmission
from adapters.profibus.codec.dp import DataExchange, build_request
from adapters.profibus.codec.fdl import (
    DataTelegram,
    FcbState,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    decode_telegram,
)
from adapters.profibus.driver import LineDriver
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.link import SerialLink, open_link
from adapters.profibus.master import InputsReceived, Master, SlaveParams, SlaveState
from adapters.profibus.master.timing import BusParams
from adapters.profibus.sim.echo import ECHO_IDENT, EchoSim, echo_cfg
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.slave import DpSlave
from bench.common import (
    Figure,
    add_counts,
    add_number,
    arg_parser,
    id_range,
    print_figures,
    sleep_cpu,
)

SIZE: Final = 8  # bytes in and out per slave (4 words)
OUTPUTS: Final = bytes(range(SIZE))  # what the master sends every slave
FIRST: Final = 3  # the first slave address
MASTER: Final = 2
ROUNDS: Final = 16  # reference / master rounds per slave count (the median of each counts)
MEASURE: Final = 0.4  # s measured per round
WINDOW: Final = 0.05  # s: a round's rate is its best window this long (see Windows)
SETTLE: Final = 0.2  # s of exchange before a master round is measured
REPLY_TIMEOUT: Final = 2.0  # s: a bare requester gives up (a benchmark never hangs)
TARGET: Final = "ratio >= 0.66"
SLAVE_COUNTS: Final = (1, 32)  # message-cycle cases (:func:`measure`)
TIMING_SLAVE_COUNTS: Final = (1, 8)  # line timing cases (:func:`measure_timing`)
# On a pty the baud rate means nothing; 12 Mbit/s keeps TSYN (2.75 us) out of the figures.
BUS: Final = BusParams.for_baudrate(12000000, master_address=MASTER, latency=0.05, gc_period=0.1)


# ---------------------------------------------------------------------------------------
# the telegrams, as the master sends them


def exchange_frames(slaves: int) -> list[bytes]:
    """Data_Exchange telegrams for each slave, two rounds so the FCB alternates (1.3)."""
    out: list[bytes] = []
    fcbs = {FIRST + i: FcbState(fcb=True, fcv=True) for i in range(slaves)}
    for _ in range(2):
        for address, fcb in fcbs.items():
            fc = fcb.fc(RequestFunction.SRD_HIGH)
            out.append(build_request(DataExchange(OUTPUTS), da=address, sa=MASTER, fc=fc).encode())
            fcbs[address] = fcb.acknowledged()
    return out


def reply_frame() -> bytes:
    """An echo slave's Data_Exchange reply: DL with the outputs as inputs."""
    return DataTelegram(MASTER, FIRST, ResponseFc(ResponseStatus.DL), data=OUTPUTS).encode()


REQUEST_LEN: Final = len(exchange_frames(1)[0])
REPLY_LEN: Final = len(reply_frame())


# ---------------------------------------------------------------------------------------
# the other side of the pty, in a child process


def _is_exchange(chunk: bytes) -> bool:
    try:
        telegram = decode_telegram(chunk)
    except ProfibusDecodeError:
        return False
    return isinstance(telegram, DataTelegram) and telegram.is_request and telegram.dsap is None


def _serve_slaves(fd: int, slaves: int) -> None:
    """Simulated slaves, Data_Exchange replies remembered (see the module docstring)."""
    line = SimLine(DpSlave(FIRST + i, EchoSim(SIZE)) for i in range(slaves))
    known: dict[bytes, bytes] = {}
    while True:
        chunk = os.read(fd, 4096)
        if not chunk:
            return
        reply = known.get(chunk)
        if reply is not None and not line.decoder.buffered:
            os.write(fd, reply)
            continue
        outgoing = line.receive(chunk, time.monotonic())
        for out in outgoing:
            os.write(fd, out.data)
        if len(outgoing) == 1 and _is_exchange(chunk):
            known[chunk] = outgoing[0].data


def _serve_paced(fd: int, slaves: int, baudrate: int) -> None:
    """:func:`_serve_slaves` paced like a line at ``baudrate``: each reply is written when
    its last byte would have come in on a real line, the request's line time, the slave's
    minimum station delay (11 bit times) and the reply's line time after the request was
    read. A pty carries bytes at once, so without this a reply comes in while the master's
    own request is still on the line by its clock, and the master waits out the rest of
    that line time after the reply, which no real line makes it do."""
    line = SimLine(DpSlave(FIRST + i, EchoSim(SIZE)) for i in range(slaves))
    bit = 1 / baudrate
    while True:
        chunk = os.read(fd, 4096)
        if not chunk:
            return
        at = time.monotonic()
        outgoing = line.receive(chunk, at)
        at += 11 * bit * len(chunk) + 11 * bit
        for out in outgoing:
            at += 11 * bit * len(out.data)
            time.sleep(max(0.0, at - time.monotonic()))
            os.write(fd, out.data)


def _serve_raw(fd: int, request_len: int, reply: bytes) -> None:
    buf = bytearray()
    while True:
        chunk = os.read(fd, 4096)
        if not chunk:
            return
        buf += chunk
        while len(buf) >= request_len:
            del buf[:request_len]
            os.write(fd, reply)


@dataclass(frozen=True)
class Placement:
    """The CPU of the requesters (this process) and the CPU of the responders (children)."""

    requester: frozenset[int]
    responder: frozenset[int]


def placement() -> Placement | None:
    """Two CPUs this process may use, or None (fewer than two: nothing to pin)."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    return Placement(frozenset(cpus[:1]), frozenset(cpus[1:2]))


@contextlib.contextmanager
def _pinned(where: Placement | None) -> Any:
    """This process on the requester CPU while inside; its old affinity afterwards."""
    if where is None:
        yield
        return
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, where.requester)
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def _responder(cpus: frozenset[int] | None, target: Callable[..., None], *args: Any) -> None:
    if cpus is not None:
        os.sched_setaffinity(0, cpus)
    target(*args)


@contextlib.contextmanager
def _child(target: Callable[..., None], *args: Any, where: Placement | None = None) -> Any:
    """A pty pair: ``target(master_fd, *args)`` in a child process (on the responder CPU
    of ``where``), the slave path for us."""
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    tty.setraw(master_fd)
    ctx = multiprocessing.get_context("fork")
    cpus = where.responder if where is not None else None
    proc = ctx.Process(target=_responder, args=(cpus, target, master_fd, *args), daemon=True)
    proc.start()
    try:
        yield os.ttyname(slave_fd)
    finally:
        proc.terminate()
        proc.join(5)
        os.close(master_fd)
        os.close(slave_fd)


@contextlib.contextmanager
def _open_raw(path: str) -> Any:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)
        termios.tcflush(fd, termios.TCIOFLUSH)  # a reply left over from an earlier run
        yield fd
    finally:
        os.close(fd)


# ---------------------------------------------------------------------------------------
# counting


class Windows:
    """Completions counted in windows of at least :data:`WINDOW` seconds.

    The host's noise (other guests, steal time, a wake-up that comes late) only ever slows
    a stretch of a round down, by a factor that changes from one stretch to the next. The
    rate of the best window, and the least CPU time per completion of any window, are
    what the code can do on this transport; master and reference are counted the same way,
    each at its own completions (docs/decisions/0021-bench-windows-and-medians.md).
    """

    def __init__(
        self,
        clock: Callable[[], float] = time.perf_counter,
        cpu_clock: Callable[[], float] = time.process_time,
    ) -> None:
        self._clock = clock
        self._cpu_clock = cpu_clock
        self._marks: list[tuple[float, float, int]] = []
        self._next = 0.0

    def tick(self, done: int) -> None:
        """``done`` completions so far; a window closes at the first tick after its end."""
        now = self._clock()
        if now >= self._next:
            self._marks.append((now, self._cpu_clock(), done))
            self._next = now + WINDOW

    def _spans(self) -> list[tuple[float, float, int]]:
        return [
            (t2 - t1, c2 - c1, n2 - n1)
            for (t1, c1, n1), (t2, c2, n2) in itertools.pairwise(self._marks)
            if n2 > n1
        ]

    def best_rate(self) -> float:
        """Completions per second in the best window (0.0 before a whole window)."""
        return max((n / wall for wall, _, n in self._spans()), default=0.0)

    def least_cpu(self) -> float:
        """This process's CPU seconds per completion, in the window that needed the least."""
        return min((cpu / n for _, cpu, n in self._spans()), default=math.nan)


# ---------------------------------------------------------------------------------------
# bare requesters


def blocking_round_trips(fd: int, requests: list[bytes], reply_len: int, duration: float) -> float:
    """Round trips per second without an event loop: write, read the whole reply, again."""
    os.set_blocking(fd, True)
    done = 0
    windows = Windows()
    windows.tick(done)
    end = time.perf_counter() + duration
    while time.perf_counter() < end:
        for request in requests:
            os.write(fd, request)
            got = 0
            while got < reply_len:
                if not select.select([fd], [], [], REPLY_TIMEOUT)[0]:
                    raise RuntimeError(f"no {reply_len}-byte reply within {REPLY_TIMEOUT} s")
                got += len(os.read(fd, 4096))
            done += 1
            windows.tick(done)
    return windows.best_rate()


@dataclass
class RawRun:
    round_trips_per_s: float
    cpu_per_round_trip: float  # s, this process


async def loop_round_trips(
    fd: int, requests: list[bytes], reply_len: int, duration: float
) -> RawRun:
    """Round trips on the event loop: ``add_reader``, non-blocking write, nothing else."""
    loop = asyncio.get_running_loop()
    os.set_blocking(fd, False)
    finished: asyncio.Future[None] = loop.create_future()
    state = {"got": 0, "done": 0, "next": 0}
    end = loop.time() + duration

    def send() -> None:
        request = requests[state["next"]]
        state["next"] = (state["next"] + 1) % len(requests)
        os.write(fd, request)

    def readable() -> None:
        try:
            state["got"] += len(os.read(fd, 4096))
        except BlockingIOError:
            return
        if state["got"] < reply_len:
            return
        state["got"] -= reply_len
        state["done"] += 1
        windows.tick(state["done"])
        if loop.time() >= end:
            if not finished.done():
                finished.set_result(None)
            return
        send()

    windows = Windows()
    windows.tick(0)
    loop.add_reader(fd, readable)
    try:
        send()
        await asyncio.wait_for(finished, duration + REPLY_TIMEOUT)
    finally:
        loop.remove_reader(fd)
    return RawRun(windows.best_rate(), windows.least_cpu())


# ---------------------------------------------------------------------------------------
# the master


@dataclass
class MasterRun:
    cycles_per_s: float
    cpu_per_cycle: float  # s
    turnaround: float  # s, median: reply in -> next request out
    cpu_per_exchange: float = math.nan  # s: the whole measured stretch's CPU / exchanges
    lateness: list[float] = dataclasses.field(default_factory=list)  # s, written - not_before
    exchanges: int = 0  # in the measured stretch
    seconds: float = 0.0  # the measured stretch, wall
    cpu: float = 0.0  # s, this process's CPU time over the measured stretch
    sleeps: float = math.nan  # the loop thread's sleeps (voluntary switches) per exchange


def _params(slaves: int) -> list[SlaveParams]:
    return [
        SlaveParams(
            address=FIRST + i,
            ident_number=ECHO_IDENT,
            cfg=echo_cfg(SIZE),
            input_len=SIZE,
            output_len=SIZE,
            watchdog=None,  # the bare requester takes over afterwards
        )
        for i in range(slaves)
    ]


async def run_master(
    path: str, slaves: int, duration: float, bus: BusParams = BUS, settle: float = SETTLE
) -> MasterRun:
    loop = asyncio.get_running_loop()
    master = Master(bus, _params(slaves), loop.time())
    exchanges = 0
    turnarounds: list[float] = []
    windows: Windows | None = None  # while measuring

    def on_action(action: Any) -> None:
        nonlocal exchanges
        if isinstance(action, InputsReceived):
            exchanges += 1
            master.set_outputs(action.address, OUTPUTS)  # what an adapter does each cycle
            if windows is not None:
                windows.tick(exchanges)

    link = await open_link(path, bus.baudrate, loop, lambda d, n: None, lambda e: None)
    driver = LineDriver(master, link, on_action)
    _time_turnaround(link, turnarounds)
    lateness = _time_lateness(driver)
    try:
        driver.start()
        async with asyncio.timeout(10):
            # The bench drives the engine without a hub: poll its states.
            while not all(master.state_of(a) is SlaveState.DATA_EXCHANGE for a in master.addresses):  # noqa: ASYNC110
                await asyncio.sleep(0.01)
        await asyncio.sleep(settle)
        turnarounds.clear()
        lateness.clear()
        measured = windows = Windows()
        windows.tick(exchanges)
        first, cpu, wall = exchanges, time.process_time(), time.perf_counter()
        switches = _sleeps()
        await asyncio.sleep(duration)
        cpu, done = time.process_time() - cpu, exchanges - first
        switches = _sleeps() - switches
        wall = time.perf_counter() - wall
        windows = None
    finally:
        driver.stop()
        await link.aclose()
    return MasterRun(
        measured.best_rate(),
        measured.least_cpu(),
        statistics.median(turnarounds) if turnarounds else math.nan,  # a stalled host
        cpu / done if done else math.nan,
        lateness,
        done,
        wall,
        cpu,
        switches / done if done else math.nan,
    )


def _sleeps() -> int:
    """The times this thread (the loop's) went to sleep so far: its voluntary context
    switches (getrusage(2), RUSAGE_THREAD on Linux, the process elsewhere)."""
    who = getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)
    return resource.getrusage(who).ru_nvcsw


def _time_lateness(driver: LineDriver) -> list[float]:
    """Wrap the driver's codec: each request's write time against its ``not_before``."""
    stream = driver.stream
    due: collections.deque[float] = collections.deque()
    out: list[float] = []
    transmission = stream.transmission
    written = stream.written

    def timed_transmission(action: Any) -> Transmission | None:
        t = transmission(action)
        if t is not None:
            due.append(t.not_before)
        return t

    def timed_written(at: float) -> Any:
        if due:
            out.append(at - due.popleft())
        return written(at)

    stream.transmission = timed_transmission  # type: ignore[method-assign]
    stream.written = timed_written  # type: ignore[method-assign]
    return out


def _time_turnaround(link: SerialLink, out: list[float]) -> None:
    """Wrap the link: when a reply's bytes come in, when the next request goes out."""
    on_data = link.on_data
    write = link.write
    rx_at = [0.0]

    def timed_data(data: bytes, now: float) -> None:
        rx_at[0] = time.perf_counter()
        on_data(data, now)

    def timed_write(data: bytes) -> None:
        if rx_at[0]:
            out.append(time.perf_counter() - rx_at[0])
            rx_at[0] = 0.0
        write(data)

    link.on_data = timed_data
    link.write = timed_write  # type: ignore[method-assign]


@dataclass
class Case:
    """The figures of one slave count: the median of each side's rounds."""

    master: MasterRun
    loop_raw: RawRun  # event-loop requester against the bare responder
    blocking_raw: float  # blocking requester against the bare responder
    peer_check: float  # blocking requester against the master's other end


def measure(
    slaves: int,
    where: Placement | None = None,
    rounds: int | None = None,
    seconds: float | None = None,
) -> Case:
    """Alternating rounds; ``where``: the CPU placement of every round (see the module
    docstring; None leaves it to the scheduler); ``rounds`` of ``seconds`` each side
    (:data:`ROUNDS`, :data:`MEASURE` when None)."""
    rounds = ROUNDS if rounds is None else rounds
    seconds = MEASURE if seconds is None else seconds
    frames = exchange_frames(slaves)
    runs: list[MasterRun] = []
    loop_raw: list[RawRun] = []
    blocking_raw: list[float] = []
    peer_check: list[float] = []
    with (
        _pinned(where),
        _child(_serve_raw, REQUEST_LEN, reply_frame(), where=where) as raw_path,
        _open_raw(raw_path) as raw,
        _child(_serve_slaves, slaves, where=where) as path,
    ):
        for _ in range(rounds):
            loop_raw.append(asyncio.run(loop_round_trips(raw, frames, REPLY_LEN, seconds)))
            runs.append(asyncio.run(run_master(path, slaves, seconds)))
            blocking_raw.append(blocking_round_trips(raw, frames, REPLY_LEN, seconds / 2))
            with _open_raw(path) as peer:
                peer_check.append(blocking_round_trips(peer, frames, REPLY_LEN, seconds / 2))
    median = statistics.median
    return Case(
        MasterRun(
            median(r.cycles_per_s for r in runs),
            median(r.cpu_per_cycle for r in runs),
            median(r.turnaround for r in runs),
        ),
        RawRun(
            median(r.round_trips_per_s for r in loop_raw),
            median(r.cpu_per_round_trip for r in loop_raw),
        ),
        median(blocking_raw),
        median(peer_check),
    )


# ---------------------------------------------------------------------------------------
# line timing honoured against timing off


TIMED_BUS: Final = BusParams.for_baudrate(
    500000, master_address=MASTER, latency=0.05, gc_period=0.1
)
TIMING_ROUNDS: Final = 6  # rounds of each of the four settings, alternating
TIMING_MEASURE: Final = 1.0  # s per round
TIMING_TARGET: Final = "ratio <= 1.5"


@dataclass
class TimingCase:
    """Medians of the rounds with 500 kbit/s timing honoured (``timed``) and with timing
    off (``untimed``: 12 Mbit/s, TSYN 2.75 us), and every request's lateness (all rounds)."""

    timed: MasterRun
    untimed: MasterRun
    lateness: list[float]
    # the same two against slaves paced like a 500 kbit/s line (:func:`_serve_paced`)
    paced: MasterRun
    paced_untimed: MasterRun
    paced_lateness: list[float]
    # s: CPU per blocking sleep of TSYN here, beyond the call (median, one per round)
    sleep: float = math.nan


def measure_timing(slaves: int, where: Placement | None = None) -> TimingCase:
    """CPU per exchange with the line's timing kept, against timing off, alternating
    rounds; the same against slaves paced like the line, whose replies come when a real
    line's would (the master idles for the request's and the reply's line time)."""
    runs: dict[str, list[MasterRun]] = collections.defaultdict(list)
    sleeps: list[float] = []
    with (
        _pinned(where),
        _child(_serve_slaves, slaves, where=where) as path,
        _child(_serve_paced, slaves, TIMED_BUS.baudrate, where=where) as paced,
    ):
        for _ in range(TIMING_ROUNDS):
            for name, port, bus in (
                ("untimed", path, BUS),
                ("timed", path, TIMED_BUS),
                ("paced_untimed", paced, BUS),
                ("paced", paced, TIMED_BUS),
            ):
                runs[name].append(asyncio.run(run_master(port, slaves, TIMING_MEASURE, bus)))
            sleep, call = sleep_cpu()  # with the slack the driver set (precise_sleeps)
            sleeps.append(sleep - call)
    return TimingCase(
        _median_run(runs["timed"]),
        _median_run(runs["untimed"]),
        [x for r in runs["timed"] for x in r.lateness],
        _median_run(runs["paced"]),
        _median_run(runs["paced_untimed"]),
        [x for r in runs["paced"] for x in r.lateness],
        statistics.median(sleeps),
    )


def _median_run(runs: list[MasterRun]) -> MasterRun:
    """The medians of the rounds that exchanged at all (a round whose slaves dropped out
    on a loaded host, their replies late past the slot time, has no CPU per exchange)."""
    runs = [r for r in runs if r.exchanges] or runs
    median = statistics.median
    return MasterRun(
        median(r.cycles_per_s for r in runs),
        median(r.cpu_per_cycle for r in runs),
        median(r.turnaround for r in runs),
        median(r.cpu_per_exchange for r in runs),
        sleeps=median(r.sleeps for r in runs),
    )


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``, nearest rank."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def _timing_figures(slaves: int, case: TimingCase) -> list[Figure]:
    cond = (
        f"{slaves} slave(s) in a child process on a pty, 8 bytes I/O each; master CPU time "
        f"(process time) over {TIMING_MEASURE:g} s / exchanges, median of {TIMING_ROUNDS} "
        "alternating rounds"
    )
    figures = [
        Figure(
            f"profibus_timed_cpu_per_exchange_{slaves}_slaves",
            case.timed.cpu_per_exchange * 1e6,
            "us",
            reference=case.untimed.cpu_per_exchange * 1e6,
            target=TIMING_TARGET,
            note=f"500 kbit/s timing honoured (TSYN and line time: under 100 us slept in the "
            "step, longer on a timerfd), slaves unpaced (a reply comes while the request "
            "is still on the line by its line time); reference: "
            f"timing off (12 Mbit/s); {cond}",
        ),
        Figure(
            f"profibus_timed_exchanges_per_s_{slaves}_slaves",
            case.timed.cycles_per_s,
            "1/s",
            reference=case.untimed.cycles_per_s,
            note="best window; reference: timing off. At 500 kbit/s a 14-byte request's "
            "line time and TSYN (374 us) bound it near 2,670/s on a pty",
        ),
    ]
    figures += [
        Figure(
            f"profibus_paced_timed_cpu_per_exchange_{slaves}_slaves",
            case.paced.cpu_per_exchange * 1e6,
            "us",
            reference=case.paced_untimed.cpu_per_exchange * 1e6,
            note="500 kbit/s timing honoured against timing off, both against slaves paced "
            "like a 500 kbit/s line (each reply written when its last byte would come in); "
            f"what honouring the timing costs where the replies come as on a line; {cond}",
        ),
        Figure(
            f"profibus_paced_timed_exchanges_per_s_{slaves}_slaves",
            case.paced.cycles_per_s,
            "1/s",
            reference=case.paced_untimed.cycles_per_s,
            note="best window, slaves paced like a 500 kbit/s line; reference: timing off "
            "against the same slaves (requests sent without TSYN)",
        ),
    ]
    figures += _floor_figures(slaves, case)
    for lateness, kind in ((case.lateness, ""), (case.paced_lateness, "paced_")):
        for q, label in ((0.5, "p50"), (0.99, "p99"), (0.999, "p99_9")):
            figures.append(
                Figure(
                    f"profibus_{kind}timed_lateness_{label}_{slaves}_slaves",
                    percentile(lateness, q) * 1e6,
                    "us",
                    note=f"write time - not_before of each request at 500 kbit/s "
                    f"({len(lateness)} requests, all rounds"
                    f"{', slaves paced like the line' if kind else ''}); never negative",
                )
            )
    return figures


def _floor_figures(slaves: int, case: TimingCase) -> list[Figure]:
    """The least timed CPU per exchange this host allows a master that does not spin.

    Keeping the line's timing, the master sleeps more often per exchange than with timing
    off: TSYN after the reply (paced slaves), or the rest of the request's line time (a
    pty's unpaced reply comes early), where timing off may find the reply already in.
    A master whose only extra cost was those sleeps would need the untimed CPU plus the
    extra sleeps (voluntary switches of the loop thread, counted in the rounds) times
    the CPU of one sleep (:func:`bench.common.sleep_cpu`, measured in the same rounds);
    that is the reference of the ``..._against_floor`` figures, and the ``..._floor``
    figures are the timed/untimed ratio it gives. The sleep is timed at TSYN's length;
    the unpaced case's extra sleep lasts about 300 us and costs more on the test machine,
    so its floor is on the low side (docs/decisions/0024-profibus-timing-cost.md)."""
    sleep = case.sleep
    figures: list[Figure] = []
    for kind, timed, untimed in (
        ("", case.timed, case.untimed),
        ("paced_", case.paced, case.paced_untimed),
    ):
        extra = max(0.0, timed.sleeps - untimed.sleeps)
        least = untimed.cpu_per_exchange + extra * sleep
        note = (
            f"{'slaves paced like the line; ' if kind else 'unpaced slaves; '}sleeps per "
            f"exchange {timed.sleeps:.2f} with timing, {untimed.sleeps:.2f} without; one "
            f"sleep {sleep * 1e6:.1f} us of CPU on this host (select(2) of TSYN, beyond the "
            "call, median of the rounds); the floor = timing off's CPU + the extra sleeps' "
            "CPU, the least a master that does not spin can need here"
        )
        figures.append(
            Figure(
                f"profibus_{kind}timed_cpu_against_floor_{slaves}_slaves",
                timed.cpu_per_exchange * 1e6,
                "us",
                reference=least * 1e6,
                note=f"timed CPU per exchange against the floor: {note}",
            )
        )
        figures.append(
            Figure(
                f"profibus_{kind}timing_ratio_floor_{slaves}_slaves",
                least / untimed.cpu_per_exchange,
                "ratio",
                note=f"the least the {TIMING_TARGET!r} ratio can be here: {note}",
            )
        )
    return figures


# ---------------------------------------------------------------------------------------
# the master without I/O


class _NoLink:
    """Takes the driver's writes; the bench hands it the replies (no port, no event loop)."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.on_data: Callable[[bytes, float], None] = lambda data, now: None
        self.sent: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.sent.append(data)

    def wait_readable(self, timeout: float) -> bool:
        return False  # the replies come from the bench, never from waiting

    def read_now(self) -> None:
        return


ENGINE_MESSAGES: Final = 20000
# Without a line the replies come at once; at a real rate the driver would wait out the
# request's time on the line and TSYN before the next (15.6 us at 12 Mbit/s) and time that.
UNTIMED_BUS: Final = dataclasses.replace(BUS, baudrate=10**12)


async def engine_cost(slaves: int, messages: int = ENGINE_MESSAGES) -> float:
    """Seconds per message cycle of the master's own code (engine, decoder, driver).

    The replies come from the simulated slaves, each computed once and then replayed, so
    only the master's side is timed: what remains of a message cycle without the pty.
    """
    loop = asyncio.get_running_loop()
    master = Master(UNTIMED_BUS, _params(slaves), loop.time())
    link = _NoLink(loop)

    def on_action(action: Any) -> None:
        if isinstance(action, InputsReceived):
            master.set_outputs(action.address, OUTPUTS)

    driver = LineDriver(master, link, on_action)  # type: ignore[arg-type]
    line = SimLine(DpSlave(FIRST + i, EchoSim(SIZE)) for i in range(slaves))
    known: dict[bytes, list[bytes]] = {}

    def exchange(count: int) -> None:
        for _ in range(count):
            while not link.sent:
                driver.poke()
            request = link.sent.pop(0)
            replies = known.get(request)
            if replies is None:
                replies = [out.data for out in line.receive(request, loop.time())]
                if _is_exchange(request):
                    known[request] = replies
            for reply in replies:
                link.on_data(reply, loop.time())

    driver.start()
    try:
        async with asyncio.timeout(10):
            while not all(master.state_of(a) is SlaveState.DATA_EXCHANGE for a in master.addresses):
                exchange(1)
                await asyncio.sleep(0)
        exchange(2 * slaves + 100)
        start = time.perf_counter()
        exchange(messages)
        return (time.perf_counter() - start) / messages
    finally:
        driver.stop()


# ---------------------------------------------------------------------------------------
# a real line


def felser_cycle(slaves: int, baudrate: int) -> float:
    """T = (380 + 300 x slaves + 11 x bytes) x t_bit + 75 us, bytes = I/O of all slaves."""
    io_bytes = slaves * 2 * SIZE
    return (380 + 300 * slaves + 11 * io_bytes) / baudrate + 75e-6


def _engine_figure(slaves: int, cost: float) -> Figure:
    return Figure(
        f"profibus_master_own_time_per_msg_cycle_{slaves}_slaves",
        cost * 1e6,
        "us",
        note="engine, decoder and driver per message cycle, without the pty and the event loop",
    )


def _placed(where: Placement | None) -> str:
    if where is None:
        return "one CPU: placement left to the scheduler"
    return f"requesters on CPU {min(where.requester)}, responders on CPU {min(where.responder)}"


def _case_figures(
    slaves: int, case: Case, where: Placement | None = None, rounds: int | None = None
) -> list[Figure]:
    sizes = (
        f"{REQUEST_LEN} B request, {REPLY_LEN} B reply; {_placed(where)}; median of "
        f"{ROUNDS if rounds is None else rounds} rounds, each its best {WINDOW:g} s window"
    )
    return [
        Figure(
            f"profibus_master_msg_cycles_{slaves}_slaves",
            case.master.cycles_per_s,
            "1/s",
            reference=case.loop_raw.round_trips_per_s,
            target=TARGET,
            note=f"reference: bare event-loop requester, raw round trips over a pty, {sizes}",
        ),
        Figure(
            f"profibus_master_vs_blocking_raw_{slaves}_slaves",
            case.master.cycles_per_s,
            "1/s",
            reference=case.blocking_raw,
            note=f"reference: bare blocking requester (no event loop), {sizes}",
        ),
        Figure(
            f"profibus_peer_check_{slaves}_slaves",
            case.peer_check,
            "1/s",
            reference=case.blocking_raw,
            note="blocking requester against the master's simulated slaves vs the bare responder",
        ),
        Figure(
            f"profibus_master_cpu_per_msg_cycle_{slaves}_slaves",
            case.master.cpu_per_cycle * 1e6,
            "us",
            reference=case.loop_raw.cpu_per_round_trip * 1e6,
            note="master process CPU time (engine, driver, link) per message cycle; "
            "reference: the bare event-loop requester's CPU time per round trip",
        ),
        Figure(
            f"profibus_master_turnaround_{slaves}_slaves",
            case.master.turnaround * 1e6,
            "us",
            note="median, reply bytes in -> next request written",
        ),
    ]


def _line_figures(turnaround: dict[int, float]) -> list[Figure]:
    figures: list[Figure] = []
    for baudrate in (500000, 187500):
        kbit = f"{baudrate / 1000:g}k".replace(".", "_")
        for slaves, master_time in turnaround.items():
            bus = felser_cycle(slaves, baudrate)
            with_master = bus + slaves * master_time
            figures.append(
                Figure(
                    f"profibus_line_{kbit}_{slaves}_slaves_cycle",
                    with_master * 1e3,
                    "ms",
                    reference=bus * 1e3,
                    note="Felser estimate plus the master's turnaround; reference: estimate alone",
                )
            )
            figures.append(
                Figure(
                    f"profibus_line_{kbit}_{slaves}_slaves_efficiency",
                    bus / with_master,
                    "ratio",
                    note="Felser estimate / (estimate + the master's turnaround)",
                )
            )
    return figures


def run(
    slave_counts: tuple[int, ...] = SLAVE_COUNTS,
    timing_slave_counts: tuple[int, ...] = TIMING_SLAVE_COUNTS,
    rounds: int | None = None,
    seconds: float | None = None,
) -> list[Figure]:
    """Every figure; ``rounds`` and ``seconds`` are the message-cycle cases' (:data:`ROUNDS`
    and :data:`MEASURE` when None; the line timing cases keep theirs)."""
    figures: list[Figure] = []
    turnaround: dict[int, float] = {}
    where = placement()
    for slaves in timing_slave_counts:
        figures += _timing_figures(slaves, measure_timing(slaves, where))
    for slaves in slave_counts:
        case = measure(slaves, where, rounds, seconds)
        turnaround[slaves] = case.master.turnaround
        figures += _case_figures(slaves, case, where, rounds)
        figures.append(_engine_figure(slaves, asyncio.run(engine_cost(slaves))))
    return figures + _line_figures(turnaround)


# Slave addresses FIRST..FIRST + N - 1, at most 125 (EN 50170 / IEC 61158: DP slaves 0-125)
_slave_count = id_range(1, 126 - FIRST, f"slave counts (addresses {FIRST}..{FIRST}+N-1)")


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_profibus", __doc__)
    add_counts(
        parser,
        "--slaves",
        _slave_count,
        SLAVE_COUNTS,
        "echo slaves of each message-cycle case (none: no such case)",
        may_be_empty=True,
    )
    add_counts(
        parser,
        "--timing-slaves",
        _slave_count,
        TIMING_SLAVE_COUNTS,
        "echo slaves of each line timing case (none: no such case)",
        may_be_empty=True,
    )
    add_number(
        parser, "--rounds", ROUNDS, "rounds of each side per message-cycle case (the median counts)"
    )
    add_number(parser, "--seconds", MEASURE, "seconds measured per message-cycle round")
    args = parser.parse_args(argv)
    figures = run(tuple(args.slaves), tuple(args.timing_slaves), args.rounds, args.seconds)
    print_figures(figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
