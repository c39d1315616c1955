"""The systemd journal's native protocol, sans-IO: a record's fields as one datagram.

journald reads datagrams on ``/run/systemd/journal/socket``; each field is
``NAME=value\\n``, or, when the value holds a newline, ``NAME\\n``, its length as 64-bit
little-endian, the value and ``\\n``. A name is upper-case letters, digits and ``_``, not
starting with ``_`` (those are journald's own), at most 64 characters.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping

SOCKET_PATH = "/run/systemd/journal/socket"
_NAME = re.compile(r"[A-Z0-9][A-Z0-9_]{0,63}")
_LENGTH = struct.Struct("<Q")


def field_name(name: str) -> str:
    """``name`` as a journal field name (upper case, other characters as ``_``)."""
    cleaned = re.sub(r"[^A-Z0-9_]", "_", name.upper()).lstrip("_")[:64]
    if not _NAME.fullmatch(cleaned):
        raise ValueError(f"{name!r} cannot be a journal field name")
    return cleaned


def encode(fields: Mapping[str, str]) -> bytes:
    """The datagram of one journal entry."""
    out = bytearray()
    for name, value in fields.items():
        key = field_name(name).encode("ascii")
        raw = value.encode("utf-8", "replace")
        if b"\n" in raw:
            out += key + b"\n" + _LENGTH.pack(len(raw)) + raw + b"\n"
        else:
            out += key + b"=" + raw + b"\n"
    return bytes(out)


def decode(datagram: bytes) -> dict[str, str]:
    """The fields of a datagram :func:`encode` made (tests, and a reader's check)."""
    fields: dict[str, str] = {}
    at = 0
    while at < len(datagram):
        end = datagram.index(b"\n", at)
        line = datagram[at:end]
        if b"=" in line:
            name, _, value = line.partition(b"=")
            fields[name.decode("ascii")] = value.decode("utf-8")
            at = end + 1
            continue
        (size,) = _LENGTH.unpack_from(datagram, end + 1)
        start = end + 1 + _LENGTH.size
        fields[line.decode("ascii")] = datagram[start : start + size].decode("utf-8")
        if datagram[start + size : start + size + 1] != b"\n":
            raise ValueError("a binary field does not end with a newline")
        at = start + size + 1
    return fields
