"""Typed errors of the CANopen codec layer.

Every decoder in ``adapters.canopen`` raises only subclasses of
:class:`CanOpenDecodeError`, itself a :class:`gateway.errors.FrameDecodeError` (so also
a ``ValueError``). Each carries the raw data bytes and, where known, the COB-ID.
Encoders raise :class:`gateway.errors.FrameEncodeError`.
"""

from __future__ import annotations

from gateway.errors import ConfigError, FrameDecodeError


class CanOpenDecodeError(FrameDecodeError):
    """A CANopen frame that does not decode."""

    def __init__(self, message: str, raw: bytes = b"", *, cob_id: int | None = None) -> None:
        self.cob_id = cob_id
        if cob_id is not None:
            message = f"{message} [COB-ID 0x{cob_id:03X}]"
        super().__init__(message, raw)


class InvalidCobId(CanOpenDecodeError):
    """An identifier that is not 11-bit, or a node id outside 1..127."""


class NmtDecodeError(CanOpenDecodeError):
    """A malformed NMT command or heartbeat frame."""


class SdoDecodeError(CanOpenDecodeError):
    """A malformed SDO frame (wrong length, unknown command specifier, bad size)."""


class SdoProtocolError(CanOpenDecodeError):
    """A well-formed SDO frame that does not fit the transfer in progress (toggle,
    wrong index, wrong specifier); ``abort_code`` is the CiA 301 code to abort with."""

    def __init__(self, message: str, raw: bytes = b"", *, abort_code: int) -> None:
        self.abort_code = abort_code
        super().__init__(message, raw)


class EmcyDecodeError(CanOpenDecodeError):
    """A malformed EMCY frame."""


class Cia402DecodeError(CanOpenDecodeError):
    """A statusword whose state bits match no CiA 402 state."""


class EdsError(ConfigError):
    """An EDS/DCF that does not parse, or lacks an object the configuration needs;
    names the file, the object and the reason."""
