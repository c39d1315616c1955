"""The MCD 600 card's external diagnosis telegram (installation guide 5.1).

Three bytes: byte 0 the user diagnosis length (always 3, which is also the header of a
device-related diagnosis block: length including itself), byte 1 the trip code (5.1.1),
byte 2 the number of a parameter changed on the starter's keypad (5.1.2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Self

from adapters.mcd600.errors import Mcd600DecodeError
from gateway.errors import require_int

DIAG_LENGTH: Final = 3  # 5.1 byte 0: "always = 3"


@dataclass(frozen=True, slots=True)
class ExtDiag:
    trip_code: int = 0  # byte 1 (5.1.1): 0 = no trip
    changed_param: int = 0  # byte 2 (5.1.2): 0 = none changed

    @property
    def empty(self) -> bool:
        return self.trip_code == 0 and self.changed_param == 0

    def encode(self) -> bytes:
        """The guide's telegram, byte 0 (length 3) included."""
        trip = require_int("trip code", self.trip_code, 0, 255)
        param = require_int("changed parameter number", self.changed_param, 0, 255)
        return bytes((DIAG_LENGTH, trip, param))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """The telegram with its length byte (3 bytes, byte 0 = 3) or without it (2 bytes)."""
        raw = bytes(data)
        if len(raw) == DIAG_LENGTH:
            if raw[0] != DIAG_LENGTH:
                raise Mcd600DecodeError(f"diagnosis length byte is {raw[0]}, not 3", raw)
            raw = raw[1:]
        if len(raw) != DIAG_LENGTH - 1:
            raise Mcd600DecodeError(
                f"external diagnosis is 3 bytes (or 2 without the length), got {len(data)}",
                bytes(data),
            )
        return cls(trip_code=raw[0], changed_param=raw[1])
