"""Programming structure of the MCD 600 PROFIBUS card (parameter upload/download mode).

Installation guide 4.4: outputs bytes 3-6 (table 7) carry the parameter number, a read or a
write flag and the value to write (high byte first); inputs bytes 6-9 (table 8) echo the
number, flag an invalid number or value and carry the value read (high byte first).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Self

from adapters.mcd600.errors import require_size
from gateway.errors import require_int

REQUEST_SIZE: Final = 4
REPLY_SIZE: Final = 4
PARAM_NUMBER_MAX: Final = 255  # one byte (table 7, byte 3)
PARAM_VALUE_MAX: Final = 0xFFFF  # two bytes (table 7, bytes 5-6)

READ_BIT: Final = 1  # table 7 byte 4 bit 1
WRITE_BIT: Final = 2  # table 7 byte 4 bit 2
INVALID_NUMBER_BIT: Final = 0  # table 8 byte 7 bit 0
INVALID_VALUE_BIT: Final = 1  # table 8 byte 7 bit 1


@dataclass(frozen=True, slots=True)
class ParamRequest:
    """Output bytes 3-6 (guide 4.4.1 table 7). All zero = no request."""

    number: int = 0  # byte 3
    read: bool = False  # byte 4 bit 1
    write: bool = False  # byte 4 bit 2
    value: int = 0  # bytes 5 (high) and 6 (low); 0 for a read

    @property
    def idle(self) -> bool:
        return not (self.read or self.write)

    def encode(self) -> bytes:
        number = require_int("parameter number", self.number, 0, PARAM_NUMBER_MAX)
        value = require_int("parameter value", self.value, 0, PARAM_VALUE_MAX)
        flags = self.read << READ_BIT | self.write << WRITE_BIT
        return bytes((number, flags, value >> 8, value & 0xFF))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        number, flags, high, low = require_size("parameter request", data, REQUEST_SIZE)
        return cls(
            number=number,
            read=bool(flags >> READ_BIT & 1),
            write=bool(flags >> WRITE_BIT & 1),
            value=high << 8 | low,
        )


IDLE: Final = ParamRequest()


@dataclass(frozen=True, slots=True)
class ParamReply:
    """Input bytes 6-9 (guide 4.4.2 table 8)."""

    echo: int = 0  # byte 6: echoed parameter number
    invalid_number: bool = False  # byte 7 bit 0
    invalid_value: bool = False  # byte 7 bit 1
    value: int = 0  # bytes 8 (high) and 9 (low)

    def encode(self) -> bytes:
        echo = require_int("parameter echo", self.echo, 0, PARAM_NUMBER_MAX)
        value = require_int("parameter value", self.value, 0, PARAM_VALUE_MAX)
        flags = self.invalid_number << INVALID_NUMBER_BIT | self.invalid_value << INVALID_VALUE_BIT
        return bytes((echo, flags, value >> 8, value & 0xFF))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        echo, flags, high, low = require_size("parameter reply", data, REPLY_SIZE)
        return cls(
            echo=echo,
            invalid_number=bool(flags >> INVALID_NUMBER_BIT & 1),
            invalid_value=bool(flags >> INVALID_VALUE_BIT & 1),
            value=high << 8 | low,
        )


PARAM_ERROR_TEXTS: Final[dict[int, str]] = {  # table 8 byte 7, as ParameterError codes
    1 << INVALID_NUMBER_BIT: "invalid parameter number",
    1 << INVALID_VALUE_BIT: "invalid parameter value",
}
