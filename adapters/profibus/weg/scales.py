"""The speed word's base and the motor ratings it comes from (read at connect or configured).

Which ratings a drive needs and what its speed word's full scale means depend on its data
profile (:mod:`.manufacturer`: 8192 = the synchronous speed; :mod:`.profidrive`: 4000h =
P0134); both are expressed in these two values.
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.profibus.weg import words as w
from gateway.model import SpeedScale


@dataclass(frozen=True)
class SpeedBase:
    """What the speed word's full scale means: ``rpm`` at ``full_scale`` (8192 or 4000h)."""

    rpm: float
    full_scale: int
    max_pct: float
    label: str

    def to_raw(self, rpm: float | None, pct: float | None) -> int:
        if rpm is not None:
            return w.speed_to_raw(rpm, self.rpm, self.full_scale)
        if pct is not None:
            return w.speed_to_raw(pct, 100.0, self.full_scale)
        return 0

    def rpm_of(self, raw: int) -> float:
        return w.raw_to_speed(raw, self.rpm, self.full_scale)

    def pct_of(self, raw: int) -> float:
        return w.raw_to_speed(raw, 100.0, self.full_scale)

    def scale(self) -> SpeedScale:
        return SpeedScale(base_rpm=self.rpm, max_pct=self.max_pct, label=self.label)


@dataclass(frozen=True)
class Ratings:
    """Scale parameters read at connect (or fixed by the config)."""

    rated_hz: float | None = None  # P0403
    rated_rpm: float | None = None  # P0402
    sync_rpm: float | None = None  # from the two above (13-bit base)
    max_rpm: float | None = None  # P0134 (PROFIdrive base)
    rated_current_a: float | None = None  # P0401 (frame 20 P0760)
    rated_power_kw: float | None = None  # P0404 (frame 20 P0761)
