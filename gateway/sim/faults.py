"""Fault injection shared by the simulators: a seeded noise source and a fault slot."""

from __future__ import annotations

import random
from dataclasses import dataclass


@dataclass
class FaultInjector:
    """What a test asks a simulated device to suffer.

    ``bit_error_rate`` flips bits per byte sent; ``drop_rate`` loses whole replies;
    ``delay`` makes replies late; ``fault_code`` trips the device until reset.
    Deterministic for a given seed.
    """

    seed: int = 0
    bit_error_rate: float = 0.0
    drop_rate: float = 0.0
    delay: float = 0.0
    fault_code: int | None = None

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)

    def trip(self, code: int) -> None:
        self.fault_code = code

    def clear(self) -> None:
        self.fault_code = None

    def drop(self) -> bool:
        """True when the next reply is to be lost."""
        return self.drop_rate > 0.0 and self._rng.random() < self.drop_rate

    def corrupt(self, data: bytes) -> bytes:
        """Flip bits in ``data`` at ``bit_error_rate`` per byte."""
        if self.bit_error_rate <= 0.0:
            return data
        out = bytearray(data)
        for i in range(len(out)):
            if self._rng.random() < self.bit_error_rate:
                out[i] ^= 1 << self._rng.randrange(8)
        return bytes(out)
