"""How long a CAN 2.0A (11-bit identifier) data frame is on the wire, in bit times, sans-IO
(ISO 11898-1): 47 + 8n bits with the 3-bit intermission, of which the 34 + 8n from SOF
to the CRC are stuffed. The shortest (no stuff bit) bounds a wait from below; the
longest (every stuff bit) bounds a cycle from above."""

from __future__ import annotations


def frame_bits(data_bytes: int) -> int:
    """The worst-case length of a data frame with ``data_bytes`` bytes: at worst one stuff
    bit per 4 after the first (Davis, Burns, Bril, Lukkien 2007):
    47 + 8n + floor((34 + 8n - 1) / 4)."""
    stuffed = 34 + 8 * data_bytes  # SOF, id 11, RTR, IDE, r0, DLC 4, data, CRC 15
    return stuffed + 13 + (stuffed - 1) // 4  # CRC delimiter, ACK 2, EOF 7, intermission 3


def frame_bits_min(data_bytes: int) -> int:
    """The shortest a data frame with ``data_bytes`` bytes can be: 47 + 8n with no stuff
    bit at all. A lower bound: the frame can take no less, so a wait computed from it
    never outlasts the earliest time the frame can be there (stuffing adds at most
    (34 + 8n - 1) // 4 bits: 19 % for a 4-byte frame). More than 8 bytes is a fragmented
    message: its first frame at least."""
    return 47 + 8 * min(data_bytes, 8)
