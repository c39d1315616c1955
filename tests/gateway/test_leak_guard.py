"""The leak guard of tests/conftest.py fails a test that leaves a task, a thread or a
child process behind (run on tests of its own, in a separate pytest process)."""

from __future__ import annotations

from pathlib import Path

import pytest

CONFTEST = Path(__file__).resolve().parents[1] / "conftest.py"

LEAKY = """
import asyncio
import subprocess
import sys
import threading

never = threading.Event()


def test_clean_thread() -> None:
    t = threading.Thread(target=lambda: None)
    t.start()
    t.join()


def test_leaks_a_thread() -> None:
    threading.Thread(target=never.wait, name="left-behind", daemon=True).start()


def test_leaks_a_child_process() -> None:
    subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])


async def test_leaks_a_task() -> None:
    asyncio.create_task(asyncio.sleep(60), name="left-running")


async def test_clean_task() -> None:
    await asyncio.create_task(asyncio.sleep(0))
"""


def test_the_guard_fails_every_kind_of_leak(pytester: pytest.Pytester) -> None:
    pytester.makeconftest(CONFTEST.read_text())
    pytester.makeini(
        "[pytest]\nasyncio_mode = auto\nasyncio_default_fixture_loop_scope = function\n"
    )
    pytester.makepyfile(test_leaky=LEAKY)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", timeout=120)
    result.assert_outcomes(passed=5, errors=3)
    out = result.stdout.str()
    assert "AssertionError: test leaked threads: ['left-behind']" in out
    assert "AssertionError: test leaked child processes: [" in out
    assert "AssertionError: test leaked tasks: ['left-running']" in out
