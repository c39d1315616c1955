"""A whole plant on one gateway: every line paced at its bit rate, every front end loaded.

Processes (all on 127.0.0.1, each started and killed by pid):

- the gateway: ``drive-gateway run`` through :mod:`bench.plant.launch` (which registers the
  bench CAN bus and records each line's cycles), with the drives, lines and front ends below;
- Profibus DP: :data:`PROFIBUS_SLAVES` CFW700 drives (4 I/O words, manufacturer profile) at
  1.5 Mbit/s, master at address 0, slaves 1-125, cycle back to back; the slaves simulated
  in their own process on a pty (:mod:`bench.plant.pbsim`, the line of
  ``drive-gateway sim profibus --config``), each reply held for its line time;
- DeviceNet: :data:`DEVICENET_NODES` CFW-08 drives (polled, assembly 21/71) at 500 kbit/s:
  ``drive-gateway sim devicenet`` in its own process, on the bench CAN bus
  (:mod:`bench.plant.canbus`: a broker process that arbitrates and paces every frame at its
  bit time); the scanner's poll interval is its minimum (1 ms): cycles back to back;
- CANopen: :data:`CANOPEN_NODES` CiA 402 drives (velocity mode, the shipped EDS) at
  500 kbit/s: ``drive-gateway sim canopen`` in its own process, on a second bench CAN
  broker; the master's SYNC period is the line's physical minimum (:func:`canopen_line`);
- :data:`MODBUS_CLIENTS` Modbus TCP clients each polling every drive's status block at
  :data:`MODBUS_RATE` Hz, and one Zenoh subscriber to every drive's state
  (:mod:`bench.plant.clients`, one process each).

Figures, over the measured window (after every drive is online and a settling time):

- the gateway's CPU as a share of one core: its process's utime + stime
  (``/proc/<pid>/stat``) over the wall time; its RSS (``/proc/<pid>/status`` VmRSS);
- the same CPU by part (``plant_gateway_cpu_<part>``, reference: the process's total;
  :mod:`bench.plant.cpusplit`): each line's thread, the daemon's loop and its share per
  part (Modbus, Zenoh, web, hub, ...), Zenoh's own threads;
- each line's median cycle time against its physical minimum (the reference; target
  ratio <= 1.05). Profibus (Felser): the sum over the slaves of request and reply telegram
  bits (11 bits per character) + min TSDR + TSYN, plus the Global_Control broadcast
  (its telegram + TSYN every ``global_control_period``); DeviceNet: the bit-time sum of the
  frames the broker carried in the window (stuff bits counted exactly, see
  :func:`bench.plant.canbus.frame_bits`) divided by the cycles in it;
- each line's p99 cycle jitter: the 99th percentile of |cycle - median cycle|, against the
  median cycle (target ratio < 0.10);
- what the clients saw: polls per drive per second (reference: the rate asked) and Zenoh
  state samples per second over the drives that published;
- line diagnostics: the master's turnaround seen from the Profibus line (reply written ->
  next request read, against TSYN), how late the paced simulators and the CAN broker were;
  the turnaround's mean and p99 against its median (``plant_profibus_turnaround_mean``,
  ``_p99``; targets ratio <= 1.5 and <= 3), and beside them the pty's own round trip in
  the same window (:mod:`bench.plant.ptyprobe`, ``plant_pty_round_trip_p99`` against its
  median): the host's share of the turnaround's tail.

:func:`run` measures the plant twice: every line flat out (``plant_*``), then every line's
cycle at :data:`CYCLE_100MS` (``plant_100ms_*``: the CPU a steady plant costs).

``python -m bench.bench_plant [--seconds S] [--profibus N] [--devicenet N] [--canopen N] [--cycle S] [--profile F]``;
``make bench`` runs it with :data:`MEASURE` seconds (``BENCH_PLANT_SECONDS`` overrides, the
``--short`` flag of ``python -m bench`` gives :data:`SHORT_MEASURE`). Start-up is bounded
by :data:`STARTUP_BOUND`; the whole run stays within a couple of minutes.
``BENCH_DEVICENET_STATUS=S``: the CFW-08s' ``status_interval`` (their explicit status
reads; the adapter's default otherwise), to weigh those reads' share of the line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from adapters.link.ring import ring_mode
from adapters.profibus.codec.dp import DataExchange, build_request
from adapters.profibus.codec.fdl import DataTelegram, RequestFunction, ResponseFc, ResponseStatus
from adapters.profibus.master.timing import BITS_PER_CHAR, BusParams
from bench.common import Figure, add_number, arg_parser, positive_float, print_figures
from bench.plant import PIN_ENV, REALTIME_ENV, canbus, cpusplit
from tests.support.net import free_port

PROFIBUS_SLAVES: Final = 125
PROFIBUS_BAUD: Final = 1_500_000
PROFIBUS_WORDS: Final = 4  # CFW700 I/O words (P0922 = 3), in and out
MASTER_ADDRESS: Final = 0
DEVICENET_NODES: Final = 63
CAN_BITRATE: Final = 500_000
CANOPEN_NODES: Final = 32
CANOPEN_RPDO1_BYTES: Final = 4  # controlword + vl target velocity (INTEGER16 each)
CANOPEN_TPDO1_BYTES: Final = 8  # statusword + vl velocity actual + current + torque
MODBUS_CLIENTS: Final = 10
MODBUS_RATE: Final = 10.0  # Hz, every drive, every client
MEASURE: Final = 30.0  # s measured (make bench)
SHORT_MEASURE: Final = 8.0  # s measured with --short
CYCLE_100MS: Final = 0.1  # s: every line's cycle in the second run (the CPU target)
SETTLE: Final = 3.0  # s of full load before the window opens
PROFIBUS_WATCHDOG: Final = 2.0  # s, the slaves' (the config below)
STARTUP_BOUND: Final = 150.0  # s for every drive to come online (three lines on a loaded host)
STOP_BOUND: Final = 15.0  # s for a process to end after SIGTERM (then SIGKILL)
PY: Final = sys.executable
HERE: Final = Path(__file__).resolve().parent.parent


@dataclass
class Plant:
    """What one run starts; sizes can be made tiny (the test)."""

    profibus: int = PROFIBUS_SLAVES
    devicenet: int = DEVICENET_NODES
    canopen: int = CANOPEN_NODES
    modbus_clients: int = MODBUS_CLIENTS
    modbus_rate: float = MODBUS_RATE
    seconds: float = MEASURE
    settle: float = SETTLE
    profile: str | None = None  # cProfile stats of the gateway, written here
    # the gateway on one CPU, everything else on another (placement); off by default: on a
    # machine shared with other work it made every figure worse (the gateway could not move
    # away from a CPU another job held: 0.21 core but 15.6 x the Profibus minimum, 2.3 x on
    # DeviceNet, Modbus late, in a run beside the unpinned ones of
    # docs/decisions/0054-full-plant-benchmark.md)
    pin: bool = False
    opcua_sessions: int = 0
    """OPC UA client sessions subscribed to every drive (bench/bench_opcua.py); 0: the
    gateway serves no OPC UA."""
    opcua_interval: float = 0.1  # s, their subscriptions' publishing interval
    # every line's cycle (Profibus cycle_time, DeviceNet poll_interval, CANopen sync_period),
    # s; None: each line flat out (back to back, the SYNC at the line's minimum)
    cycle: float | None = None
    # the Profibus line's steady rings under SCHED_FIFO at this priority (ring_priority, as
    # the site template asks; decision 0104), and the Profibus slaves' simulator too (it
    # stands in for slaves that answer in microseconds); 0 (BENCH_PLANT_REALTIME=0): neither
    realtime: int = field(default_factory=lambda: int(os.environ.get("BENCH_PLANT_REALTIME", "10")))
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    logs: list[Any] = field(default_factory=list)
    raw: dict[str, Any] = field(default_factory=dict)
    """What :func:`measure` measured, for another benchmark to compare runs: the window,
    the gateway's CPU share, the lines' cycles and the clients' figures."""


