"""The gateway's CPU time by part, measured inside its process (:mod:`bench.plant.launch`).

By thread, from the kernel's per-thread CPU clocks:

- ``line <bus>``: each line's own thread (``line-<bus>``, gateway/runtime/linethread.py);
- ``loop``: the daemon's asyncio loop (the main thread): the hub, the Modbus server, the
  Zenoh front end's loop side, the web page and /metrics, logging;
- ``zenoh``: the Zenoh I/O worker thread (``zenoh-io ...``) and every thread Python did not
  start (Zenoh's native threads), read from ``/proc/self/task/<tid>/stat`` (10 ms ticks);
- ``other``: any other Python thread.

The loop's CPU by what it runs (:class:`LoopAccount`): the main thread's CPU clock read
around every callback of the daemon's loop, charged to the part of the callback's code (a task's outermost
coroutine, a transport's protocol, a function's own; :data:`PARTS` by file); ``loop: asyncio, epoll`` is what is
left of the loop's CPU (the selector, the loop's own bookkeeping, and the accounting's
own two clock reads per callback).
"""

from __future__ import annotations

import asyncio
import collections
import functools
import os
import sys
import threading
import time
from typing import Any, Final

TICK: Final = os.sysconf("SC_CLK_TCK")

PARTS: Final[tuple[tuple[str, str], ...]] = (
    ("/gateway/modbus/", "modbus"),
    ("/pymodbus/", "modbus"),
    ("/gateway/zenoh/", "zenoh"),
    ("/zenoh/", "zenoh"),
    ("/gateway/web/", "web"),
    ("/aiohttp/", "web"),
    ("/prometheus_client/", "web"),
    ("/gateway/runtime/lineport.py", "hub"),
    ("/gateway/hub.py", "hub"),
    ("/gateway/eventlog.py", "hub"),
    ("/logging/", "logging"),
    ("/bench/", "bench recorder"),
)
"""A code's file -> the part it belongs to (the first pattern found in its path)."""


def _group(thread: threading.Thread) -> str:
    name = thread.name
    if thread is threading.main_thread():
        return "loop"
    if name.startswith("line-"):
        return f"line {name[5:]}"
    if name.startswith("zenoh"):
        return "zenoh"
    return "other"


def _proc_cpu(tid: int) -> float | None:
    """utime + stime of thread ``tid`` of this process, seconds (None: it ended)."""
    try:
        with open(f"/proc/self/task/{tid}/stat") as f:
            text = f.read()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # fields 14 and 15 of stat(5)


def threads_cpu() -> dict[str, float]:
    """CPU seconds so far of each group of threads (module docstring)."""
    out: dict[str, float] = collections.defaultdict(float)
    known: set[int] = set()
    for thread in threading.enumerate():
        if thread.ident is None or thread.native_id is None:
            continue
        try:
            cpu = time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
        except (OSError, ProcessLookupError):  # it ended meanwhile
            continue
        known.add(thread.native_id)
        out[_group(thread)] += cpu
    for entry in os.listdir("/proc/self/task"):
        tid = int(entry)
        if tid in known:
            continue
        native = _proc_cpu(tid)
        if native is not None:
            out["zenoh"] += native
    return dict(out)


def part_of_file(file: str) -> str:
    """The part a source file belongs to (:data:`PARTS`)."""
    for pattern, part in PARTS:
        if pattern in file:
            return part
    if "/gateway/" in file or "/adapters/" in file:
        return "gateway other"
    return "other"


def _owner_of(callback: Any) -> Any:
    """What a loop callback's part is known by: a task's outermost coroutine's code, a
    transport's protocol's class (its reads and writes), a function's own code."""
    owner = getattr(callback, "__self__", None)
    if isinstance(owner, asyncio.Task):
        coro = owner.get_coro()
        return getattr(coro, "cr_code", None) or getattr(coro, "gi_code", None)
    protocol = getattr(owner, "_protocol", None)
    if protocol is not None:
        return type(protocol)
    while isinstance(callback, functools.partial):
        callback = callback.func
    return getattr(getattr(callback, "__func__", callback), "__code__", None)


def _file_of(owner: Any) -> str:
    if isinstance(owner, type):
        module = sys.modules.get(owner.__module__)
        return str(getattr(module, "__file__", "") or "")
    return str(getattr(owner, "co_filename", ""))


class LoopAccount:
    """The main thread's CPU time in each loop callback, by the part the callback belongs
    to (:meth:`install` wraps ``asyncio.events.Handle._run``: two reads of the thread's CPU
    clock per callback)."""

    def __init__(self) -> None:
        self.seconds: collections.defaultdict[str, float] = collections.defaultdict(float)
        self._parts: dict[Any, str] = {}

    def install(self) -> None:
        run = asyncio.events.Handle._run
        clock = time.thread_time
        seconds, parts = self.seconds, self._parts

        main, ident = threading.main_thread().ident, threading.get_ident

        def timed(handle: asyncio.events.Handle) -> None:
            if ident() != main:  # a line's loop: its thread's CPU is its own
                run(handle)
                return
            start = clock()
            try:
                run(handle)
            finally:
                owner = _owner_of(getattr(handle, "_callback", None))
                part = parts.get(owner)
                if part is None:
                    part = parts[owner] = part_of_file(_file_of(owner))
                seconds[part] += clock() - start

        asyncio.events.Handle._run = timed  # type: ignore[method-assign,assignment]


def sample(account: LoopAccount) -> dict[str, Any]:
    """One sample: its time, each thread group's CPU, the loop's by part so far."""
    return {"t": time.monotonic(), "cpu": threads_cpu(), "loop": dict(account.seconds)}


def split(samples: list[dict[str, Any]], t0: float, t1: float) -> dict[str, float] | None:
    """The cores each part took between the first sample at or after ``t0`` and the last at
    or before ``t1`` (None: fewer than two samples in between). The loop's by part as
    ``loop: <part>``, beside its total ``loop``."""
    inside = [s for s in samples if t0 <= s["t"] <= t1]
    if len(inside) < 2:
        return None
    first, last = inside[0], inside[-1]
    wall = last["t"] - first["t"]
    out = {group: (cpu - first["cpu"].get(group, 0.0)) / wall for group, cpu in last["cpu"].items()}
    loop = out.get("loop", 0.0)
    accounted = 0.0
    for part, seconds in sorted(last["loop"].items()):
        cores = (seconds - first["loop"].get(part, 0.0)) / wall
        if cores > 0:
            out[f"loop: {part}"] = cores
            accounted += cores
    if "loop" in out:
        out["loop: asyncio, epoll"] = max(0.0, loop - accounted)
    return {k: round(v, 4) for k, v in out.items()}
