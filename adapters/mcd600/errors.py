"""Typed errors of the MCD 600 codecs.

Every decoder in ``adapters.mcd600`` raises only :class:`Mcd600DecodeError` (a
:class:`gateway.errors.FrameDecodeError`, so also a ``ValueError``) carrying the raw bytes;
encoders raise :class:`gateway.errors.FrameEncodeError`.
"""

from __future__ import annotations

from gateway.errors import FrameDecodeError


class Mcd600DecodeError(FrameDecodeError):
    """Bytes that do not decode as an MCD 600 PROFIBUS card structure."""


def require_size(what: str, data: bytes, size: int) -> bytes:
    """``bytes(data)`` if it is exactly ``size`` bytes long, else Mcd600DecodeError."""
    raw = bytes(data)
    if len(raw) != size:
        raise Mcd600DecodeError(f"{what} is {size} bytes, got {len(raw)}", raw)
    return raw
