"""What the line benches read of a line's thread: its CPU time, the kernel's part of it,
and, on request, a CPU-time profile of it (``BENCH_LINE_PROFILE=FILE``: cProfile stats of
the line's thread over the measured stretch, timed by the thread's CPU clock, so the waits
on the port do not count)."""

from __future__ import annotations

import contextlib
import cProfile
import math
import os
import threading
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any


def thread_cpu(thread: threading.Thread | None) -> float:
    """A thread's CPU time (s), 0 before it started."""
    if thread is None or thread.ident is None:
        return 0.0
    return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))


def thread_system(native_id: int | None) -> float:
    """The kernel's share of a thread's CPU (s), from /proc (stime, in clock ticks)."""
    if native_id is None:
        return math.nan
    try:
        stat = Path(f"/proc/self/task/{native_id}/stat").read_text()
    except OSError:
        return math.nan
    fields = stat.rsplit(")", 1)[1].split()
    return int(fields[12]) / os.sysconf("SC_CLK_TCK")  # field 15 of stat(5)


@contextlib.asynccontextmanager
async def line_profile(line: Any) -> AsyncIterator[None]:
    """The line's thread under cProfile while the block runs, when ``BENCH_LINE_PROFILE``
    names a file (the stats are written there); nothing otherwise. ``line``: a
    :class:`~gateway.runtime.linethread.LineThread` (its ``call`` runs on the line's loop)."""
    path = os.environ.get("BENCH_LINE_PROFILE")
    if not path:
        yield
        return
    prof = cProfile.Profile(time.thread_time)  # CPU, not the waits
    await line.call(prof.enable)
    try:
        yield
    finally:
        await line.call(prof.disable)
        prof.dump_stats(path)
