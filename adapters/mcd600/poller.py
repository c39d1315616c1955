"""The extended-mode data request round robin (installation guide 4.3), one per drive.

Each ``period`` seconds the next request number (1..16) goes out in output byte 2; every
reply whose echo is a number asked since the last (re)connection and whose "invalid"
bit is clear updates the readings. A reading nobody has answered yet is absent (None in
the model): nothing is carried over from an earlier connection or from another drive.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Final

from adapters.mcd600.errors import Mcd600DecodeError
from adapters.mcd600.monitoring import REQUESTS, DataRequest, MonitorReply, Readings, decode_value
from gateway.model import Readings as DriveReadings

log = logging.getLogger(__name__)

MODEL_FIELDS: Final = ("motor_temp_pct", "power_kw", "voltage_v")
"""Readings that are DriveState fields; every other reading goes to ``values``."""


class DataPoller:
    def __init__(self, period: float, current_scale: float = 1.0) -> None:
        self.period = period
        self.current_scale = current_scale
        self._readings: Readings = {}
        self._asked: set[int] = set()
        self._index = -1
        self._sent_at: float | None = None
        self.invalid: set[DataRequest] = set()  # requests the starter flagged invalid
        self.bad_values = 0  # replies whose value did not decode (e.g. power scale 7)

    def reset(self) -> None:
        """Forget everything read (communication lost or re-established)."""
        self._readings = {}
        self._asked = set()
        self._index = -1
        self._sent_at = None
        self.invalid = set()

    @property
    def readings(self) -> Mapping[str, float | int]:
        return self._readings

    def next_request(self, now: float) -> int:
        """The data request number to send this cycle."""
        if self._sent_at is None or now - self._sent_at >= self.period:
            self._index = (self._index + 1) % len(REQUESTS)
            self._sent_at = now
            self._asked.add(int(REQUESTS[self._index]))
        return int(REQUESTS[self._index])

    def take(self, reply: MonitorReply) -> Readings | None:
        """Take a reply; returns the readings it brought (None if it brought nothing)."""
        if reply.echo not in self._asked:
            return None  # 0 (nothing yet) or an echo of a request we did not make
        request = DataRequest(reply.echo)
        if reply.invalid:  # table 5 byte 3 bit 0
            if request not in self.invalid:
                log.warning("MCD 600 flags data request %d as invalid", reply.echo)
            self.invalid.add(request)
            return None
        self.invalid.discard(request)
        try:
            new = decode_value(request, reply.value, self.current_scale)
        except Mcd600DecodeError as exc:
            self.bad_values += 1
            log.warning("MCD 600 data request %d: %s", reply.echo, exc)
            return None
        self._readings.update(new)
        return new

    def model_fields(self) -> DriveReadings:
        """The DriveState fields the readings give (None where not read yet)."""
        got = self._readings.get
        return {
            "motor_temp_pct": _float(got("motor_temp_pct")),
            "power_kw": _float(got("power_kw")),
            "voltage_v": _float(got("voltage_v")),
        }

    def values(self) -> dict[str, float | int]:
        """The readings that are not DriveState fields, for ``DriveState.values``."""
        return {k: v for k, v in self._readings.items() if k not in MODEL_FIELDS}


def _float(value: float | int | None) -> float | None:
    return None if value is None else float(value)
