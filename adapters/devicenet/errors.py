"""Typed errors of the DeviceNet codec layer.

Every decoder in ``adapters.devicenet`` raises only subclasses of
:class:`DeviceNetDecodeError`, itself a :class:`gateway.errors.FrameDecodeError`
(so also a ``ValueError``). Each error carries the raw data bytes (``raw``) and,
where known, the CAN identifier they came with (``arbitration_id``).
Encoders raise :class:`gateway.errors.FrameEncodeError`.
"""

from __future__ import annotations

from gateway.errors import ConfigError, FrameDecodeError, GatewayTimeout


class DeviceNetDecodeError(FrameDecodeError):
    """A DeviceNet frame or message that does not decode."""

    def __init__(
        self, message: str, raw: bytes = b"", *, arbitration_id: int | None = None
    ) -> None:
        self.arbitration_id = arbitration_id
        if arbitration_id is not None:
            message = f"{message} [id 0x{arbitration_id:03X}]"
        super().__init__(message, raw)


class InvalidCanFrame(DeviceNetDecodeError):
    """A CAN frame DeviceNet cannot carry (extended id, more than 8 data bytes)."""


class InvalidCanId(DeviceNetDecodeError):
    """An identifier outside the four message groups (0x7F0-0x7FF, or not 11-bit)."""


class UnexpectedCanId(DeviceNetDecodeError):
    """A frame given to a decoder that is not meant for its identifier."""


class DataTypeDecodeError(DeviceNetDecodeError):
    """A CIP elementary value of the wrong length or content."""


class DupMacDecodeError(DeviceNetDecodeError):
    """A malformed Duplicate MAC ID check frame."""


class ExplicitDecodeError(DeviceNetDecodeError):
    """A malformed explicit message.

    Carries what could be read before the fault (``mac``, ``xid``, ``service``) and,
    for a request, ``general_status``: the CIP general status a server should answer
    with (for example 0x13 not enough data, 0x15 too much data), so a simulated slave
    can build its error response from the error alone.
    """

    def __init__(
        self,
        message: str,
        raw: bytes = b"",
        *,
        arbitration_id: int | None = None,
        mac: int | None = None,
        xid: bool | None = None,
        service: int | None = None,
        general_status: int | None = None,
    ) -> None:
        self.mac = mac
        self.xid = xid
        self.service = service
        self.general_status = general_status
        super().__init__(message, raw, arbitration_id=arbitration_id)


class FragmentationError(DeviceNetDecodeError):
    """Root of the fragmentation protocol errors (fact sheet 2.8)."""


class FragmentDecodeError(FragmentationError):
    """A fragment or acknowledge frame that does not decode."""


class FragmentOutOfSequence(FragmentationError):
    """A fragment whose count is not the next one expected (lost, reordered, stray).

    The partial message is discarded; ``expected`` is None when no message was in
    progress (a middle or last fragment without a first).
    """

    def __init__(
        self,
        message: str,
        raw: bytes = b"",
        *,
        expected: int | None = None,
        received: int | None = None,
    ) -> None:
        self.expected = expected
        self.received = received
        super().__init__(message, raw)


class ReassembledTooLong(FragmentationError):
    """A fragmented message that grew beyond the reassembler's bound; discarded."""


class ReassemblyTimeout(FragmentationError):
    """No fragment within the reassembly timeout; ``raw`` holds the partial message."""


class FragmentAckError(FragmentationError):
    """The receiver acknowledged a fragment with a non-zero status."""

    def __init__(self, message: str, raw: bytes = b"", *, status: int) -> None:
        self.status = status
        super().__init__(message, raw)


class FragmentAckTimeout(GatewayTimeout):
    """No acknowledge for a sent fragment in time (sender side)."""


class AssemblyDecodeError(DeviceNetDecodeError):
    """I/O assembly data of the wrong length for its instance (CFW-08 seed 3, table 11)."""


class EdsError(ConfigError):
    """An EDS file that does not parse or says something impossible.

    Names the file, the line (0: the whole file) and the key (``[Section] Key``).
    A :class:`gateway.errors.ConfigError`, so a drive config naming a bad EDS fails
    like any other config error.
    """

    def __init__(self, file: str, line: int, key: str, reason: str) -> None:
        self.line = line
        self.eds_key = key
        where = " ".join(p for p in (f"line {line}:" if line else "", key) if p)
        super().__init__(file, where.removesuffix(":"), reason)
