"""One root for every error the gateway raises.

Leaves also inherit the matching builtin so callers can catch either way:
decode errors are ``ValueError``, timeouts are ``TimeoutError``.
"""

from __future__ import annotations


class GatewayError(Exception):
    """Root of every error raised by drive-gateway."""


class ConfigError(GatewayError, ValueError):
    """A configuration problem, naming the file, the key path and the reason."""

    def __init__(self, file: str, key: str, reason: str) -> None:
        self.file = file
        self.key = key
        self.reason = reason
        where = f"{file}: {key}: " if key else f"{file}: "
        super().__init__(f"{where}{reason}")


class ConfigErrors(GatewayError, ValueError):
    """Several configuration problems found in one pass."""

    def __init__(self, errors: list[ConfigError]) -> None:
        self.errors = list(errors)
        super().__init__("\n".join(str(e) for e in self.errors))


class StartupError(GatewayError):
    """The gateway cannot start (a port in use or not allowed, an endpoint Zenoh cannot
    bind): fatal at start-up, reported as one line naming the cause and the fix."""

    def __init__(self, what: str, cause: str, fix: str) -> None:
        self.what = what
        self.cause = cause
        self.fix = fix
        super().__init__(f"{what}: {cause}; {fix}")


class FrameDecodeError(GatewayError, ValueError):
    """Bytes on a bus that do not decode; carries the raw bytes."""

    def __init__(self, message: str, raw: bytes = b"") -> None:
        self.raw = bytes(raw)
        self.message = message
        super().__init__(f"{message} (raw: {self.raw.hex(' ') or 'none'})")


class FrameEncodeError(GatewayError, ValueError):
    """A value that cannot be put on the wire (out of range, too long)."""


def require_int(what: str, value: object, low: int, high: int) -> int:
    """``value`` if it is an int (not a bool) in ``low..high``, else FrameEncodeError: the
    one range check of every encoder (codecs may import this module of the core)."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise FrameEncodeError(f"{what} must be an integer in {low}..{high}, got {value!r}")
    return value


class GatewayTimeout(GatewayError, TimeoutError):
    """A request that got no answer in time."""


class CommandRejected(GatewayError, ValueError):
    """A command refused before anything of it was applied; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


class StopAppliedRestRefused(CommandRejected):
    """A command that asked for less motion and for something refused: its stop part was
    applied (a stop is never refused, safety rule 1), the rest was not; ``reason`` says
    both."""


class ParameterError(GatewayError):
    """A parameter access refused by the device (its own code and text) or by the gateway."""

    def __init__(self, text: str, code: int | None = None) -> None:
        self.text = text
        self.code = code
        prefix = f"error 0x{code:04X}: " if code is not None else ""
        super().__init__(f"{prefix}{text}")


class ParameterNotWritable(ParameterError):
    """A write to a parameter that the drive's config does not allow (safety rule 5)."""


class AdapterError(GatewayError):
    """A fieldbus adapter failed (port missing, bus down)."""


class LineHeld(AdapterError):
    """Another master already holds the line (safety rule 3, one master per line): a
    serial port locked by another process, the scanner's DeviceNet MAC ID answered by
    another device. The text names the line, the holder where it can be known, and what
    to do. The gateway never becomes a second master: it refuses to start on it."""


class DriveOffline(GatewayError):
    """The drive is not online, so the request cannot be served."""


class UnknownDrive(GatewayError, KeyError):
    """A drive id that the gateway does not have."""


class HistoryError(GatewayError):
    """The history store cannot serve a request (a bad time range, too many rows); the
    text says why and what to ask instead."""