# ---------------------------------------------------------------------- the physics


def bus_params() -> BusParams:
    return BusParams.for_baudrate(PROFIBUS_BAUD, master_address=MASTER_ADDRESS)


def exchange_bits(words: int = PROFIBUS_WORDS) -> tuple[int, int]:
    """Line bits of a Data_Exchange request and of its reply with ``words`` words each way."""
    data = bytes(2 * words)
    request = build_request(DataExchange(data), da=1, sa=MASTER_ADDRESS, fc=_srd())
    reply = DataTelegram(MASTER_ADDRESS, 1, ResponseFc(ResponseStatus.DL), data=data)
    return BITS_PER_CHAR * len(request.encode()), BITS_PER_CHAR * len(reply.encode())


def _srd() -> Any:
    from adapters.profibus.codec.fdl import FcbState

    return FcbState(fcb=True, fcv=True).fc(RequestFunction.SRD_HIGH)


def felser_cycle(slaves: int, bus: BusParams | None = None) -> float:
    """The physical minimum of a DP cycle, seconds (module docstring; fact sheet 1.1)."""
    bus = bus or bus_params()
    request, reply = exchange_bits()
    per_slave = request + reply + bus.min_tsdr + 33  # TSYN: 33 bit times before a request
    slaves_time = slaves * per_slave * bus.t_bit
    from adapters.profibus.codec.dp import GlobalControl, global_control_request

    gc = global_control_request(GlobalControl.operate(), sa=MASTER_ADDRESS).encode()
    gc_time = (BITS_PER_CHAR * len(gc) + 33) * bus.t_bit
    return slaves_time / (1.0 - gc_time / bus.global_control_period)


# ---------------------------------------------------------------------- the config


def _status_interval() -> list[str]:
    """The DeviceNet line's ``status_interval`` line where ``BENCH_DEVICENET_STATUS`` sets it."""
    value = os.environ.get("BENCH_DEVICENET_STATUS")
    return [] if not value else [f"status_interval = {float(value)!r}"]


