"""The test adapters, registered the way a third-party adapter is: an entry point in the
group ``drive_gateway.adapters``, declared by the distribution metadata in ``site/``.

A config names the test adapter ``"fake"``; the daemon finds it through that metadata,
on ``sys.path`` in-process (tests/conftest.py) and through :func:`pythonpath` in the
daemon processes the tests start.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SITE = Path(__file__).resolve().parent / "site"
FAKE = "fake"
"""The registered name of :class:`tests.support.fake_adapter.FakeAdapter`."""


def pythonpath() -> str:
    """PYTHONPATH for a daemon process the tests start: the clone and the test adapters."""
    return os.pathsep.join([str(ROOT), str(SITE)])


def register() -> None:
    """Make the test adapters' entry points visible in this process."""
    if str(SITE) not in sys.path:
        sys.path.append(str(SITE))
