"""Bench-only helpers of the full-plant benchmark (:mod:`bench.bench_plant`).

Nothing here is production code and nothing in ``gateway/`` or ``adapters/`` imports it:

- :mod:`bench.plant.canbus`: a cross-process CAN bus for the bench: a python-can bus class
  (interface name :data:`~bench.plant.canbus.INTERFACE`) over a Unix-domain socket to a
  broker process that arbitrates and paces the frames at the CAN bit time;
- :mod:`bench.plant.pbsim`: the simulated Profibus slaves of a config (the same line as
  ``drive-gateway sim profibus --config``) on a pty, each reply held for its line time;
- :mod:`bench.plant.launch`: runs ``drive-gateway`` (the daemon, or ``sim devicenet``) with
  the bench CAN bus registered, and for the daemon records each line's cycles (optionally
  under cProfile);
- :mod:`bench.plant.clients`: the Modbus TCP clients and the Zenoh subscriber.
"""

import os

PIN_ENV = "DRIVE_GATEWAY_BENCH_CPUS"
"""The CPUs a bench process keeps to (comma-separated), set by :mod:`bench.bench_plant`."""


def pin_from_env() -> None:
    """Keep this process on the CPUs :data:`PIN_ENV` names (first thing in a main, so every
    thread it starts inherits them)."""
    text = os.environ.get(PIN_ENV)
    if text:
        os.sched_setaffinity(0, {int(c) for c in text.split(",")})


REALTIME_ENV = "DRIVE_GATEWAY_BENCH_SIM_PRIORITY"
"""The SCHED_FIFO priority the Profibus slaves' simulator takes (set by
:mod:`bench.bench_plant`): it stands in for slaves whose ASIC answers in microseconds, so
that its own scheduling on a busy host is not counted as the master's turnaround."""


def realtime_from_env() -> None:
    """This process under SCHED_FIFO at :data:`REALTIME_ENV`'s priority, if set (and
    permitted: else it stays as it is, and says so)."""
    text = os.environ.get(REALTIME_ENV)
    if not text or int(text) <= 0:
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(text)))
    except OSError as exc:
        print(f"SCHED_FIFO {text} not permitted: {exc}", flush=True)