def config_text(
    plant: Plant, tmp: Path, modbus_port: int, zenoh_port: int, opcua_port: int = 0
) -> str:
    lines = [
        "[gateway]",
        'name = "plant"',
        'log_level = "WARNING"',
        "[zenoh]",
        'prefix = "plant"',
        'mode = "peer"',
        f'listen = ["tcp/127.0.0.1:{zenoh_port}"]',
        "connect = []",
        "multicast_scouting = false",
        "[modbus]",
        f'bind = "127.0.0.1:{modbus_port}"',
        'allow = ["127.0.0.0/8"]',
    ]
    if plant.opcua_sessions:
        lines += [
            "[opcua]",
            f'bind = "127.0.0.1:{opcua_port}"',
            f"publish_interval = {plant.opcua_interval:g}",
        ]
    unit = 1
    if plant.profibus:
        lines += [
            "[buses.profibus]",
            'adapter = "profibus"',
            f'port = "{tmp / "profibus.tty"}"',
            f"baudrate = {PROFIBUS_BAUD}",
            f"master_address = {MASTER_ADDRESS}",
            f"cycle_time = {plant.cycle or 0.0!r}",
            f"watchdog = {PROFIBUS_WATCHDOG:g}",
            "latency = 0.05",
            "live_list_period = 0.0",
            f"ring_priority = {plant.realtime}",
        ]
        for address in range(1, plant.profibus + 1):
            lines += [
                "[[buses.profibus.drives]]",
                f'id = "pb{address}"',
                'device = "CFW700"',
                f"address = {address}",
                f"modbus_unit = {unit}",
                'data_profile = "manufacturer"',
                f"words = {PROFIBUS_WORDS}",
            ]
            unit += 1
    if plant.devicenet:
        lines += [
            "[buses.devicenet]",
            'adapter = "devicenet"',
            f'interface = "{canbus.INTERFACE}"',
            f'channel = "{tmp / "can.sock"}"',
            f"bitrate = {CAN_BITRATE}",
            "mac = 0",
            f"poll_interval = {plant.cycle or 0.001!r}",
            "expected_packet_rate = 0.5",
            *_status_interval(),
        ]
        for mac in range(1, plant.devicenet + 1):
            lines += [
                "[[buses.devicenet.drives]]",
                f'id = "dn{mac}"',
                'device = "CFW-08"',
                f"address = {mac}",
                f"modbus_unit = {unit}",
                "assembly = 21",
                'connection = "polled"',
                "max_rpm = 1800",
            ]
            unit += 1
    lines += canopen_line(plant, tmp, unit)
    return "\n".join(lines) + "\n"


def canopen_cycle(nodes: int) -> float:
    """The physical minimum of one SYNC cycle of the CANopen line, seconds: the bit-time
    sum of the SYNC and of every node's RPDO1 and TPDO1 (CiA 301 §7.2.2, §7.2.5), stuff
    bits counted exactly (:func:`bench.plant.canbus.frame_bits`) on the drives at
    standstill (every data byte 0). The frames' sizes are those the master maps for a
    CiA 402 drive of the shipped EDS in velocity mode: :data:`CANOPEN_RPDO1_BYTES`
    (controlword, vl target) and :data:`CANOPEN_TPDO1_BYTES` (statusword, vl actual,
    current, torque)."""
    from adapters.canopen.codec import frames

    bits = canbus.frame_bits(frames.COB_SYNC, b"")
    for node in range(1, nodes + 1):
        bits += canbus.frame_bits(frames.rpdo_id(1, node), bytes(CANOPEN_RPDO1_BYTES))
        bits += canbus.frame_bits(frames.tpdo_id(1, node), bytes(CANOPEN_TPDO1_BYTES))
    return bits / CAN_BITRATE


def canopen_sync_period(nodes: int) -> float:
    """The line's ``sync_period``: the shortest the configuration takes for these drives
    (``adapters.canopen.options.min_sync_period``: the same frames at worst-case bit
    stuffing, a little longer than :func:`canopen_cycle`'s exact count at standstill),
    rounded up to the microsecond."""
    from adapters.can.bits import frame_bits
    from adapters.canopen.options import SYNC_FLOOR

    bits = frame_bits(0) + nodes * (
        frame_bits(CANOPEN_RPDO1_BYTES) + frame_bits(CANOPEN_TPDO1_BYTES)
    )
    return max(SYNC_FLOOR, math.ceil(round(bits / CAN_BITRATE * 1e6, 6)) / 1e6)


def canopen_line(plant: Plant, tmp: Path, first_unit: int) -> list[str]:
    """The CANopen line: ``plant.canopen`` CiA 402 drives (node ids 1..n, the shipped EDS,
    velocity mode) on their own bench CAN broker at :data:`CAN_BITRATE`, SYNC-driven
    (``Master._cycle`` at every SYNC: the line's cycle is ``sync_period``, set to the line's
    physical minimum, :func:`canopen_sync_period`); units from ``first_unit``."""
    if not plant.canopen:
        return []
    lines = [
        "[buses.canopen]",
        'adapter = "canopen"',
        f'interface = "{canbus.INTERFACE}"',
        f'channel = "{tmp / "canopen.sock"}"',
        f"bitrate = {CAN_BITRATE}",
        f"sync_period = {plant.cycle or canopen_sync_period(plant.canopen)!r}",
    ]
    for node in range(1, plant.canopen + 1):
        lines += [
            "[[buses.canopen.drives]]",
            f'id = "co{node}"',
            'device = "CiA 402"',
            f"address = {node}",
            f"modbus_unit = {first_unit + node - 1}",
            'eds = "eds/cia402-drive.eds"',
            "max_rpm = 1800",
        ]
    return lines


# ---------------------------------------------------------------------- processes


