"""Wrong command tokens per client address: at most ``web.token_failures`` in any
``web.token_window`` seconds.

Sans-IO (the caller passes the time). An address that has given that many wrong tokens
within the window is refused unchecked (429, with the seconds to wait) until the oldest of
them is older than the window: guessing is held to ``token_failures`` tries per window, and
a refusal costs no hashing. A right token clears the address's failures. The table is
bounded: beyond :data:`MAX_PEERS` addresses, the one that failed least recently is forgotten.
"""

from __future__ import annotations

import collections

MAX_PEERS = 4096  # addresses whose recent failures are kept


class TokenFailures:
    """The recent wrong tokens of each client address."""

    def __init__(self, failures: int, window: float, max_peers: int = MAX_PEERS) -> None:
        self.failures = failures
        self.window = window
        self.max_peers = max_peers
        self._times: collections.OrderedDict[str, collections.deque[float]] = (
            collections.OrderedDict()
        )

    def wait(self, peer: str, now: float) -> float:
        """Seconds before ``peer`` may give a token again (0.0: it may now)."""
        times = self._times.get(peer)
        if times is None or len(times) < self.failures:
            return 0.0
        return max(0.0, times[0] + self.window - now)

    def count(self, peer: str) -> int:
        """The wrong tokens of ``peer`` kept (at most ``failures``)."""
        times = self._times.get(peer)
        return len(times) if times is not None else 0

    def failed(self, peer: str, now: float) -> None:
        """``peer`` gave a wrong token at ``now``."""
        times = self._times.get(peer)
        if times is None:
            times = self._times[peer] = collections.deque(maxlen=self.failures)
        times.append(now)
        self._times.move_to_end(peer)
        while len(self._times) > self.max_peers:
            self._times.popitem(last=False)

    def succeeded(self, peer: str) -> None:
        """``peer`` gave the right token: its failures are forgotten."""
        self._times.pop(peer, None)

    def __len__(self) -> int:
        return len(self._times)
