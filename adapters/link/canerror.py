"""SocketCAN error frames, sans-IO: the error class in the identifier, details in the data.

Fact sheet Part 3 "Errors and bus-off on socketcan" [PC][LNX]: error frames arrive with
``is_error_frame``; the error class bits are in the identifier and the controller
details in ``data[1]``. The link (:mod:`.can`) reports each as the conditions this
module names; what they make of the line's health is :mod:`adapters.can.health`.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import Enum


class LineCondition(Enum):
    """What an error frame reports about the line."""

    TX_TIMEOUT = "tx timeout"
    LOST_ARBITRATION = "lost arbitration"
    CONTROLLER = "controller problem"
    PROTOCOL = "protocol violation"
    TRANSCEIVER = "transceiver problem"
    NO_ACK = "no ACK"
    BUS_OFF = "bus-off"
    BUS_ERROR = "bus error"
    RESTARTED = "restarted"
    RX_OVERFLOW = "rx buffer overflow"
    TX_OVERFLOW = "tx buffer overflow"
    ERROR_WARNING = "error warning"
    ERROR_PASSIVE = "error passive"
    ERROR_ACTIVE = "error active"  # back to error active: the warning or passive state ended


# Error class bits of the identifier (fact sheet Part 3, table).
ERROR_CLASS_BITS: Mapping[int, LineCondition] = {
    0x001: LineCondition.TX_TIMEOUT,
    0x002: LineCondition.LOST_ARBITRATION,
    0x004: LineCondition.CONTROLLER,
    0x008: LineCondition.PROTOCOL,
    0x010: LineCondition.TRANSCEIVER,
    0x020: LineCondition.NO_ACK,
    0x040: LineCondition.BUS_OFF,
    0x080: LineCondition.BUS_ERROR,
    0x100: LineCondition.RESTARTED,
}

# Controller details, data[1] (fact sheet Part 3: 0x01/0x02 RX/TX overflow,
# 0x04/0x08 warning, 0x10/0x20 passive; [LNX] error.h: 0x40 CAN_ERR_CRTL_ACTIVE,
# "recovered to error active state").
CONTROLLER_BITS: Mapping[int, LineCondition] = {
    0x01: LineCondition.RX_OVERFLOW,
    0x02: LineCondition.TX_OVERFLOW,
    0x04: LineCondition.ERROR_WARNING,
    0x08: LineCondition.ERROR_WARNING,
    0x10: LineCondition.ERROR_PASSIVE,
    0x20: LineCondition.ERROR_PASSIVE,
    0x40: LineCondition.ERROR_ACTIVE,
}
CONTROLLER_DETAIL_INDEX = 1


def decode_error_frame(error_class: int, data: bytes) -> frozenset[LineCondition]:
    """The conditions one error frame reports; unknown bits are ignored, never an error."""
    found = {cond for bit, cond in ERROR_CLASS_BITS.items() if error_class & bit}
    if error_class & 0x004 and len(data) > CONTROLLER_DETAIL_INDEX:
        detail = data[CONTROLLER_DETAIL_INDEX]
        found.update(cond for bit, cond in CONTROLLER_BITS.items() if detail & bit)
    return frozenset(found)
