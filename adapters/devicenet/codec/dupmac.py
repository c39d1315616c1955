"""The Duplicate MAC ID check message (group 2 message 7, carrying the claimed MAC).

Fact sheet 2.3: 7 data bytes; byte 0 = b7 request (0) / response (1) + b6-0
physical port number; Vendor ID (UINT, little-endian); serial number (UDINT,
little-endian). The check procedure (two requests, 1 s apart) belongs to the engine.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from adapters.devicenet.codec.datatypes import CipType, encode_value, read_value
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import (
    MAX_MAC,
    PredefinedMessage,
    match_predefined,
    predefined_can_id,
)
from adapters.devicenet.errors import DupMacDecodeError, UnexpectedCanId
from gateway.errors import require_int

DUPMAC_LENGTH = 7  # fact sheet 2.3
_RESPONSE_BIT = 0x80  # byte 0 b7 (fact sheet 2.3)
_PORT_MASK = 0x7F  # byte 0 b6-0
WEG_VENDOR_ID = 0x0355  # seed table 8: Identity Vendor ID default 355h


def is_request(data: bytes) -> bool:
    """Whether a check message's data bytes are a request of the right length, read without
    decoding them (the scanner counts a flood of requests for its MAC at this cost)."""
    return len(data) == DUPMAC_LENGTH and not data[0] & _RESPONSE_BIT


class DupMacKind(IntEnum):
    """Byte 0 b7 of the check message (fact sheet 2.3)."""

    REQUEST = 0
    RESPONSE = 1


@dataclass(frozen=True, slots=True)
class DupMacCheck:
    """One Duplicate MAC ID check request or response for the MAC being claimed."""

    mac: int
    kind: DupMacKind
    port: int
    vendor_id: int
    serial_number: int

    def __post_init__(self) -> None:
        require_int("MAC ID", self.mac, 0, MAX_MAC)
        require_int("check message kind", self.kind, 0, 1)
        require_int("physical port", self.port, 0, _PORT_MASK)
        require_int("vendor ID", self.vendor_id, 0, CipType.UINT.maximum)
        require_int("serial number", self.serial_number, 0, CipType.UDINT.maximum)
        object.__setattr__(self, "kind", DupMacKind(self.kind))

    def encode_data(self) -> bytes:
        """The 7 data bytes."""
        first = (_RESPONSE_BIT if self.kind is DupMacKind.RESPONSE else 0) | self.port
        return (
            bytes((first,))
            + encode_value(CipType.UINT, self.vendor_id)
            + encode_value(CipType.UDINT, self.serial_number)
        )

    def to_frame(self) -> CanFrame:
        """The frame on G2 message 7 of the claimed MAC."""
        return CanFrame(
            predefined_can_id(PredefinedMessage.DUPLICATE_MAC_CHECK, self.mac), self.encode_data()
        )

    @classmethod
    def decode_data(cls, mac: int, data: bytes) -> DupMacCheck:
        """The message from its data bytes, for the MAC its identifier carries."""
        raw = bytes(data)
        if len(raw) != DUPMAC_LENGTH:
            raise DupMacDecodeError(f"check message of {len(raw)} bytes (7 expected)", raw)
        if not 0 <= mac <= MAX_MAC:
            raise DupMacDecodeError(f"MAC ID {mac} out of 0..63", raw)
        kind = DupMacKind.RESPONSE if raw[0] & _RESPONSE_BIT else DupMacKind.REQUEST
        vendor_id, offset = read_value(CipType.UINT, raw, 1)
        serial, _ = read_value(CipType.UDINT, raw, offset)
        return cls(mac, kind, raw[0] & _PORT_MASK, vendor_id, serial)

    @classmethod
    def from_frame(cls, frame: CanFrame) -> DupMacCheck:
        """Decode a received frame; :class:`UnexpectedCanId` if not on G2 message 7."""
        found = match_predefined(frame.arbitration_id)
        if found is None or found.message is not PredefinedMessage.DUPLICATE_MAC_CHECK:
            raise UnexpectedCanId(
                "not a Duplicate MAC ID check identifier",
                frame.data,
                arbitration_id=frame.arbitration_id,
            )
        return cls.decode_data(found.mac, frame.data)
