"""How long the tests wait: every bound comes from here, scaled by one documented factor.

A wait in a test is for an event (a state, an event, a reply); its bound only
decides how long a failing test takes to fail. So the bounds are generous, and
on a slow or emulated machine (the vcan VM under TCG, an ARM board) they grow
with ``DRIVE_GATEWAY_TEST_TIME_SCALE`` (default 1; the vcan VM sets 4). Tests
never assert that something happened fast: speed is shown by `make bench`.
"""

from __future__ import annotations

import os

ENV = "DRIVE_GATEWAY_TEST_TIME_SCALE"


def _factor() -> float:
    try:
        value = float(os.environ.get(ENV, "1") or "1")
    except ValueError:
        raise SystemExit(f"{ENV} must be a number, not {os.environ[ENV]!r}") from None
    return max(value, 1.0)


TIME_SCALE = _factor()


def scaled(seconds: float) -> float:
    """A bound of ``seconds`` on an idle machine, on this one."""
    return seconds * TIME_SCALE
