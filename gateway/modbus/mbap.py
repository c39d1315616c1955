"""The MBAP header of Modbus TCP (Modbus Messaging on TCP/IP Implementation Guide
V1.0b, section 3.1.3), checked before pymodbus frames the request (sans-IO).

``transaction id (2) | protocol id (2, always 0) | length (2) | unit id (1)``,
then the PDU. ``length`` counts the unit id and the PDU: 2 (unit id and a
function code) to 254 (a 253-byte PDU). A stream whose header is wrong cannot be
re-synchronised, so the front end closes that connection.
"""

from __future__ import annotations

from dataclasses import dataclass

from gateway.errors import FrameDecodeError

HEADER_SIZE = 7  # the MBAP header, unit id included
MIN_LENGTH = 2
MAX_LENGTH = 254


class MbapError(FrameDecodeError):
    """A Modbus TCP frame whose MBAP header is invalid."""


@dataclass(frozen=True, slots=True)
class MbapHeader:
    transaction: int
    protocol: int
    length: int
    unit: int

    @property
    def frame_size(self) -> int:
        """Bytes of the whole frame, header included."""
        return 6 + self.length


def parse_header(data: bytes) -> MbapHeader | None:
    """The header at the start of ``data``; None until 7 bytes are there.

    Raises :class:`MbapError` (carrying the raw bytes) for a bad protocol id or length.
    """
    if len(data) < HEADER_SIZE:
        return None
    raw = bytes(data[:HEADER_SIZE])
    header = MbapHeader(
        transaction=int.from_bytes(raw[0:2], "big"),
        protocol=int.from_bytes(raw[2:4], "big"),
        length=int.from_bytes(raw[4:6], "big"),
        unit=raw[6],
    )
    if header.protocol != 0:
        raise MbapError(f"MBAP protocol id {header.protocol} is not 0 (Modbus)", raw)
    if not MIN_LENGTH <= header.length <= MAX_LENGTH:
        raise MbapError(f"MBAP length {header.length} is outside {MIN_LENGTH}..{MAX_LENGTH}", raw)
    return header
