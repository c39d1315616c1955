"""Every benchmark module has a command line of its own: ``python -m bench.bench_X --help``
prints its usage and exits 0 without starting anything, and an unknown option is argparse's
exit 2. Each module runs in a child interpreter with an audit hook (a ``sitecustomize`` on
its path) that ends it with :data:`GUARD_EXIT` at the first child process, fork, pty,
temporary directory (a venv's) or socket: a module that began its benchmark instead of
answering could not pass, however fast it failed."""

from __future__ import annotations

import argparse
import ast
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from bench.common import first_paragraph, positive_float, positive_int
from tests.support.timing import scaled

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(p.stem for p in (ROOT / "bench").glob("bench_*.py"))
GUARD_EXIT = 97
BOUND = scaled(90.0)  # s: an interpreter start and the module's imports on a loaded host

# The guard, loaded by the child's site module before anything else runs.
GUARD = f"""
import os
import sys

FORBIDDEN = frozenset({{
    "subprocess.Popen", "os.fork", "os.forkpty", "os.posix_spawn", "os.spawn", "os.exec",
    "os.system", "pty.spawn", "tempfile.mkdtemp", "tempfile.mkstemp", "socket.bind",
    "socket.connect",
}})


def _stop(what):
    os.write(2, ("bench-cli-guard: " + what + "\\n").encode())
    os._exit({GUARD_EXIT})


def _hook(event, args):
    if event in FORBIDDEN:
        _stop(event)


def _openpty():
    _stop("os.openpty")


sys.addaudithook(_hook)
os.openpty = _openpty
"""


@pytest.fixture(scope="module")
def guarded_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    where = tmp_path_factory.mktemp("guard")
    (where / "sitecustomize.py").write_text(GUARD)
    paths = [str(where), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def _run(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=BOUND,
        check=False,
    )


def test_every_benchmark_module_is_covered() -> None:
    assert len(MODULES) >= 10
    assert {"bench_profibus", "bench_pyprofibus", "bench_plant", "bench_zenoh"} <= set(MODULES)


def test_the_guard_stops_a_child_process(guarded_env: dict[str, str]) -> None:
    done = _run(guarded_env, "-c", "import subprocess; subprocess.run(['true']); print('ran')")
    assert done.returncode == GUARD_EXIT
    assert "bench-cli-guard: subprocess.Popen" in done.stderr
    assert "ran" not in done.stdout
    done = _run(guarded_env, "-c", "import pty; pty.openpty()")
    assert done.returncode == GUARD_EXIT, done.stderr


@pytest.mark.parametrize("module", MODULES)
def test_help_prints_usage_and_a_bad_option_exits_2(
    module: str, guarded_env: dict[str, str]
) -> None:
    source = (ROOT / "bench" / f"{module}.py").read_text()
    summary = first_paragraph(ast.get_docstring(ast.parse(source)))
    assert summary

    shown = _run(guarded_env, "-m", f"bench.{module}", "--help")
    assert "bench-cli-guard" not in shown.stderr, shown.stderr
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith(f"usage: python -m bench.{module}")
    assert summary in " ".join(shown.stdout.split())  # argparse re-wraps the paragraph

    bad = _run(guarded_env, "-m", f"bench.{module}", "--no-such-option")
    assert "bench-cli-guard" not in bad.stderr, bad.stderr
    assert bad.returncode == 2, bad.stderr
    assert "usage:" in bad.stderr
    assert "unrecognized arguments: --no-such-option" in bad.stderr
    assert bad.stdout == ""


@pytest.mark.parametrize(
    ("convert", "text", "message"),
    [
        (positive_int, "0", "'0': must be 1 or more"),
        (positive_int, "2.5", "'2.5' is not a whole number"),
        (positive_float, "0", "'0': must be a finite number above 0"),
        (positive_float, "nan", "'nan': must be a finite number above 0"),
        (positive_float, "inf", "'inf': must be a finite number above 0"),
        (positive_float, "soon", "'soon' is not a number"),
    ],
)
def test_a_bad_count_or_time_is_named(
    convert: Callable[[str], object], text: str, message: str
) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=message):
        convert(text)
    assert positive_int("3") == 3 and positive_float("0.5") == 0.5


def test_a_bad_value_of_a_knob_exits_2_naming_it(guarded_env: dict[str, str]) -> None:
    done = _run(guarded_env, "-m", "bench.bench_devicenet", "--nodes", "1", "64")
    assert done.returncode == 2, done.stderr
    assert "argument --nodes: '64': DeviceNet node counts (MAC IDs 1..N) are 1-63" in done.stderr
    assert done.stdout == ""
