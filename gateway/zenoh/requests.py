"""Sans-IO handling of what arrives on the Zenoh keys: payload bytes in, typed requests out,
and the JSON bodies of the replies.

Nothing here touches Zenoh or the hub; every problem with a request is a typed
error carrying the text the client gets back.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import orjson

from gateway import jsontext
from gateway.adapter import ParamInfo, ParamValue
from gateway.errors import CommandRejected, GatewayError, ParameterError
from gateway.model import (
    DriveCommand,
    DriveState,
    DriveStatus,
)
from gateway.paramsbackup import parse_numbers

PARAM_NUMBER_MAX = 65535
PARAM_SUBINDEX_MAX = 65535


class BadRequest(GatewayError, ValueError):
    """A query the gateway cannot serve as asked; ``text`` goes back in the error reply."""

    def __init__(self, text: str) -> None:
        self.text = text
        super().__init__(text)


@dataclass(frozen=True, slots=True)
class Answer:
    """One reply to a query: ``ok`` is a normal reply on ``key``, else an error reply."""

    ok: bool
    payload: bytes
    key: str = ""

    @classmethod
    def reply(cls, key: str, body: Any) -> Answer:
        return cls(True, encode_json(body), key)

    @classmethod
    def error(cls, body: Mapping[str, Any]) -> Answer:
        return cls(False, encode_json(body))

    @classmethod
    def refusal(cls, text: str) -> Answer:
        return cls.error({"error": text})


def encode_json(obj: Any) -> bytes:
    """Compact JSON; anything JSON cannot hold becomes its text (never an exception)."""
    return json.dumps(obj, separators=(",", ":"), default=str).encode()


def _finite(value: Any) -> Any:
    return value if value is None or math.isfinite(value) else None


def _sanitise(obj: Any) -> Any:
    if isinstance(obj, float):
        return _finite(obj)
    if isinstance(obj, dict):
        return {k: _sanitise(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_sanitise(v) for v in obj]
    return obj


def encode_state(state: DriveState) -> bytes:
    """The published form of a state: ``DriveState.to_json()`` as compact JSON.

    Hot path of the fan-out. The state's fields, in the order of the JSON form
    (:data:`gateway.model.PUBLISHED_FIELDS`), go to orjson with the enums given as their
    JSON text; orjson writes a non-finite number as null. A value it cannot write (an
    integer beyond 64 bits, a mapping that is no dict, a key that is no string)
    falls back to ``to_json`` with every non-finite number made null.
    """
    doc = state.__dict__.copy()  # its fields in PUBLISHED_FIELDS order (checked at import)
    doc["status"] = _STATUS_TEXT[doc["status"]]  # an IntEnum: its hash is int's
    # the plain Enums by their value (hashing one runs Python code); spelt out, not a
    # loop over the names: a tenth of the encoder's work
    doc["device"] = doc["device"]._value_
    doc["comm"] = doc["comm"]._value_
    doc["direction"] = doc["direction"]._value_
    doc["control_source"] = doc["control_source"]._value_
    try:
        return orjson.dumps(doc)
    except TypeError:  # orjson.JSONEncodeError
        return encode_json(_sanitise(state.to_json()))


_STATUS_TEXT = {m: m.label for m in DriveStatus}


MAX_PAYLOAD = 4096
"""Bytes: a command or parameter payload above this is refused before it is copied
or parsed (a command is under 200 bytes; docs/zenoh-keys.md)."""


def too_large(size: int) -> str:
    """The refusal of a payload of ``size`` bytes over :data:`MAX_PAYLOAD`."""
    return f"payload of {size} bytes is over the limit of {MAX_PAYLOAD} bytes"


def decode_json(payload: bytes) -> Any:
    """Parse a JSON payload; raises ValueError with a short reason."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(too_large(len(payload)))
    try:
        return jsontext.loads(payload.decode("utf-8"))
    except jsontext.DuplicateKey as exc:
        raise ValueError(f"invalid JSON: {exc}") from None
    except UnicodeDecodeError:
        raise ValueError("payload is not UTF-8") from None
    except RecursionError:
        raise ValueError("invalid JSON: nested too deeply") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"invalid JSON: {exc.msg} at position {exc.pos}") from None


# ---------------------------------------------------------------- commands


def parse_command(payload: bytes | None) -> DriveCommand:
    """A command payload -> DriveCommand; every problem is a CommandRejected with the reason."""
    if not payload:
        raise CommandRejected("a command is a JSON object, and the payload is empty")
    try:
        data = decode_json(payload)
    except ValueError as exc:
        raise CommandRejected(str(exc)) from None
    return DriveCommand.from_json(data)


