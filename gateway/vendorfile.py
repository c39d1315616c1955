"""The vendor files a config names (a drive's GSD or EDS file), read only when safe to read.

``check-config`` and ``run`` read every ``gsd =`` and ``eds =`` file the config names, so
such a file must never hang or exhaust the gateway. :func:`read_vendor_file` reads one
only if it is a regular file (a device such as ``/dev/zero``, a named pipe, a socket or a
directory is refused by name; a link is followed and named) of at most :data:`MAX_BYTES`.
It opens the file without blocking and without following a link, checks that the
descriptor is the regular file it looked at (nothing swapped in between), and reads it in
chunks within :data:`READ_SECONDS`. Every refusal is a :class:`VendorFileError` naming the
file and the reason; the bus's loader names the key. The bytes are the codec's to decode:
a GSD file is ISO-8859-1 (its specification), an EDS ASCII (DeviceNet) or UTF-8 (CANopen).
See docs/decisions/0077-vendor-files.md.
"""

from __future__ import annotations

import os
import stat
import time
from collections.abc import Callable
from pathlib import Path
from typing import Final

from gateway.errors import ConfigError

MAX_BYTES: Final = 4 << 20
"""The largest vendor file read (4 MiB): the files shipped and in the test corpus are 2 to
16 kB; a maker's file with thousands of objects stays far below it."""
READ_SECONDS: Final = 10.0
"""The bound on one file's read: 4 MiB from a local disk or an SD card takes well under a
second; a file served slower is on a file system the gateway must not wait for."""
CHUNK: Final = 64 << 10
"""Bytes read at a time; the time bound is checked between chunks."""

OPEN_FLAGS: Final = os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_NOCTTY | os.O_CLOEXEC
"""open(2) of the file looked at: never blocking (a named pipe swapped in opens at once and
is refused), never following a link swapped in, never a controlling terminal."""

_KINDS: Final = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a named pipe"),
    (stat.S_ISSOCK, "a socket"),
)


class VendorFileError(ConfigError):
    """A vendor file refused before or while it is read; ``file`` is the vendor file."""

    def __init__(self, file: str, reason: str) -> None:
        super().__init__(file, "", reason)


def read_vendor_file(
    path: Path,
    what: str,
    *,
    limit: int = MAX_BYTES,
    seconds: float = READ_SECONDS,
    clock: Callable[[], float] = time.monotonic,
) -> bytes:
    """The bytes of the regular file ``path`` (``what`` names its kind in reasons, e.g.
    "a GSD file"): at most ``limit`` bytes, read within ``seconds``; VendorFileError
    naming the file and the reason otherwise."""
    shown = str(path)
    real, info = _look(path, shown)
    if not stat.S_ISREG(info.st_mode):
        link = f"a link to {real}, " if os.path.islink(path) else ""
        raise VendorFileError(
            shown, f"is {link}{file_kind(info.st_mode)}, not a regular file ({what} must be one)"
        )
    if info.st_size > limit:
        raise VendorFileError(shown, f"is {info.st_size} bytes; {_at_most(what, limit)}")
    fd = _open(real, shown)
    try:
        _same_file(fd, info, shown, what)
        return _read(fd, shown, what, limit=limit, seconds=seconds, clock=clock)
    finally:
        os.close(fd)


def file_kind(mode: int) -> str:
    """What a file that is not a regular file is, in words ("a named pipe")."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _at_most(what: str, limit: int) -> str:
    mib = f" ({limit >> 20} MiB)" if limit % (1 << 20) == 0 else ""
    return f"{what} may have at most {limit} bytes{mib}"


def _cannot(exc: OSError) -> str:
    return f"cannot be read: {(exc.strerror or str(exc)).lower()}"


def _look(path: Path, shown: str) -> tuple[str, os.stat_result]:
    """The file's real path (links followed) and what it is, before anything opens it."""
    try:
        real = os.path.realpath(path)
        return real, os.stat(real)
    except FileNotFoundError:
        raise VendorFileError(shown, "does not exist") from None
    except OSError as exc:
        raise VendorFileError(shown, _cannot(exc)) from None
    except ValueError as exc:  # an embedded NUL
        raise VendorFileError(shown, f"is not a usable path: {exc}") from None


def _open(real: str, shown: str) -> int:
    try:
        return os.open(real, OPEN_FLAGS)
    except OSError as exc:
        raise VendorFileError(shown, f"changed while being opened: {_cannot(exc)}") from None


def _same_file(fd: int, looked: os.stat_result, shown: str, what: str) -> None:
    """The descriptor is the regular file looked at (a file swapped in between is refused)."""
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        reason = f"is now {file_kind(info.st_mode)}, not a regular file ({what} must be one)"
        raise VendorFileError(shown, f"changed while being opened: {reason}")
    if (info.st_dev, info.st_ino) != (looked.st_dev, looked.st_ino):
        raise VendorFileError(shown, "changed while being opened: another file took its place")


def _read(
    fd: int, shown: str, what: str, *, limit: int, seconds: float, clock: Callable[[], float]
) -> bytes:
    """Chunks up to the end of the file, never more than ``limit`` bytes nor ``seconds``."""
    deadline = clock() + seconds
    chunks: list[bytes] = []
    total = 0
    while True:
        if clock() > deadline:
            raise VendorFileError(
                shown, f"was not read within {seconds:g} s (a slow or hung file system?)"
            )
        try:
            chunk = os.read(fd, min(CHUNK, limit + 1 - total))
        except OSError as exc:
            raise VendorFileError(shown, _cannot(exc)) from None
        if not chunk:
            return b"".join(chunks)
        total += len(chunk)
        if total > limit:
            raise VendorFileError(shown, f"grew while being read; {_at_most(what, limit)}")
        chunks.append(chunk)