def placement() -> tuple[frozenset[int], frozenset[int]] | None:
    """(the gateway's CPU, the other processes' CPU), or None with fewer than two CPUs."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    return frozenset(cpus[:1]), frozenset(cpus[1:2])


def _start(plant: Plant, name: str, argv: list[str], tmp: Path, **kw: Any) -> None:
    log = open(tmp / f"{name}.log", "wb")  # noqa: SIM115 - closed in _stop_all
    plant.logs.append(log)
    where = placement() if plant.pin else None
    env = dict(os.environ)
    if where is not None:  # bench.plant.pin_from_env, before the child starts a thread
        cpus = where[0] if name == "gateway" else where[1]
        env[PIN_ENV] = ",".join(str(c) for c in sorted(cpus))
    if name in ("profibus-sim", "pty-probe"):  # bench.plant.realtime_from_env
        env[REALTIME_ENV] = str(plant.realtime)
    plant.procs[name] = subprocess.Popen(
        argv, cwd=HERE, stdout=kw.pop("stdout", log), stderr=log, env=env, **kw
    )


class WaitTimeout(RuntimeError):
    """What was waited for did not come within its bound."""


def _wait(what: str, ready: Any, bound: float, plant: Plant, tmp: Path) -> None:
    end = time.monotonic() + bound
    while not ready():
        for name, proc in plant.procs.items():
            if proc.poll() is not None:
                text = (tmp / f"{name}.log").read_text(errors="replace")[-2000:]
                raise RuntimeError(f"{name} ended ({proc.returncode}) before {what}:\n{text}")
        if time.monotonic() > end:
            raise WaitTimeout(f"no {what} within {bound:g} s")
        time.sleep(0.1)


def _wait_online(plant: Plant, tmp: Path, record: Path, drives: int) -> None:
    """Every drive online within STARTUP_BOUND; else an error with the count on each bus."""

    def all_online() -> bool:
        doc = _read_json(record)
        return bool(doc) and doc["online"] == drives

    try:
        _wait(f"all {drives} drives online", all_online, STARTUP_BOUND, plant, tmp)
    except WaitTimeout as exc:
        by_bus = (_read_json(record) or {}).get("online_by_bus")
        log = (tmp / "gateway.log").read_text(errors="replace")[-1500:]
        raise StartupFailed(
            f"{exc}; online by bus: {by_bus}; the gateway's log ends:\n{log}"
        ) from None


def _stop_all(plant: Plant) -> None:
    """SIGTERM every process started, by pid; SIGKILL what has not ended in STOP_BOUND."""
    for proc in plant.procs.values():
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
    end = time.monotonic() + STOP_BOUND
    for proc in plant.procs.values():
        try:
            proc.wait(max(0.1, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait()
    for log in plant.logs:
        log.close()
    plant.logs.clear()


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


def _host_busy() -> tuple[int, int]:
    """(busy, total) jiffies of all CPUs (/proc/stat): what else ran on the machine."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle, iowait
    return sum(fields) - idle, sum(fields)


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _broker_log(tmp: Path, name: str) -> tuple[Any, Any]:
    """A CAN broker's frame log (or None) and its figures (or None)."""
    log = canbus.load_log(str(tmp / name)) if (tmp / f"{name}.ends").exists() else None
    return log, _read_json(tmp / f"{name}.json")


@contextlib.contextmanager
def _plant(plant: Plant) -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="plant-") as name:
        try:
            yield Path(name)
        finally:
            _stop_all(plant)


def _start_broker(plant: Plant, tmp: Path, name: str, socket: str, what: str) -> Path:
    """A bench CAN broker process (:mod:`bench.plant.canbus`) named ``name`` on ``socket``
    (the one the gateway's config names), its frame log beside it; the socket's path once
    it listens."""
    sock = tmp / socket
    _start(
        plant,
        name,
        [
            *(PY, "-m", "bench.plant.canbus", "--path", str(sock)),
            *("--bitrate", str(CAN_BITRATE), "--out", str(tmp / name)),
        ],
        tmp,
    )
    _wait(what, sock.exists, 20, plant, tmp)
    return sock


def _start_lines(plant: Plant, tmp: Path, config: Path) -> None:
    launch = [PY, "-m", "bench.plant.launch"]
    if plant.devicenet:
        sock = _start_broker(plant, tmp, "canbus", "can.sock", "the CAN broker")
        nodes = f"1-{plant.devicenet}" if plant.devicenet > 1 else "1"
        _start(
            plant,
            "devicenet-sim",
            [
                *(*launch, "--", "sim", "devicenet", "--interface", canbus.INTERFACE),
                *("--channel", str(sock), "--nodes", nodes, "--assembly", "21"),
                *("--log-level", "WARNING"),
            ],
            tmp,
        )
    if plant.canopen:
        sock = _start_broker(plant, tmp, "canopen-bus", "canopen.sock", "the CANopen broker")
        node_args = [a for n in range(1, plant.canopen + 1) for a in ("--node", str(n))]
        _start(
            plant,
            "canopen-sim",
            [
                *(*launch, "--", "sim", "canopen", "--interface", canbus.INTERFACE),
                *("--channel", str(sock), *node_args, "--log-level", "WARNING"),
            ],
            tmp,
        )
    if plant.profibus:
        link = tmp / "profibus.tty"
        _start(
            plant,
            "profibus-sim",
            [
                *(PY, "-m", "bench.plant.pbsim", "--config", str(config)),
                *("--baud", str(PROFIBUS_BAUD), "--link", str(link)),
                *("--out", str(tmp / "profibus-sim.json")),
            ],
            tmp,
        )
        _wait("the Profibus pty", link.exists, 20, plant, tmp)


# ---------------------------------------------------------------------- figures


def _cycles_in(cycles: list[list[float]], t0: float, t1: float) -> list[float]:
    return [seconds for end, seconds in cycles if t0 <= end < t1]