def command_accepted() -> dict[str, Any]:
    return {"accepted": True}


def command_refused(reason: str) -> dict[str, Any]:
    return {"accepted": False, "error": reason}


# ---------------------------------------------------------------- parameters


@dataclass(frozen=True, slots=True)
class ParamRequest:
    """A read (``value`` None) or a write of one parameter."""

    number: int
    subindex: int = 0
    value: ParamValue | None = None

    @property
    def is_write(self) -> bool:
        return self.value is not None


def _index(text: str, what: str, maximum: int) -> int:
    """A decimal number, or a hexadecimal one with 0x (a CANopen object: params/0x6083)."""
    if text[:2].lower() == "0x":
        digits = text[2:]
        if not digits or not all(c in "0123456789abcdefABCDEF" for c in digits):
            raise BadRequest(f"{what} must be 0x and hexadecimal digits, not {text!r}")
        value = int(digits, 16)
    elif not text.isascii() or not text.isdigit():
        raise BadRequest(f"{what} must be a decimal number, not {text!r}")
    else:
        value = int(text)
    if value > maximum:
        raise BadRequest(f"{what} {value} is beyond {maximum}")
    return value


def parse_param_request(rest: tuple[str, ...], payload: bytes | None) -> ParamRequest:
    """``rest``: the key chunks after ``params/`` (number and optional subindex)."""
    if not rest or len(rest) > 2:
        raise BadRequest("a parameter key is params/<number> or params/<number>/<subindex>")
    number = _index(rest[0], "parameter number", PARAM_NUMBER_MAX)
    subindex = _index(rest[1], "subindex", PARAM_SUBINDEX_MAX) if len(rest) == 2 else 0
    return ParamRequest(number, subindex, _write_value(payload))


def _write_value(payload: bytes | None) -> ParamValue | None:
    if not payload:
        return None
    try:
        data = decode_json(payload)
    except ValueError as exc:
        raise BadRequest(str(exc)) from None
    if not isinstance(data, dict) or "value" not in data:
        raise BadRequest('a parameter write is {"value": V}')
    unknown = sorted(set(data) - {"value"})
    if unknown:
        raise BadRequest(f"unknown field(s): {', '.join(unknown)}")
    value = data["value"]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadRequest(f"value must be a number, not {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise BadRequest("value must be a finite number")
    return value


@dataclass(frozen=True, slots=True)
class BackupRequest:
    """A query on ``<prefix>/drives/<id>/params``: ``numbers`` None = the drive's table."""

    numbers: tuple[tuple[int, int], ...] | None = None
    describe: bool = False


BACKUP_PARAMETERS = frozenset({"numbers", "describe"})


def parse_backup_request(parameters: str) -> BackupRequest:
    """The selector's parameters: ``numbers=100-103,134`` and ``describe``."""
    given: dict[str, str] = {}
    for part in filter(None, parameters.split(";")):
        name, _, value = part.partition("=")
        given[name] = value
    unknown = sorted(set(given) - BACKUP_PARAMETERS)
    if unknown:
        raise BadRequest(
            f"unknown selector parameter(s): {', '.join(unknown)} (known: describe, numbers)"
        )
    numbers = parse_numbers(given["numbers"]) if "numbers" in given else None
    return BackupRequest(numbers, "describe" in given)


def param_result(
    req: ParamRequest, value: ParamValue, info: ParamInfo | None = None
) -> dict[str, Any]:
    """The reply: number, subindex and raw value, and where the drive's parameter table
    knows the parameter, its ``code`` as the manual writes it, ``name``, ``unit`` and the
    value in that unit (``scaled``)."""
    body: dict[str, Any] = {"number": req.number, "subindex": req.subindex, "value": value}
    if info is not None:
        body.update(code=info.label, name=info.name, unit=info.unit, scaled=info.scaled(value))
    return body


def error_body(exc: BaseException) -> dict[str, Any]:
    """The error reply for a failed request: the device's own text and code where it has one."""
    if isinstance(exc, ParameterError):
        body: dict[str, Any] = {"error": exc.text}
        if exc.code is not None:
            body["code"] = exc.code
        return body
    if isinstance(exc, BadRequest):
        return {"error": exc.text}
    if isinstance(exc, KeyError) and exc.args:
        return {"error": str(exc.args[0])}
    return {"error": str(exc) or type(exc).__name__}
