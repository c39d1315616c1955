"""One master per line: a serial port held exclusively, and who holds it when it is taken.

Two locks, both taken before the first byte is sent (docs/operations.md, "One master per
line"; the choice in docs/decisions/0014-serial-port-lock.md):

* ``flock(LOCK_EX | LOCK_NB)`` on the open device (pyserial's ``exclusive=True``), taken
  before pyserial changes any setting of the port: a second master is refused before it
  could change the line's baud rate or parity under the first. Advisory, so only programs
  that flock respect it, but it holds for root too, and the kernel drops it when the
  holder's file closes or its process dies (no stale lock file after ``kill -9``).
* ``TIOCEXCL`` once the flock is ours: the kernel refuses every further ``open()`` of the
  tty (``EBUSY``) to a process without CAP_SYS_ADMIN, so a terminal program that does not
  flock cannot open the line either. Root bypasses it (seen on Linux 6.18: a second open
  as root succeeds on a pty slave; its flock is what refuses it). It is cleared
  (``TIOCNXCL``) before the port closes: on a pty whose master side stays open the flag
  outlives the slave's close and would refuse the next non-root opener.

No UUCP lock file (``/run/lock/LCK..ttyUSB0``): it outlives a killed holder, needs a
writable ``/run/lock`` in the service's sandbox, and ``/proc`` names the holder anyway:
:func:`find_holder` reads ``/proc/locks`` (the pid holding the flock on the device's
inode) and, failing that, ``/proc/*/fd`` (a holder using ``TIOCEXCL`` alone), and
``/proc/<pid>/cmdline``. A process this user may not see (``hidepid``, another user under
systemd's ``ProtectProc=invisible``) stays unnamed.

URL ports (``rfc2217://``, ``socket://``) have no local device to lock: the terminal
server on the other end decides who may connect.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import termios
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from gateway.errors import LineHeld

PROC: Final = Path("/proc")
HELD_ERRNOS: Final = frozenset({errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY})
"""What a refused lock (flock: EWOULDBLOCK) or a refused open of a TIOCEXCL tty (EBUSY) gives."""
COMMAND_MAX: Final = 160  # characters of the holder's command line in a message


@dataclass(frozen=True, slots=True)
class Holder:
    """The process holding a port: its pid and command line ("" when unreadable)."""

    pid: int
    command: str = ""

    def __str__(self) -> str:
        return f"pid {self.pid} ({self.command})" if self.command else f"pid {self.pid}"


class PortHeld(LineHeld):
    """A serial port another process holds; the text names it and says what to do."""

    def __init__(self, port: str, holder: Holder | None) -> None:
        self.port = port
        self.holder = holder
        who = str(holder) if holder is not None else "another process (not visible to this user)"
        super().__init__(
            f"serial port {port} is held by {who}: another master is on this line; "
            "stop that process or configure another port (one master per line)"
        )


def held(exc: OSError) -> bool:
    """Whether an open or lock failure means that another process holds the port."""
    return exc.errno in HELD_ERRNOS


def set_exclusive(fd: int) -> bool:
    """TIOCEXCL on an open tty whose flock is ours; False where the device is no tty."""
    try:
        fcntl.ioctl(fd, termios.TIOCEXCL)
    except OSError:
        return False
    return True


def clear_exclusive(fd: int) -> None:
    """TIOCNXCL before the holder closes the port (see the module docstring)."""
    with contextlib.suppress(OSError):
        fcntl.ioctl(fd, termios.TIOCNXCL)


def find_holder(port: str, proc: Path = PROC) -> Holder | None:
    """The process holding ``port``'s lock, or having it open; None if none can be seen."""
    try:
        st = os.stat(port)
    except OSError:
        return None
    pid = _flock_holder(st, proc) or _opener(st, proc)
    if pid is None:
        return None
    return Holder(pid, _command(pid, proc))


def _flock_holder(st: os.stat_result, proc: Path) -> int | None:
    """The pid of the FLOCK on the device node's inode in ``/proc/locks``.

    A line reads ``1: FLOCK  ADVISORY  WRITE 4242 00:1a:4 0 EOF``: the pid, then the
    filesystem's major:minor in hex and the inode in decimal. Waiters (``1: -> FLOCK``)
    have one more field and do not hold the lock.
    """
    key = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        text = (proc / "locks").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        fields = line.split()
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[5] == key:
            with contextlib.suppress(ValueError):
                pid = int(fields[4])
                if pid > 0:
                    return pid
    return None


def _opener(st: os.stat_result, proc: Path) -> int | None:
    """Another process with the device open (by device number: any path, symlinks too)."""
    if not stat.S_ISCHR(st.st_mode):
        return None
    me = os.getpid()
    for entry in proc.iterdir():
        if not entry.name.isdigit() or int(entry.name) == me:
            continue
        with contextlib.suppress(OSError):
            for fd in (entry / "fd").iterdir():
                with contextlib.suppress(OSError):
                    other = os.stat(fd)
                    if stat.S_ISCHR(other.st_mode) and other.st_rdev == st.st_rdev:
                        return int(entry.name)
    return None


def _command(pid: int, proc: Path) -> str:
    try:
        raw = (proc / str(pid) / "cmdline").read_bytes()
    except OSError:
        return ""
    text = " ".join(part.decode(errors="replace") for part in raw.split(b"\0") if part)
    return text if len(text) <= COMMAND_MAX else text[: COMMAND_MAX - 3] + "..."
