"""SocketCAN error frames as the DeviceNet scanner sees them: the shared CAN decoder
(:mod:`adapters.link.canerror`; error frames are the same on every bus over SocketCAN)."""

from __future__ import annotations

from adapters.link.canerror import LineCondition, LineHealth, decode_error_frame, health_after

__all__ = ["LineCondition", "LineHealth", "decode_error_frame", "health_after"]
