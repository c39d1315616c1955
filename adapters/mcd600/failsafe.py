"""The MCD 600's own reaction to a lost master, from the drive's config alone.

Installation guide 3.3 (seeds/danfoss-mcd600-profibus.pt.txt l.171-179): when the network
fails the card leaves data exchange after the master's DP watchdog expires; after the
communication timeout of the GSD user data (0-100 s, default 10 s) the starter is forced
to a trip state, whose kind parameter 6-13 Network Communications sets (2.3 note l.139-141:
with Soft Trip and Log or Trip Starter it must be reset). A timeout of 0 leaves the
starter's state unchanged: "NÃO é à prova de falhas" (not fail-safe).

The guide gives no bus number for 6-13 (the programming structure of 4.4 uses one-byte
numbers from the starter's own list, not in the guide), so the gateway cannot read it: the
site states it with ``network_comms`` (what is set on the starter's keypad). Unstated, the
reaction after the timeout is unknown (``failsafe`` None).
"""

from __future__ import annotations

from typing import Final

from adapters.mcd600.paramtable import NetworkCommsAction

NETWORK_COMMS_NAMES: Final[dict[str, NetworkCommsAction]] = {
    "soft_trip_and_log": NetworkCommsAction.SOFT_TRIP_AND_LOG,
    "trip_starter": NetworkCommsAction.TRIP_STARTER,
    "warn_and_log": NetworkCommsAction.WARN_AND_LOG,
    "log_only": NetworkCommsAction.LOG_ONLY,
}
"""``network_comms`` values: parameter 6-13 Network Communications (guide 2.3, 3.3)."""

STOPS: Final = frozenset({NetworkCommsAction.SOFT_TRIP_AND_LOG, NetworkCommsAction.TRIP_STARTER})
"""6-13 settings that stop the motor (a trip: 2.3 note); the others only warn or log."""

_LABELS: Final[dict[NetworkCommsAction, str]] = {
    NetworkCommsAction.SOFT_TRIP_AND_LOG: "Soft Trip and Log: soft stop, then a trip",
    NetworkCommsAction.TRIP_STARTER: "Trip Starter: the starter trips, the motor coasts",
    NetworkCommsAction.WARN_AND_LOG: "Warn and Log: the starter keeps running",
    NetworkCommsAction.LOG_ONLY: "Log Only: the starter keeps running",
}


def failsafe_of(
    comm_timeout: int, network_comms: NetworkCommsAction | None
) -> tuple[bool | None, str]:
    """(``failsafe``, ``failsafe_text``) of the starter: False with a timeout of 0 or a
    6-13 that keeps running, True with one that trips, None when 6-13 is not stated."""
    if comm_timeout == 0:
        return False, (
            "comm_timeout = 0: the starter keeps its state when the master is lost "
            "(guide 3.3: not fail-safe)"
        )
    after = f"comm_timeout = {comm_timeout} s after the DP watchdog, then 6-13 Network Comms"
    if network_comms is None:
        return None, f"{after} (not readable over the card; state it with network_comms)"
    return network_comms in STOPS, f"{after} = {_LABELS[network_comms]} (as configured)"


def failsafe_warning(
    comm_timeout: int, network_comms: NetworkCommsAction | None, watchdog: float
) -> str | None:
    """``check-config``: the line to warn with, or None when the starter stops on its own
    once the master is gone (a DP ``watchdog`` of 0 means the card never sees it go, 3.3)."""
    failsafe, text = failsafe_of(comm_timeout, network_comms)
    if not watchdog:
        return (
            "watchdog = 0: the DP watchdog is off, the card never leaves data exchange when "
            "the master is lost, so its comm timeout and 6-13 never act (guide 3.3)"
        )
    if failsafe is False:
        return f"no fail-safe reaction to a lost master: {text}"
    if failsafe is None:
        return f"reaction to a lost master unknown: {text}"
    return None
