"""Requests per client address: a token bucket per address, sans-IO (the caller passes
the time). A client over its rate is not answered faster by refusing it (a refusal costs
the gateway as much as an answer): its connection is not read until its next request is
due (``web.request_rate``, ``web.request_burst``; gateway/web/admission.py)."""

from __future__ import annotations

import collections
from dataclasses import dataclass

MAX_ADDRESSES = 4096  # buckets kept; the longest unused is dropped (it was full anyway)


@dataclass(slots=True)
class _Bucket:
    tokens: float
    at: float


class RequestRate:
    """``rate`` requests per second per address, ``burst`` at once."""

    def __init__(self, rate: float, burst: int, max_addresses: int = MAX_ADDRESSES) -> None:
        self.rate = rate
        self.burst = float(burst)
        self.max_addresses = max_addresses
        self._buckets: collections.OrderedDict[str, _Bucket] = collections.OrderedDict()

    def _bucket(self, peer: str, now: float) -> _Bucket:
        bucket = self._buckets.get(peer)
        if bucket is None:
            bucket = self._buckets[peer] = _Bucket(self.burst, now)
            if len(self._buckets) > self.max_addresses:
                self._buckets.popitem(last=False)
        else:
            self._buckets.move_to_end(peer)
            bucket.tokens = min(self.burst, bucket.tokens + (now - bucket.at) * self.rate)
            bucket.at = now
        return bucket

    def take(self, peer: str, now: float) -> float:
        """A request of ``peer`` now: 0 when within its rate, else how many seconds its
        connection is not to be read (the request is counted either way)."""
        bucket = self._bucket(peer, now)
        bucket.tokens -= 1.0
        return 0.0 if bucket.tokens >= 0.0 else -bucket.tokens / self.rate

    def wait(self, peer: str, now: float) -> float:
        """Seconds until ``peer`` may send a request (0: now), nothing counted."""
        bucket = self._bucket(peer, now)
        return 0.0 if bucket.tokens >= 0.0 else -bucket.tokens / self.rate
