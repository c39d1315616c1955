"""One master per line at the port: a second open of a held port is refused, naming the
holder, before anything is set or sent (adapters/link/portlock.py)."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import struct
import subprocess
import sys
import termios
from collections.abc import Iterator
from pathlib import Path

import pytest

from adapters.link.portlock import Holder, PortHeld, find_holder
from adapters.profibus.link import open_port
from gateway.cli import main
from gateway.errors import LineHeld

TIOCGEXCL = 0x80045440  # _IOR('T', 0x40, int): whether the tty is in exclusive mode


@contextlib.contextmanager
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


def exclusive(fd: int) -> bool:
    return bool(struct.unpack("i", fcntl.ioctl(fd, TIOCGEXCL, bytes(4)))[0])


def test_a_second_open_of_a_held_pty_is_refused_naming_the_holder() -> None:
    with pty_pair() as (_, path):
        first = open_port(path, 500000)
        try:
            settings = termios.tcgetattr(first.fileno())
            assert exclusive(first.fileno())  # TIOCEXCL: other users' opens get EBUSY
            with pytest.raises(PortHeld) as info:
                open_port(path, 9600)
            assert isinstance(info.value, LineHeld)  # what the daemon refuses to start on
            holder = info.value.holder
            assert holder is not None and holder.pid == os.getpid()
            assert "pytest" in holder.command or "python" in holder.command
            text = str(info.value)
            assert text.startswith(f"serial port {path} is held by pid {os.getpid()} (")
            assert text.endswith(
                "stop that process or configure another port (one master per line)"
            )
            # refused before it set anything: the holder's 500000 8E1 is untouched
            assert termios.tcgetattr(first.fileno()) == settings
        finally:
            first.close()
        with open(path, "rb", buffering=0) as probe:
            assert not exclusive(probe.fileno())  # cleared on close: the pty outlives us
        again = open_port(path, 500000)  # free again
        again.close()


def test_the_scan_tool_is_refused_on_a_held_port(capsys: pytest.CaptureFixture[str]) -> None:
    with pty_pair() as (master, path):
        holder = open_port(path, 500000)
        try:
            assert main(["profibus", "scan", "--port", path, "--to", "3"]) == 1
            err = capsys.readouterr().err
            assert err.startswith(f"error: serial port {path} is held by pid {os.getpid()} (")
            os.set_blocking(master, False)
            with pytest.raises(BlockingIOError):
                os.read(master, 64)  # not one byte reached the line
        finally:
            holder.close()


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("setpriv"), reason="needs root")
def test_tiocexcl_refuses_another_user_root_is_refused_by_the_flock() -> None:
    """Root bypasses TIOCEXCL (the flock refuses it: the test above); another user is
    refused by the kernel at open() already, EBUSY."""
    probe = "import os, sys\ntry:\n os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)\nexcept OSError as e:\n print(e.errno)"
    with pty_pair() as (_, path):
        os.chmod(path, 0o666)
        run = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        run += [sys.executable, "-I", "-c", probe, path]
        held = open_port(path, 500000)
        try:
            out = subprocess.run(run, capture_output=True, text=True, timeout=60, check=True)
            assert out.stdout.strip() == "16", out  # EBUSY
        finally:
            held.close()
        out = subprocess.run(run, capture_output=True, text=True, timeout=60, check=True)
        assert out.stdout.strip() == "", out  # TIOCNXCL on close: free for anyone


def test_the_holder_is_read_from_proc_locks(tmp_path: Path) -> None:
    device = tmp_path / "ttyX"
    device.write_text("")
    st = os.stat(device)
    key = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    proc = tmp_path / "proc"
    (proc / "4242").mkdir(parents=True)
    (proc / "4242" / "cmdline").write_bytes(b"drive-gateway\0run\0--config\0site.toml\0")
    (proc / "locks").write_text(
        f"1: POSIX  ADVISORY  WRITE 99 {key} 0 EOF\n"
        f"2: -> FLOCK  ADVISORY  WRITE 77 {key} 0 EOF\n"  # a waiter holds nothing
        "3: FLOCK  ADVISORY  WRITE 55 00:01:12345 0 EOF\n"  # another file
        f"4: FLOCK  ADVISORY  WRITE 4242 {key} 0 EOF\n"
    )
    holder = find_holder(str(device), proc)
    assert holder == Holder(4242, "drive-gateway run --config site.toml")
    (proc / "locks").write_text("")
    assert find_holder(str(device), proc) is None
    assert find_holder(str(tmp_path / "missing"), proc) is None


def test_an_unseen_holder_is_said_so() -> None:
    text = str(PortHeld("/dev/ttyUSB0", None))
    assert text.startswith("serial port /dev/ttyUSB0 is held by another process (not visible")
