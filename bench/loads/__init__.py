"""Bench-only helpers of the loads benchmark (:mod:`bench.bench_loads`).

Nothing here is production code and nothing in ``gateway/`` or ``adapters/`` imports it:

- :mod:`bench.loads.clients`: the network loads and the Modbus probe, each run as a child
  process (``python -m bench.loads.clients KIND ...``) so that its own CPU is not the
  gateway's;
- :mod:`bench.loads.gateway`: the demo gateway in the bench's own process (its config, its
  lines' counters, the hub's events, the process's RSS and log);
- :mod:`bench.loads.kinds`: each load, started and ended by the benchmark (child processes
  by pid, CAN floods from a thread on the lines' in-process channels).
"""
