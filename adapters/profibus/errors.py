"""Typed errors of the Profibus codec layer (fact sheet part 1, every section).

Every decoder in ``adapters.profibus`` raises only :class:`ProfibusDecodeError` subclasses,
which inherit :class:`gateway.errors.FrameDecodeError` (so also ``ValueError``) and carry the
raw bytes plus a :class:`DecodeFailure` reason that counters can group by. Encoders raise
:class:`gateway.errors.FrameEncodeError`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from enum import Enum, auto

from gateway.errors import FrameDecodeError, FrameEncodeError, GatewayError


class DecodeFailure(Enum):
    """Why bytes did not decode (one value per kind of fault, for counters and tests)."""

    TRUNCATED = auto()  # fewer bytes than the layout needs
    TRAILING_BYTES = auto()  # more bytes than the layout allows
    NO_START_DELIMITER = auto()  # first byte is not SD1/SD2/SD3/SD4/SC
    BAD_LENGTH = auto()  # LE out of range, LE != LEr, second SD2 missing, length field mismatch
    BAD_CHECKSUM = auto()  # FCS mismatch
    BAD_END_DELIMITER = auto()  # ED is not 0x16
    BAD_ADDRESS = auto()  # address extension where none fits, reserved SAP bits
    BAD_FRAME_CONTROL = auto()  # reserved FC bit or unknown function/status code
    BAD_FIELD = auto()  # a field value outside what the layout defines
    UNKNOWN_FUNCTION = auto()  # unknown PDU function / SAP / request id / format
    UNSUPPORTED = auto()  # valid on the wire but not handled by this codec


class ProfibusDecodeError(FrameDecodeError):
    """Bytes that do not decode as a Profibus telegram or PDU."""

    def __init__(self, reason: DecodeFailure, message: str, raw: bytes = b"") -> None:
        self.reason = reason
        super().__init__(message, raw)


class FdlDecodeError(ProfibusDecodeError):
    """An FDL telegram (SD1..SD4, SC) that does not decode (fact sheet 1.2, 1.3)."""


class DpDecodeError(ProfibusDecodeError):
    """A DP-V0 PDU that does not decode (fact sheet 1.4 to 1.9)."""


class Dpv1DecodeError(ProfibusDecodeError):
    """A DP-V1 MSAC_C1 PDU that does not decode (fact sheet 1.10)."""


class ProfidriveDecodeError(ProfibusDecodeError):
    """A PROFIdrive parameter record (index 47) that does not decode (fact sheet 1.11)."""


class WegRecordDecodeError(ProfibusDecodeError):
    """A WEG parameter record (index 48) that does not decode (WEG manuals 4.2.6/5.2.5)."""


def require_length(what: str, data: bytes, low: int, high: int) -> bytes:
    """Return ``bytes(data)`` if its length is in ``low..high``, else FrameEncodeError."""
    if not low <= len(data) <= high:
        raise FrameEncodeError(f"{what} must be {low}..{high} bytes long, got {len(data)}")
    return bytes(data)


@contextmanager
def whole_raw(data: bytes) -> Iterator[None]:
    """Re-raise a decode error from a part of ``data`` so that it carries all of ``data``."""
    try:
        yield
    except ProfibusDecodeError as exc:
        if exc.raw == data:
            raise
        raise type(exc)(exc.reason, exc.message, data) from None


class SteadyRingError(GatewayError):
    """What a steady ring did does not fit its plan (a slave's reply taken for another
    request, a broadcast not due): a fault of the master's, never of the line."""
