"""A vendor file (a drive's GSD or EDS) is read only if it is a regular file of at most
4 MiB, within a time bound: /dev/zero, a named pipe, a link to a device, a file over the
limit, a file swapped or grown while it is read are refused, naming the file and why."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from gateway import vendorfile
from gateway.errors import ConfigError
from gateway.vendorfile import MAX_BYTES, READ_SECONDS, VendorFileError, read_vendor_file
from tests.support.timing import scaled

GSD = "a GSD file"


def refused(
    path: Path,
    limit: int = MAX_BYTES,
    seconds: float = READ_SECONDS,
    clock: Callable[[], float] = time.monotonic,
) -> str:
    with pytest.raises(VendorFileError) as info:
        read_vendor_file(path, GSD, limit=limit, seconds=seconds, clock=clock)
    assert isinstance(info.value, ConfigError) and info.value.file == str(path)
    return info.value.reason


def bounded(call: Callable[[], str], fifo: Path) -> str:
    """``call()`` on a thread; a call blocked in open(2) of ``fifo`` past the bound is
    woken by a writer and the test fails (it never hangs)."""
    out: list[str] = []
    thread = threading.Thread(target=lambda: out.append(call()), daemon=True)
    thread.start()
    thread.join(scaled(10.0))
    if thread.is_alive():
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        thread.join(scaled(10.0))
        pytest.fail(f"the read blocked on {fifo}")
    return out[0]


def test_a_regular_file_is_read_whole(tmp_path: Path) -> None:
    path = tmp_path / "x.gsd"
    data = bytes(range(256)) * 1000  # several chunks
    path.write_bytes(data)
    assert read_vendor_file(path, GSD) == data


def test_a_link_to_a_regular_file_is_followed(tmp_path: Path) -> None:
    (tmp_path / "real.gsd").write_bytes(b"#Profibus_DP\n")
    (tmp_path / "link.gsd").symlink_to(tmp_path / "real.gsd")
    assert read_vendor_file(tmp_path / "link.gsd", GSD) == b"#Profibus_DP\n"


def test_dev_zero_is_refused_before_it_is_opened() -> None:
    reason = refused(Path("/dev/zero"))
    assert reason == "is a character device, not a regular file (a GSD file must be one)"


def test_a_named_pipe_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.gsd"
    os.mkfifo(fifo)
    reason = bounded(lambda: refused(fifo), fifo)
    assert reason == "is a named pipe, not a regular file (a GSD file must be one)"


def test_a_link_to_dev_zero_is_refused_and_named(tmp_path: Path) -> None:
    link = tmp_path / "zero.gsd"
    link.symlink_to("/dev/zero")
    assert refused(link) == (
        "is a link to /dev/zero, a character device, not a regular file (a GSD file must be one)"
    )


def test_a_file_over_the_limit_is_refused_unread(tmp_path: Path) -> None:
    big = tmp_path / "big.gsd"
    with big.open("wb") as f:
        f.truncate(400 << 20)  # sparse: nothing written
    assert (
        refused(big)
        == f"is {400 << 20} bytes; a GSD file may have at most {MAX_BYTES} bytes (4 MiB)"
    )
    assert MAX_BYTES == 4 << 20


def test_the_limit_itself_is_read(tmp_path: Path) -> None:
    path = tmp_path / "x.gsd"
    path.write_bytes(b"x" * 10)
    assert read_vendor_file(path, GSD, limit=10) == b"x" * 10
    path.write_bytes(b"x" * 11)
    assert refused(path, limit=10) == "is 11 bytes; a GSD file may have at most 10 bytes"


@pytest.mark.parametrize(
    ("name", "reason"),
    [
        ("missing.gsd", "does not exist"),
        ("dir.gsd", "is a directory, not a regular file (a GSD file must be one)"),
        ("file.gsd/x.gsd", "cannot be read: not a directory"),
    ],
)
def test_what_is_not_a_readable_file_is_named(tmp_path: Path, name: str, reason: str) -> None:
    (tmp_path / "dir.gsd").mkdir()
    (tmp_path / "file.gsd").write_bytes(b"")
    assert refused(tmp_path / name) == reason


def test_a_read_past_its_time_bound_is_refused(tmp_path: Path) -> None:
    """A file served slowly (a hung network mount): the bound is checked between chunks."""
    path = tmp_path / "slow.gsd"
    path.write_bytes(b"x" * (3 * vendorfile.CHUNK))
    ticks: Iterator[float] = iter([0.0, 0.0, 4.0, 8.0, 12.0, 16.0])
    reason = refused(path, seconds=10.0, clock=lambda: next(ticks))
    assert reason == "was not read within 10 s (a slow or hung file system?)"


# ---------------------------------------------------------------- a file swapped while opened


def _looked_at(regular: Path, real: Path) -> Callable[[Path, str], tuple[str, os.stat_result]]:
    """What the reader saw before opening: ``regular``; what is there when it opens: ``real``."""
    return lambda _path, _shown: (str(real), os.stat(regular))


def test_a_named_pipe_swapped_in_is_opened_without_blocking_and_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    regular, fifo = tmp_path / "x.gsd", tmp_path / "pipe.gsd"
    regular.write_bytes(b"x")
    os.mkfifo(fifo)
    monkeypatch.setattr(vendorfile, "_look", _looked_at(regular, fifo))
    reason = bounded(lambda: refused(regular), fifo)
    assert reason == (
        "changed while being opened: is now a named pipe, not a regular file "
        "(a GSD file must be one)"
    )


def test_a_link_swapped_in_is_not_followed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    regular, link = tmp_path / "x.gsd", tmp_path / "zero.gsd"
    regular.write_bytes(b"x")
    link.symlink_to("/dev/zero")
    monkeypatch.setattr(vendorfile, "_look", _looked_at(regular, link))
    assert refused(regular) == (
        "changed while being opened: cannot be read: too many levels of symbolic links"
    )


def test_another_file_swapped_in_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    regular, other = tmp_path / "x.gsd", tmp_path / "y.gsd"
    regular.write_bytes(b"x")
    other.write_bytes(b"y")
    monkeypatch.setattr(vendorfile, "_look", _looked_at(regular, other))
    assert refused(regular) == "changed while being opened: another file took its place"


def test_a_file_that_grows_while_read_stops_at_the_limit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "x.gsd"
    path.write_bytes(b"x" * 5)
    look = vendorfile._look

    def look_then_grow(p: Path, shown: str) -> tuple[str, os.stat_result]:
        seen = look(p, shown)
        with path.open("ab") as f:
            f.write(b"y" * 100)
        return seen

    monkeypatch.setattr(vendorfile, "_look", look_then_grow)
    assert refused(path, limit=10) == "grew while being read; a GSD file may have at most 10 bytes"
