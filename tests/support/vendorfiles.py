"""Vendor files that must neither hang nor exhaust the gateway (gateway/vendorfile.py), and
``check-config`` and ``run`` on a config naming them, each in a process of its own bounded
in time and memory: a reader without the bounds waits on a named pipe for ever and reads
``/dev/zero`` until memory runs out, and a test must end either way."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from tests.support.plugins import pythonpath
from tests.support.timing import scaled

BIG = 400 << 20
"""The size of the sparse file (400 MB, no byte of it written)."""
ADDRESS_SPACE = 2 << 30
"""The memory a command's process may map (2 GiB): ``/dev/zero`` read whole fails fast."""
COMMAND_SECONDS = 60.0
"""The bound on one command: a refusal takes about a second."""
REFUSED = {
    "device": "is a character device, not a regular file ({what} must be one)",
    "fifo": "is a named pipe, not a regular file ({what} must be one)",
    "link": "is a link to /dev/zero, a character device, not a regular file ({what} must be one)",
    "big": f"is {BIG} bytes; {{what}} may have at most 4194304 bytes (4 MiB)",
}
"""What each special file is refused with (``what``: "a GSD file", "an EDS file")."""


def special_files(directory: Path, suffix: str) -> dict[str, Path]:
    """``/dev/zero`` itself, a named pipe, a link to ``/dev/zero`` and a 400 MB sparse file,
    the last three in ``directory`` with names ending in ``suffix`` (".gsd", ".eds")."""
    fifo = directory / f"fifo{suffix}"
    os.mkfifo(fifo)
    link = directory / f"zero{suffix}"
    link.symlink_to("/dev/zero")
    big = directory / f"big{suffix}"
    with big.open("wb") as f:
        f.truncate(BIG)
    return {"device": Path("/dev/zero"), "fifo": fifo, "link": link, "big": big}


def refusal(kind: str, path: Path, what: str) -> str:
    """The reason a special file is refused with, after its path."""
    return f"{path}: {REFUSED[kind].format(what=what)}"


@dataclass(frozen=True)
class Outcome:
    """A command's exit status and the error lines it printed."""

    status: int
    errors: list[str]
    stderr: str


BOUNDED_GATEWAY = (
    "import resource, runpy, sys\n"
    f"resource.setrlimit(resource.RLIMIT_AS, ({ADDRESS_SPACE}, {ADDRESS_SPACE}))\n"
    "sys.argv[0] = 'gateway'\n"
    "runpy.run_module('gateway', run_name='__main__', alter_sys=True)\n"
)
"""``python -m gateway`` with its memory bounded, set in the child itself."""


def gateway_command(cwd: Path, *argv: str) -> Outcome:
    """``python -m gateway ARGV`` in its own process, killed after :data:`COMMAND_SECONDS`
    (subprocess.TimeoutExpired then fails the test), its memory bounded."""
    env = {**os.environ, "PYTHONPATH": pythonpath()}
    env.pop("NOTIFY_SOCKET", None)
    done = subprocess.run(
        [sys.executable, "-c", BOUNDED_GATEWAY, *argv],
        cwd=cwd,
        env=env,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=scaled(COMMAND_SECONDS),
        check=False,
    )
    errors = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
    return Outcome(done.returncode, errors, done.stderr)


def check_and_run(config: Path) -> tuple[Outcome, Outcome]:
    """``check-config CONFIG`` and ``run --config CONFIG``, each bounded."""
    check = gateway_command(config.parent, "check-config", str(config))
    run = gateway_command(config.parent, "run", "--config", str(config))
    return check, run
