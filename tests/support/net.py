"""Loopback helpers for tests: free ports, so instances can run side by side."""

from __future__ import annotations

import random
import socket
from pathlib import Path

EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")
SPAN = 10_000  # ports below the kernel's ephemeral range the tests choose from
_rng = random.SystemRandom()  # never the global generator hypothesis seeds
_given: set[int] = set()


def _choices() -> tuple[int, int]:
    """The ports to choose from: below the kernel's ephemeral range, where no outgoing
    connection takes a port between our check and the server's bind."""
    try:
        low = int(EPHEMERAL_RANGE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768  # Linux's default
    return max(1024, low - SPAN), low - 1


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago, never handed out twice by this
    process and outside the ephemeral range: a port the kernel picked for ``bind(0)`` was
    released again before the server under test bound it, and an outgoing connection (a
    Zenoh or Modbus client) could take it meanwhile ("Address already in use")."""
    lo, hi = _choices()
    for _ in range(1000):
        port = _rng.randint(lo, hi)
        if port in _given:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        _given.add(port)
        return port
    raise RuntimeError(f"no free TCP port on 127.0.0.1 in {lo}-{hi}")


def zenoh_endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"
