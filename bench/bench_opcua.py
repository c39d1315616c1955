"""The OPC UA server under load: the plant's drives, client sessions subscribed at 100 ms,
and what it costs the fieldbus lines.

The plant of :mod:`bench.bench_plant` (Profibus DP, DeviceNet and CANopen lines paced at
their bit rates in their own processes, Modbus clients and a Zenoh subscriber) is run
twice in this run: without OPC UA (the reference), then with the ``[opcua]`` server on and
:data:`SESSIONS` asyncua client sessions (:mod:`bench.plant.opcua_clients`, a process of
their own), each subscribed at :data:`INTERVAL` s to four variables of every drive.

Figures:

- ``opcua_<line>_cycle_rate``: the line's cycles per second with OPC UA, its reference the
  same without, the mean of a run before and a run after (its note gives both: their ratio
  is the host's own spread between runs); target ratio >= 0.9;
- ``opcua_gateway_cpu_share``: the gateway process's CPU (share of one core) with OPC UA,
  its reference the same without; ``opcua_server_cpu_share``: the difference, what the OPC
  UA server and its sessions cost;
- ``opcua_notifications``: the data changes the sessions received per second in all (what
  the drives changed, at most one per item per interval);
- ``opcua_sessions_up``: the sessions subscribed before the window opened;
- ``opcua_host_busy``: the cores every process on the host used with OPC UA, its
  reference the same without (the client sessions' process is on the same host: when it
  fills the host, the simulators slow down and the lines' rates with them).

The plant's drives stand still (their readings hardly change), so the server's cost under
change is measured apart, in one process (:mod:`bench.opcua_changes`: ``opcua_changes_*``,
220 drives of which a quarter change every 100 ms, 10 sessions). When the whole plant does
not come up on the host, a smaller one (:data:`SMALLER`) is measured.

``python -m bench opcua`` (both parts); ``python -m bench.bench_opcua [--profibus N]
[--devicenet N] [--canopen N] [--sessions N] [--seconds S]`` (the plant part);
``python -m bench.opcua_changes`` (the change part).
"""

from __future__ import annotations

import math
import os
from typing import Any, Final

from bench import opcua_changes
from bench.bench_plant import (
    CANOPEN_NODES,
    DEVICENET_NODES,
    MEASURE,
    PROFIBUS_SLAVES,
    SHORT_MEASURE,
    Plant,
    StartupFailed,
    _cycles_in,
    measure,
)
from bench.common import Figure, add_number, arg_parser, print_figures

SESSIONS: Final = 10
INTERVAL: Final = 0.1  # s
SETTLE: Final = 10.0  # s: the sessions browse and subscribe to ~900 items each first
LINES: Final = ("profibus", "devicenet", "canopen")


def _rate(raw: dict[str, Any], line: str) -> float:
    cycles = _cycles_in(raw["cycles"].get(line, []), raw["t0"], raw["t1"])
    return len(cycles) / (raw["t1"] - raw["t0"]) if cycles else math.nan


