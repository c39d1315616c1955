"""Test-wide fixtures: the leak guard that every test runs under."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import threading
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest
import pytest_asyncio

# The test adapters' entry points (tests/support/plugins.py), without importing the tests
# package: tests/gateway/test_leak_guard.py runs this file elsewhere.
_TEST_SITE = Path(__file__).resolve().parent / "support" / "site"
if _TEST_SITE.is_dir() and str(_TEST_SITE) not in sys.path:
    sys.path.append(str(_TEST_SITE))

pytest_plugins = ["pytester"]  # tests/gateway/test_leak_guard.py runs the guard on itself

THREAD_GRACE = 2.0  # seconds a thread the test started may take to finish after it


def _children() -> set[int]:
    """Live child processes of this process (zombies included: not reaped is leaked)."""
    me = str(os.getpid())
    out = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[-1].split()
        if len(fields) > 1 and fields[1] == me:
            out.add(int(entry.name))
    return out


@pytest.fixture(autouse=True)
def no_leaked_threads_or_processes() -> Iterator[None]:
    """Fail a test that leaves Python threads or child processes behind."""
    threads_before = set(threading.enumerate())
    children_before = _children()
    yield
    leaked_threads = []
    for thread in set(threading.enumerate()) - threads_before:
        thread.join(THREAD_GRACE)
        if thread.is_alive():
            leaked_threads.append(thread.name)
    leaked_children = _children() - children_before
    for pid in leaked_children:
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
    assert not leaked_threads, f"test leaked threads: {leaked_threads}"
    assert not leaked_children, f"test leaked child processes: {sorted(leaked_children)}"


@pytest_asyncio.fixture(autouse=True)
async def no_leaked_tasks() -> AsyncIterator[None]:
    """Fail an async test that leaves asyncio tasks running."""
    before = asyncio.all_tasks()
    yield
    current = asyncio.current_task()
    leaked = [t for t in asyncio.all_tasks() - before if t is not current and not t.done()]
    for task in leaked:
        task.cancel()
    if leaked:
        await asyncio.gather(*leaked, return_exceptions=True)
    assert not leaked, f"test leaked tasks: {[t.get_name() for t in leaked]}"
