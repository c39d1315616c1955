"""WEG parameter access through DP-V1 data record 48 (slot 0, index 48).

Sans-IO codec written from the WEG manuals: CFW-11 4.2.6 "Estrutura de Dados para Acesso aos
Parâmetros - WEG", CFW700 5.2.5 and CFW320 5.2.4 "Data Structure for Parameter Access - WEG":

* change: DS_Write with 4 data bytes, parameter number then value, most significant byte
  first; the write reply says whether the change was made;
* read: DS_Write with 2 data bytes (the parameter number), then DS_Read whose reply holds
  2 bytes, the parameter value. The DS_Read asks for 240 bytes: the record 48 sections use
  "the telegrams described in the section 4.2.3" (CFW-11, CFW700; CFW320 5.2.3), whose
  DS_Read request has "Tamanho 240 (solicita o número máximo de bytes de leitura)";
* errors come back as DP-V1 error PDUs with the Error_Code_1 values of
  :data:`adapters.profibus.codec.dpv1.WEG_ERROR_CODE_1_TEXTS`.

Values are the raw 16-bit words (0..65535); signedness and scaling are the profile's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Self

from adapters.profibus.codec.dpv1 import MAX_DATA, WEG_ERROR_CODE_1_TEXTS, ReadRequest, WriteRequest
from adapters.profibus.errors import DecodeFailure, WegRecordDecodeError
from gateway.errors import require_int

WEG_RECORD_INDEX: Final = 48
WEG_SLOT: Final = 0
VALUE_LENGTH: Final = 2  # the DS_Read reply carries 2 bytes
READ_LENGTH: Final = MAX_DATA  # the DS_Read request asks for 240 bytes (4.2.3 telegram)
ERROR_TEXTS: Final = WEG_ERROR_CODE_1_TEXTS


def _fail(reason: DecodeFailure, message: str, raw: bytes) -> WegRecordDecodeError:
    return WegRecordDecodeError(reason, message, raw)


@dataclass(frozen=True)
class WegSelect:
    """DS_Write data of a read: the 2-byte parameter number to be read next."""

    number: int

    def encode(self) -> bytes:
        return require_int("parameter number", self.number, 0, 0xFFFF).to_bytes(2, "big")


@dataclass(frozen=True)
class WegWrite:
    """DS_Write data of a change: parameter number then value, 2 bytes each."""

    number: int
    value: int

    def encode(self) -> bytes:
        number = require_int("parameter number", self.number, 0, 0xFFFF)
        value = require_int("parameter value", self.value, 0, 0xFFFF)
        return number.to_bytes(2, "big") + value.to_bytes(2, "big")


WegWriteData = WegSelect | WegWrite


def decode_write_data(data: bytes) -> WegWriteData:
    """Simulator side: 2 bytes select a parameter to read, 4 bytes change one."""
    data = bytes(data)
    if len(data) == 2:
        return WegSelect(int.from_bytes(data, "big"))
    if len(data) == 4:
        return WegWrite(int.from_bytes(data[:2], "big"), int.from_bytes(data[2:], "big"))
    raise _fail(DecodeFailure.BAD_LENGTH, f"record 48 write of {len(data)} bytes (2 or 4)", data)


@dataclass(frozen=True)
class WegValue:
    """DS_Read reply data: the 2-byte value of the selected parameter."""

    value: int

    def encode(self) -> bytes:
        return require_int("parameter value", self.value, 0, 0xFFFF).to_bytes(2, "big")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        if len(data) != VALUE_LENGTH:
            raise _fail(DecodeFailure.BAD_LENGTH, f"record 48 value of {len(data)} bytes", data)
        return cls(int.from_bytes(data, "big"))


def select_request(number: int, slot: int = WEG_SLOT) -> WriteRequest:
    """Read, step 1: DS_Write(slot 0, index 48, parameter number)."""
    return WriteRequest(slot, WEG_RECORD_INDEX, WegSelect(number).encode())


def read_request(slot: int = WEG_SLOT) -> ReadRequest:
    """Read, step 2: DS_Read(slot 0, index 48, 240 bytes); the reply holds 2."""
    return ReadRequest(slot, WEG_RECORD_INDEX, READ_LENGTH)


def write_request(number: int, value: int, slot: int = WEG_SLOT) -> WriteRequest:
    """Change: DS_Write(slot 0, index 48, parameter number + value)."""
    return WriteRequest(slot, WEG_RECORD_INDEX, WegWrite(number, value).encode())
