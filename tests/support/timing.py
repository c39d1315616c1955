"""The suite's time scale for waits: ``DRIVE_GATEWAY_TEST_TIME_SCALE`` (default 1).

A slow machine (the vcan VM under TCG runs Python several times slower) sets it above 1
and every wait that uses :func:`scaled` grows by that factor. Protocol timers are not
scaled: only how long a test is willing to wait for something that will happen.
"""

from __future__ import annotations

import os

ENV = "DRIVE_GATEWAY_TEST_TIME_SCALE"


def _read() -> float:
    text = os.environ.get(ENV, "1")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{ENV}={text!r} is not a number") from None
    if not value >= 1.0:
        raise ValueError(f"{ENV}={text!r}: the time scale is at least 1")
    return value


TIME_SCALE = _read()


def scaled(seconds: float) -> float:
    """A wait of ``seconds`` on this machine (the time scale applied)."""
    return seconds * TIME_SCALE