def compare(without: Plant, with_opcua: Plant, again: Plant) -> list[Figure]:
    """Run the plants without, with, and again without OPC UA (the reference is the mean of
    the two runs without, so that a drift between runs does not count as the server's);
    the figures (module docstring)."""
    measure(without)
    measure(with_opcua)
    measure(again)
    ref, run, ref2 = without.raw, with_opcua.raw, again.raw
    figures = []
    drives = without.profibus + without.devicenet + without.canopen
    for line in LINES:
        if not getattr(without, line):
            continue
        first, second = _rate(ref, line), _rate(ref2, line)
        figures.append(
            Figure(
                f"opcua_{line}_cycle_rate",
                round(_rate(run, line), 2),
                "cycles/s",
                reference=round((first + second) / 2, 2),
                target="ratio >= 0.9",
                note=f"{drives} drives, {with_opcua.opcua_sessions} OPC UA sessions at "
                f"{INTERVAL:g} s; reference: the same plant without OPC UA, the mean of a run "
                f"before ({first:.2f}) and one after ({second:.2f}): their ratio "
                f"{second / first:.3f} is the host's own spread",
            )
        )
    figures.append(
        Figure(
            "opcua_gateway_cpu_share",
            round(run["cpu_share"], 3),
            "core",
            reference=round(ref["cpu_share"], 3),
            note="the gateway process; reference: without OPC UA",
        )
    )
    figures.append(
        Figure(
            "opcua_server_cpu_share",
            round(run["cpu_share"] - ref["cpu_share"], 3),
            "core",
            note="with minus without OPC UA: the server and its sessions",
        )
    )
    busy, ref_busy = run["others"]["host (all CPUs)"], ref["others"]["host (all CPUs)"]
    cpus = os.cpu_count() or 1
    figures.append(
        Figure(
            "opcua_host_busy",
            busy,
            "cores",
            reference=ref_busy,
            note=f"every process on the host, of {cpus} CPUs; the OPC UA client sessions' "
            f"process {run['others'].get('opcua-clients', math.nan)} core: a host near "
            f"{cpus} slows the simulators, so the lines' rates fall whatever the server costs",
        )
    )
    clients = run["clients"].get("opcua-clients", {})
    figures.append(
        Figure(
            "opcua_notifications",
            round(clients.get("notifications_per_s", math.nan), 1),
            "1/s",
            note=f"{clients.get('items')} monitored items in all; data changes received",
        )
    )
    figures.append(
        Figure(
            "opcua_sessions_up",
            clients.get("up_before_window", math.nan),
            "sessions",
            reference=with_opcua.opcua_sessions,
            target="ratio = 1",
            note=f"subscribed before the window; slowest {clients.get('subscribe_s_max')} s; "
            f"errors {clients.get('errors')}",
        )
    )
    return figures


def plants(seconds: float, sessions: int = SESSIONS, **sizes: int) -> tuple[Plant, Plant, Plant]:
    """Without OPC UA, with it, and without it again."""
    base: dict[str, Any] = {"seconds": seconds, "settle": SETTLE, **sizes}
    with_opcua = Plant(**base, opcua_sessions=sessions, opcua_interval=INTERVAL)
    return Plant(**base), with_opcua, Plant(**base)


SMALLER: Final = {"profibus": 32, "devicenet": 16, "canopen": 8}
"""The plant measured when the whole one does not come up (a small or shared host)."""


def run() -> list[Figure]:
    """The whole plant; if it does not come up within bench_plant's bound, that is a figure
    of its own and a smaller plant (:data:`SMALLER`) is measured instead."""
    seconds = float(
        os.environ.get(
            "BENCH_PLANT_SECONDS", SHORT_MEASURE if os.environ.get("BENCH_SHORT") else MEASURE
        )
    )
    figures: list[Figure] = opcua_changes.measure()
    for sizes in ({}, SMALLER):
        try:
            return figures + compare(*plants(seconds, **sizes))
        except StartupFailed as exc:
            drives = sum(sizes.values()) or PROFIBUS_SLAVES + DEVICENET_NODES + CANOPEN_NODES
            figures.append(
                Figure(
                    "opcua_drives_online",
                    math.nan,
                    "drives",
                    reference=drives,
                    note=f"the plant did not come up: {str(exc).splitlines()[0]}",
                )
            )
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_opcua", __doc__)
    add_number(parser, "--seconds", MEASURE, "seconds measured, in each run")
    parser.add_argument("--profibus", type=int, metavar="N", default=PROFIBUS_SLAVES)
    parser.add_argument("--devicenet", type=int, metavar="N", default=DEVICENET_NODES)
    parser.add_argument("--canopen", type=int, metavar="N", default=CANOPEN_NODES)
    parser.add_argument("--sessions", type=int, metavar="N", default=SESSIONS)
    args = parser.parse_args(argv)
    print_figures(
        compare(
            *plants(
                args.seconds,
                args.sessions,
                profibus=args.profibus,
                devicenet=args.devicenet,
                canopen=args.canopen,
            )
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