def _gc_figure(pauses: list[list[float]], window: float) -> Figure:
    """The gateway's longest garbage-collection pause in the window, and how much there was."""
    longest = max((p[2] for p in pauses), default=0.0)
    by_gen = {g: sum(1 for p in pauses if p[1] == g) for g in (0, 1, 2)}
    total = sum(p[2] for p in pauses)
    return Figure(
        "plant_gateway_gc_pause_max",
        round(longest * 1e3, 3),
        "ms",
        note=(
            f"collections per generation {by_gen}, {total / window * 100:.2f} % of the time "
            "(a pause holds every line's loop)"
        ),
    )


def _line_errors(lines: list[dict[str, int]] | None) -> str:
    """The Profibus lines' error counters, summed, for a note (a long cycle of a line
    that repeats requests is the protocol's, not the host's)."""
    if not lines:
        return ""
    total: dict[str, int] = {}
    for counters in lines:
        for name, count in counters.items():
            total[name] = total.get(name, 0) + count
    listed = ", ".join(f"{name} {count}" for name, count in total.items())
    return f"; the line's errors over the whole run (come-up included): {listed}"


def _jitter_p99(cycles: list[float]) -> tuple[float, float]:
    """(median cycle, p99 of |cycle - median|), seconds."""
    median = statistics.median(cycles)
    dev = sorted(abs(c - median) for c in cycles)
    return median, dev[min(len(dev) - 1, int(0.99 * len(dev)))]


def _line_figures(
    name: str, cycles: list[float], minimum: float, note: str, extra: str = ""
) -> list[Figure]:
    if not cycles:
        return [Figure(f"plant_{name}_cycle", math.nan, "ms", note="no cycle in the window")]
    median, jitter = _jitter_p99(cycles)
    return [
        Figure(
            f"plant_{name}_cycle",
            round(median * 1e3, 3),
            "ms",
            reference=round(minimum * 1e3, 3),
            target="ratio <= 1.05",
            note=f"median of {len(cycles)} cycles; reference: {note}{extra}",
        ),
        Figure(
            f"plant_{name}_jitter_p99",
            round(jitter * 1e3, 3),
            "ms",
            reference=round(median * 1e3, 3),
            target="ratio < 0.10",
            note="p99 of |cycle - median|; reference: the median cycle",
        ),
    ]


def _start_clients(plant: Plant, tmp: Path, drives: int, ports: tuple[int, int, int]) -> None:
    """The northbound load: Modbus clients, the Zenoh subscriber, OPC UA sessions."""
    modbus_port, zenoh_port, opcua_port = ports
    client_args = ["--settle", str(plant.settle), "--seconds", str(plant.seconds)]
    if plant.modbus_clients:
        _start(
            plant,
            "modbus-clients",
            [
                *(PY, "-m", "bench.plant.clients", "modbus", "--port", str(modbus_port)),
                *("--units", f"1-{drives}", "--clients", str(plant.modbus_clients)),
                *("--rate", str(plant.modbus_rate), *client_args),
            ],
            tmp,
            stdout=subprocess.PIPE,
        )
    _start(
        plant,
        "zenoh-subscriber",
        [
            *(PY, "-m", "bench.plant.clients", "zenoh"),
            *("--connect", f"tcp/127.0.0.1:{zenoh_port}", "--key", "plant/drives/*/state"),
            *client_args,
        ],
        tmp,
        stdout=subprocess.PIPE,
    )
    if plant.profibus:  # the pty's own floor beside the Profibus line (bench.plant.ptyprobe)
        _start(
            plant,
            "pty-probe",
            [PY, "-m", "bench.plant.ptyprobe", *client_args],
            tmp,
            stdout=subprocess.PIPE,
        )
    if plant.opcua_sessions:
        _start(
            plant,
            "opcua-clients",
            [
                *(PY, "-m", "bench.plant.opcua_clients"),
                *("--endpoint", f"opc.tcp://127.0.0.1:{opcua_port}/drive-gateway"),
                *("--sessions", str(plant.opcua_sessions)),
                *("--interval", str(plant.opcua_interval), *client_args),
            ],
            tmp,
            stdout=subprocess.PIPE,
        )


