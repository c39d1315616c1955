"""What every benchmark reports: one figure per line, with its in-run reference."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Figure:
    name: str
    value: float
    unit: str
    reference: float | None = None  # the same measure for the reference, in this run
    target: str | None = None  # what the issue asks, e.g. "ratio >= 0.5"
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.reference in (None, 0):
            return None
        return self.value / self.reference

    def to_json(self) -> dict[str, object]:
        out = asdict(self)
        out["ratio"] = None if self.ratio is None else round(self.ratio, 4)
        return out

    def line(self) -> str:
        return json.dumps(self.to_json())
