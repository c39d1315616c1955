"""The simulated drives' clock: it does not run while their process stands still.

The simulated CiA 402 drives run in the gateway's process (``simulate = true``). When that
process stands still (a loaded machine that does not schedule it, a debugger, SIGSTOP), a
real drive's clock would go on and its heartbeat consumer would rightly fault (0x8130); the
simulated drive stood still too, and nothing the master could have sent reached it. So the
clock leaves out any gap between two readings longer than :data:`STILL_GAP`: the runner
reads it every :data:`adapters.canopen.sim.runner.TICK` (10 ms) while it runs, so such a gap
is the process standing still, not the drive waiting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

STILL_GAP = 0.25  # s between two readings: longer, and the rest of the gap is left out


class StillClock:
    """``time.monotonic`` (or ``base``) less the time the process stood still."""

    def __init__(self, base: Callable[[], float] = time.monotonic, gap: float = STILL_GAP) -> None:
        self._base = base
        self._gap = gap
        self._lock = threading.Lock()  # the loop and python-can's notifier thread read it
        self._last = base()
        self._offset = 0.0
        self.stood_still = 0.0  # s left out in all

    def __call__(self) -> float:
        with self._lock:
            now = self._base()
            gap = now - self._last
            if gap > self._gap:
                self._offset += gap - self._gap
                self.stood_still += gap - self._gap
            self._last = now
            return now - self._offset