def measure(plant: Plant) -> list[Figure]:
    """Run the plant; the figures (module docstring)."""
    with _plant(plant) as tmp:
        modbus_port, zenoh_port, opcua_port = free_port(), free_port(), free_port()
        config = tmp / "plant.toml"
        config.write_text(config_text(plant, tmp, modbus_port, zenoh_port, opcua_port))
        _start_lines(plant, tmp, config)
        record = tmp / "gateway.json"
        gateway = [PY, "-m", "bench.plant.launch", "--record", str(record)]
        if plant.profile:
            gateway += ["--profile", plant.profile]
        _start(plant, "gateway", [*gateway, "--", "run", "--config", str(config)], tmp)
        drives = plant.profibus + plant.devicenet + plant.canopen

        started = time.monotonic()
        _wait_online(plant, tmp, record, drives)
        online_at = time.monotonic()
        load_before = os.getloadavg()
        _start_clients(plant, tmp, drives, (modbus_port, zenoh_port, opcua_port))
        pid = plant.procs["gateway"].pid
        time.sleep(plant.settle)
        t0, cpu0 = time.monotonic(), _cpu_seconds(pid)
        others0 = {n: _cpu_seconds(p.pid) for n, p in plant.procs.items() if p.poll() is None}
        host0 = _host_busy()
        time.sleep(plant.seconds)
        t1, cpu1 = time.monotonic(), _cpu_seconds(pid)
        others = {
            n: round((_cpu_seconds(plant.procs[n].pid) - c) / (t1 - t0), 3)
            for n, c in others0.items()
            if n != "gateway" and plant.procs[n].poll() is None
        }
        host = _host_busy()
        others["host (all CPUs)"] = round(
            (host[0] - host0[0]) / max(host[1] - host0[1], 1) * (os.cpu_count() or 1), 3
        )
        rss = _rss_mb(pid)
        load_after = os.getloadavg()
        clients: dict[str, Any] = {}
        for name in ("modbus-clients", "zenoh-subscriber", "opcua-clients", "pty-probe"):
            if name not in plant.procs:
                continue
            out, _ = plant.procs[name].communicate(timeout=plant.settle + 30)
            lines = out.decode().strip().splitlines()
            if not lines:  # it failed: its log says why
                text = (tmp / f"{name}.log").read_text(errors="replace")[-2000:]
                raise RuntimeError(f"{name} ended without its figures:\n{text}")
            clients[name] = json.loads(lines[-1])
        # the end: SIGTERM; the launcher writes the cycles, the simulators their figures
        _stop_all(plant)
        doc = _read_json(record) or {}
        cycles = doc.get("cycles", {"profibus": [], "devicenet": [], "canopen": []})
        gc_pauses = [p for p in doc.get("gc", []) if t0 <= p[0] < t1]
        profibus_errors = doc.get("profibus_errors", [])
        cpu_parts = cpusplit.split(doc.get("cpu", []), t0, t1)
        pbsim = _read_json(tmp / "profibus-sim.json")
        canlog, broker = _broker_log(tmp, "canbus")
        colog, cobroker = _broker_log(tmp, "canopen-bus")
    plant.raw.update(
        t0=t0,
        t1=t1,
        cpu_share=(cpu1 - cpu0) / (t1 - t0),
        cycles=cycles,
        clients=clients,
        others=others,
    )
    return _figures(
        plant,
        t0=t0,
        t1=t1,
        cpu_share=(cpu1 - cpu0) / (t1 - t0),
        rss=rss,
        cycles=cycles,
        pbsim=pbsim,
        canlog=canlog,
        broker=broker,
        colog=colog,
        cobroker=cobroker,
        clients=clients,
        load=(load_before, load_after),
        others=others,
        gc_pauses=gc_pauses,
        come_up=(started, online_at),
        profibus_errors=profibus_errors,
        cpu_parts=cpu_parts,
    )


