"""The drives' methods: Run, Stop, QuickStop, Reset, SetSpeed, through the hub.

A method call is a command of the calling session (gateway/opcua/sessions.py) given to
``hub.submit`` as source ``opcua``: the same safety rules and control ownership as the
Zenoh, Modbus and web commands (a run refused while the drive is faulted, latched or
controlled by another source, a stop never refused). The answer is a CallMethodResult:
Good with Result "accepted", or a Bad status with Result the reason (the hub's own words);
the drive's LastCommandResult variable shows the same text.

Status codes of a refusal: BadUserAccessDenied (the session's role may not operate),
BadInvalidArgument (a SetSpeed argument that is not a finite number), BadInvalidState
(refused by the hub: the reason says why), BadNodeIdUnknown (no such drive).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from asyncua import ua

from gateway.adapter import EventKind
from gateway.errors import CommandRejected, GatewayError, UnknownDrive
from gateway.hub import Hub
from gateway.model import DriveCommand, Source
from gateway.opcua.sessions import CALLER, Role, RoleMap

ACCEPTED = "accepted"


def _run(_args: tuple[Any, ...]) -> DriveCommand:
    return DriveCommand(run=True)


def _stop(_args: tuple[Any, ...]) -> DriveCommand:
    return DriveCommand(run=False)


def _quick_stop(_args: tuple[Any, ...]) -> DriveCommand:
    return DriveCommand(quick_stop=True)


def _reset(_args: tuple[Any, ...]) -> DriveCommand:
    return DriveCommand(fault_reset=True, quick_stop=False, coast_stop=False)


def _set_speed(args: tuple[Any, ...]) -> DriveCommand:
    if len(args) != 1:
        raise BadArgument(f"SetSpeed takes one argument, SpeedRpm; {len(args)} given")
    value = args[0]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise BadArgument(f"SpeedRpm must be a finite number, not {value!r}")
    return DriveCommand(speed_rpm=float(value))


class BadArgument(GatewayError, ValueError):
    """A method argument that is not what the method takes."""


COMMANDS: Mapping[str, Callable[[tuple[Any, ...]], DriveCommand]] = {
    "Run": _run,
    "Stop": _stop,
    "QuickStop": _quick_stop,
    "Reset": _reset,
    "SetSpeed": _set_speed,
}
"""Method name -> the command it gives. QuickStop latches; Reset is one fault reset edge
and releases a quick stop or coast stop (the drive stays stopped: Run is needed after it)."""


@dataclass(frozen=True, slots=True)
class Outcome:
    status: int
    text: str

    @property
    def accepted(self) -> bool:
        return bool(self.status == ua.StatusCodes.Good)

    def result(self) -> ua.CallMethodResult:
        res = ua.CallMethodResult()
        res.StatusCode = ua.StatusCode(self.status)
        res.OutputArguments = [ua.Variant(self.text, ua.VariantType.String)]
        return res


class Commands:
    """Submits the drives' method calls to the hub and counts them."""

    def __init__(self, hub: Hub, roles: RoleMap) -> None:
        self.hub = hub
        self.roles = roles
        self.accepted = 0
        self.refused = 0

    def call(self, drive_id: str, method: str, args: tuple[Any, ...]) -> Outcome:
        """The outcome of ``method`` called on ``drive_id`` by the current caller."""
        outcome = self._call(drive_id, method, args)
        if outcome.accepted:
            self.accepted += 1
        else:
            self.refused += 1
        return outcome

    def _call(self, drive_id: str, method: str, args: tuple[Any, ...]) -> Outcome:
        session = CALLER.get()
        client = session.client if session is not None else "internal"
        if session is not None and self.roles(session.user_of()) is not Role.OPERATE:
            reason = (
                f"{client} may not operate drives: a session operates when it logs in as a "
                "user of role operator or above (a server without users: from loopback only)"
            )
            self._refused_event(drive_id, client, reason)
            return Outcome(ua.StatusCodes.BadUserAccessDenied, reason)
        try:
            cmd = COMMANDS[method](args)
        except BadArgument as exc:
            self._refused_event(drive_id, client, str(exc))
            return Outcome(ua.StatusCodes.BadInvalidArgument, str(exc))
        except CommandRejected as exc:
            return Outcome(ua.StatusCodes.BadInvalidArgument, exc.reason)
        try:
            self.hub.submit(drive_id, Source.OPCUA, cmd, client)  # reports its own refusals
        except CommandRejected as exc:
            return Outcome(ua.StatusCodes.BadInvalidState, exc.reason)
        except UnknownDrive:
            return Outcome(ua.StatusCodes.BadNodeIdUnknown, f"no drive {drive_id!r}")
        return Outcome(ua.StatusCodes.Good, ACCEPTED)

    def _refused_event(self, drive_id: str, client: str, reason: str) -> None:
        self.hub.event(
            drive_id,
            EventKind.COMMAND_REFUSED,
            f"command from {Source.OPCUA.value} {client} refused: {reason}",
            source=Source.OPCUA.value,
            client=client,
        )
