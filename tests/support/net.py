"""Loopback helpers for tests: free ports, so instances can run side by side."""

from __future__ import annotations

import socket


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def zenoh_endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"