def _figures(
    plant: Plant,
    *,
    t0: float,
    t1: float,
    cpu_share: float,
    rss: float,
    cycles: dict[str, list[list[float]]],
    pbsim: Any,
    canlog: Any,
    broker: Any,
    colog: Any,
    cobroker: Any,
    clients: dict[str, Any],
    load: tuple[tuple[float, ...], tuple[float, ...]],
    others: dict[str, float],
    gc_pauses: list[list[float]],
    come_up: tuple[float, float] | None = None,
    profibus_errors: list[dict[str, int]] | None = None,
    cpu_parts: dict[str, float] | None = None,
) -> list[Figure]:
    drives = plant.profibus + plant.devicenet + plant.canopen
    conditions = (
        f"{drives} drives; ring_priority {plant.realtime}; steady rings {ring_mode()}; "
        f"{os.cpu_count()} CPUs, load average {load[0][0]:.2f} before, "
        f"{load[1][0]:.2f} after; window {t1 - t0:.1f} s; CPU of the bench's other "
        f"processes and of the whole host, in cores: {json.dumps(others)}"
    )
    figures = [
        Figure(
            "plant_gateway_cpu",
            round(cpu_share, 4),
            "core",
            target="value < 0.25",
            note=f"gateway utime+stime / wall; {conditions}",
        ),
        Figure("plant_gateway_rss", round(rss, 1), "MiB", note="VmRSS at the end of the window"),
        _gc_figure(gc_pauses, t1 - t0),
        *_cpu_figures(cpu_parts, cpu_share),
    ]
    if come_up is not None:
        figures.append(_come_up_figure(come_up, cycles.get("profibus", [])))
    if plant.profibus:
        bus = bus_params()
        extra = ""
        if pbsim:
            turn = pbsim["master_turnaround"]
            figures += _turnaround_figures(turn, clients.get("pty-probe"))
            late = pbsim["reply_lateness"]
            extra = (
                f"; master turnaround seen on the line p50 {turn['p50_us']} us p99 "
                f"{turn['p99_us']} us mean {turn['mean_us']} us (TSYN {pbsim['tsyn_us']} us); "
                f"simulator reply lateness p50 {late['p50_us']} us p99 {late['p99_us']} us "
                f"mean {late['mean_us']} us"
            )
        request, reply = exchange_bits()
        pb = _cycles_in(cycles["profibus"], t0, t1)
        extra += f"; {len(pb) * plant.profibus / (t1 - t0):.0f} Data_Exchange/s"
        extra += _line_errors(profibus_errors)
        figures += _line_figures(
            f"profibus_{plant.profibus}_slaves_1500k",
            pb,
            felser_cycle(plant.profibus, bus),
            f"Felser: {plant.profibus} x ({request} + {reply} + TSDR {bus.min_tsdr} + TSYN 33) "
            "bits + Global_Control",
            extra,
        )
    if plant.devicenet:
        dn = _cycles_in(cycles["devicenet"], t0, t1)
        minimum = math.nan
        extra = ""
        if canlog is not None and dn:
            ends, bits = canlog
            carried = canbus.bits_between(ends, bits, t0, t1)
            minimum = carried / len(dn) / CAN_BITRATE
            extra = f"; bus load {carried / CAN_BITRATE / (t1 - t0):.3f}"
        if broker:
            late = broker["lateness_us"]
            extra += f"; broker lateness p50 {late['p50']} us p99 {late['p99']} us"
        extra += f"; {len(dn) * plant.devicenet / (t1 - t0):.0f} polls/s"
        figures += _line_figures(
            f"devicenet_{plant.devicenet}_nodes_500k",
            dn,
            minimum,
            "bit-time sum of the frames carried per cycle (stuffing exact)",
            extra,
        )
    if plant.canopen:
        co = _cycles_in(cycles.get("canopen", []), t0, t1)
        sync = plant.cycle or canopen_sync_period(plant.canopen)
        extra = f"; sync_period {sync * 1e3:.3f} ms"
        if colog is not None and co:
            ends, bits = colog
            carried = canbus.bits_between(ends, bits, t0, t1)
            extra += (
                f"; carried {carried / len(co):.0f} bit times per cycle (SYNC, TPDO1s, RPDO1s "
                f"on change, heartbeats); bus load {carried / CAN_BITRATE / (t1 - t0):.3f}"
            )
        if cobroker:
            late = cobroker["lateness_us"]
            extra += f"; broker lateness p50 {late['p50']} us p99 {late['p99']} us"
        extra += f"; {len(co) / (t1 - t0):.1f} SYNC cycles/s"
        figures += _line_figures(
            f"canopen_{plant.canopen}_nodes_500k",
            co,
            canopen_cycle(plant.canopen),
            f"bit-time sum of SYNC + {plant.canopen} RPDO1 ({CANOPEN_RPDO1_BYTES} bytes) + "
            f"{plant.canopen} TPDO1 ({CANOPEN_TPDO1_BYTES} bytes), stuffing exact on zero data",
            extra,
        )
    mb = clients.get("modbus-clients", {})
    if mb:
        figures.append(
            Figure(
                "plant_modbus_poll_rate",
                round(mb.get("polls_per_unit_per_s", math.nan), 3),
                "Hz",
                reference=plant.modbus_rate,
                target="ratio >= 0.99",
                note=(
                    f"{plant.modbus_clients} clients x {drives} units, FC4 x 21 registers; "
                    f"{mb.get('requests_per_s', 0):.0f} requests/s, {mb.get('exceptions')} "
                    f"exceptions, {mb.get('late_rounds')} late rounds, round p50 "
                    f"{mb.get('round_ms_p50') or math.nan:.1f} ms p99 "
                    f"{mb.get('round_ms_p99') or math.nan:.1f} ms"
                ),
            )
        )
    zn = clients.get("zenoh-subscriber", {})
    figures.append(
        Figure(
            "plant_zenoh_states",
            round(zn.get("samples_per_s", math.nan), 1),
            "samples/s",
            note=(
                f"one subscriber to plant/drives/*/state: {zn.get('keys')} of {drives} drives "
                f"seen, at least {zn.get('min_per_key')} samples each"
            ),
        )
    )
    return figures


def _cpu_figures(parts: dict[str, float] | None, total: float) -> list[Figure]:
    """The gateway's CPU by part (:mod:`bench.plant.cpusplit`), each against the process's
    total in the same window."""
    if not parts:
        return []
    threads = sum(v for k, v in parts.items() if not k.startswith("loop: "))
    note = (
        "cores, by thread and the loop's by the callbacks it ran "
        f"(bench/plant/cpusplit.py); all threads {threads:.3f} of the process's "
        f"{total:.3f}; {json.dumps(parts)}"
    )
    out = []
    for part, cores in sorted(parts.items()):
        slug = "".join(c if c.isalnum() else "_" for c in part).strip("_")
        slug = "_".join(w for w in slug.split("_") if w)
        out.append(
            Figure(f"plant_gateway_cpu_{slug}", cores, "core", reference=round(total, 4), note=note)
        )
    return out


def _turnaround_figures(
    turn: dict[str, float], probe: dict[str, float] | None = None
) -> list[Figure]:
    """The master's turnaround as the slave simulator sees it: mean and p99 against the
    median (issue targets: 1.5 x and 3 x); beside them the pty's own round trip in the
    same window (:mod:`bench.plant.ptyprobe`: the same two crossings of a pty, nothing of
    the master's in them), its p99 against its own median, and the turnaround's p99 less
    the probe's (what is left of the tail once the host's crossings are taken out)."""
    median = turn["p50_us"]
    note = f"Profibus master turnaround on the line (reply written -> next request read): {turn}"
    floor: list[Figure] = []
    if probe and probe.get("n"):
        note += f"; the pty's own round trip meanwhile (bench.plant.ptyprobe): {probe}"
        floor = [
            Figure(
                "plant_pty_round_trip_p99",
                probe["p99_us"],
                "us",
                reference=probe["p50_us"],
                note="a bare requester and echo on a pty of their own, at the simulator's "
                f"priority, in the plant's window: {probe}",
            ),
            Figure(
                "plant_profibus_turnaround_p99_less_pty",
                round(turn["p99_us"] - probe["p99_us"], 1),
                "us",
                reference=median,
                note="the turnaround's p99 less the pty round trip's p99 in the same window, "
                "against the turnaround's median",
            ),
        ]
    return [
        *floor,
        Figure(
            "plant_profibus_turnaround_mean",
            turn["mean_us"],
            "us",
            reference=median,
            target="ratio <= 1.5",
            note=note,
        ),
        Figure(
            "plant_profibus_turnaround_p99",
            turn["p99_us"],
            "us",
            reference=median,
            target="ratio <= 3",
            note=note,
        ),
    ]


def _come_up_figure(come_up: tuple[float, float], profibus: list[list[float]]) -> Figure:
    """How long every drive took to come online (from the gateway's start), and the
    Profibus cycles meanwhile against the slaves' watchdog (a longer cycle drops slaves
    already in data exchange: docs/decisions/0064-profibus-low-priority-budget.md)."""
    started, online = come_up
    during = [c for at, c in profibus if started <= at <= online]
    note = "from the gateway's start to every drive online"
    if during:
        over = sum(1 for c in during if c > PROFIBUS_WATCHDOG)
        note += (
            f"; Profibus cycles meanwhile: {len(during)}, the longest {max(during):.3f} s, "
            f"{over} over the slaves' {PROFIBUS_WATCHDOG:g} s watchdog"
        )
    return Figure(
        "plant_come_up", round(online - started, 1), "s", reference=STARTUP_BOUND, note=note
    )


class StartupFailed(RuntimeError):
    """Not every drive came online within STARTUP_BOUND (the count on each bus is said)."""


def run() -> list[Figure]:
    """The whole plant; if it does not come up within :data:`STARTUP_BOUND` (on a small or
    shared host the gateway's one core cannot carry the bring-up of three lines at once),
    that is a figure of its own, and the plant is measured in two parts, each with the
    clients: Profibus + DeviceNet (``plant_pbdn_*``) and the CANopen line (``plant_co_*``)."""
    seconds = float(
        os.environ.get(
            "BENCH_PLANT_SECONDS", SHORT_MEASURE if os.environ.get("BENCH_SHORT") else MEASURE
        )
    )
    return plant_figures("plant", seconds) + plant_figures("plant_100ms", seconds, CYCLE_100MS)


def plant_figures(prefix: str, seconds: float, cycle: float | None = None) -> list[Figure]:
    """The plant's figures, named ``<prefix>_*`` (whole, or in two parts: :func:`run`)."""

    def named(tag: str, figures: list[Figure]) -> list[Figure]:
        return [
            dataclasses.replace(f, name=f.name.replace("plant_", f"{tag}_", 1)) for f in figures
        ]

    try:
        return named(prefix, measure(Plant(seconds=seconds, cycle=cycle)))
    except StartupFailed as exc:
        figures = [_not_up(prefix, PROFIBUS_SLAVES + DEVICENET_NODES + CANOPEN_NODES, exc)]
    for tag, part in (
        ("pbdn", Plant(canopen=0, seconds=seconds, cycle=cycle)),
        ("co", Plant(profibus=0, devicenet=0, seconds=seconds, cycle=cycle)),
    ):
        try:
            figures += named(f"{prefix}_{tag}", measure(part))
        except StartupFailed as exc:
            figures.append(
                _not_up(f"{prefix}_{tag}", part.profibus + part.devicenet + part.canopen, exc)
            )
    return figures


def _not_up(prefix: str, drives: int, exc: StartupFailed) -> Figure:
    return Figure(
        f"{prefix}_drives_online",
        math.nan,
        "drives",
        reference=drives,
        note=f"did not come up: {exc}",
    )


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser(
        "bench_plant",
        __doc__,
        epilog=(
            f"make bench (python -m bench) runs it with these sizes for {MEASURE:g} s "
            f"(BENCH_PLANT_SECONDS overrides; python -m bench --short: {SHORT_MEASURE:g} s), "
            "and in two parts if the whole plant does not come up."
        ),
    )
    add_number(parser, "--seconds", MEASURE, "seconds measured")
    parser.add_argument(
        "--profibus", type=int, metavar="N", default=PROFIBUS_SLAVES, help="CFW700 DP slaves"
    )
    parser.add_argument(
        "--devicenet", type=int, metavar="N", default=DEVICENET_NODES, help="CFW-08 nodes"
    )
    parser.add_argument(
        "--canopen", type=int, metavar="N", default=CANOPEN_NODES, help="CiA 402 nodes"
    )
    parser.add_argument(
        "--modbus-clients",
        type=int,
        metavar="N",
        default=MODBUS_CLIENTS,
        help="Modbus TCP clients polling every drive",
    )
    parser.add_argument(
        "--modbus-rate",
        type=positive_float,
        metavar="HZ",
        default=MODBUS_RATE,
        help="polls per second of each drive by each client",
    )
    parser.add_argument(
        "--cycle",
        type=positive_float,
        metavar="S",
        default=None,
        help="every line's cycle (default: flat out; make bench also runs 0.1)",
    )
    parser.add_argument("--profile", help="write the gateway's cProfile stats here")
    parser.add_argument(
        "--pin",
        action="store_true",
        help="the gateway on one CPU, the simulators and clients on another",
    )
    args = parser.parse_args(argv)
    plant = Plant(
        profibus=args.profibus,
        devicenet=args.devicenet,
        canopen=args.canopen,
        modbus_clients=args.modbus_clients,
        modbus_rate=args.modbus_rate,
        seconds=args.seconds,
        profile=args.profile,
        pin=args.pin,
        cycle=args.cycle,
    )
    print_figures(measure(plant))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
