"""What one OPC UA session may hold: subscriptions, monitored items, the fastest publishing.

asyncua bounds the subscriptions of the whole server only, and neither the monitored items
nor the publishing interval (a subscription asked at 0 ms publishes at every change, one
asked at 1 ms wakes the loop a thousand times a second). The server's sessions
(gateway/opcua/sessions.py) ask :class:`SessionGuard` before they create:

- a subscription beyond ``[opcua] max_subscriptions`` of its session is refused
  (BadTooManySubscriptions), and its publishing interval is revised up to
  ``min_publishing_interval`` (OPC UA lets the server revise it; asyncua samples a
  subscription's items at its publishing interval, so that floors the sampling too);
- monitored items beyond ``max_monitored_items`` over all the subscriptions of the session
  that owns the subscription are refused one by one (BadTooManyMonitoredItems): the items
  of the request within the limit are created, the rest refused;
- a ModifyMonitoredItems gets its queue sizes revised as asyncua revises them at creation
  (at most ``max_monitored_item_queue_size``; asyncua takes them as asked on a modify,
  and 0 there is a queue without end);
- a subscription transferred from another session counts like one created;
- a session's subscriptions end with it, even when its CloseSession asks to keep them
  (kept, they would be held by no session, out of every limit).

What a session holds is counted from asyncua's own subscriptions each time (never a tally
kept beside them), so a deleted item, a deleted or expired subscription and a closed
session free their room at once. Each refusal is counted (:class:`Refusals`, the front
end's counters) and logged at most once per :data:`LOG_PERIOD` per session and kind.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from enum import Enum

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.server.internal_subscription import InternalSubscription
from asyncua.server.subscription_service import SubscriptionService

from gateway.opcuaconfig import OpcuaSection
from gateway.ratelimit import LogRateLimit

log = logging.getLogger(__name__)

LOG_PERIOD = 10.0  # s: one line per session and kind of refusal
MAX_PUBLISHING_INTERVAL = 3_600_000.0  # ms: a longer (or infinite) one is revised down
ASYNCUA_MAX_SUBSCRIPTIONS = 1_000  # asyncua's own bound for the whole server


class Limit(Enum):
    """What a refusal was about (the front end's counters, by reason)."""

    SUBSCRIPTIONS = "subscriptions"
    MONITORED_ITEMS = "monitored_items"


_STATUS = {
    Limit.SUBSCRIPTIONS: ua.StatusCodes.BadTooManySubscriptions,
    Limit.MONITORED_ITEMS: ua.StatusCodes.BadTooManyMonitoredItems,
}
_KEY = {Limit.SUBSCRIPTIONS: "max_subscriptions", Limit.MONITORED_ITEMS: "max_monitored_items"}


@dataclass(frozen=True, slots=True)
class SessionLimits:
    max_subscriptions: int
    max_monitored_items: int
    min_publishing_interval: float
    """s"""

    @classmethod
    def of(cls, section: OpcuaSection) -> SessionLimits:
        return cls(
            section.max_subscriptions, section.max_monitored_items, section.min_publishing_interval
        )

    def limit(self, kind: Limit) -> int:
        return self.max_subscriptions if kind is Limit.SUBSCRIPTIONS else self.max_monitored_items

    def publishing_interval(self, requested: float) -> float:
        """The interval (ms) a subscription that asked for ``requested`` ms gets: at least
        the floor; NaN gets the floor, beyond an hour (or infinite) an hour."""
        floor = self.min_publishing_interval * 1000.0
        if math.isnan(requested) or requested < floor:
            return floor
        return min(requested, MAX_PUBLISHING_INTERVAL)


def queue_size(requested: int, cap: int) -> int:
    """The queue an item gets, as asyncua revises it at creation: 0 (the server's choice)
    the cap, else at most the cap."""
    return cap if requested <= 0 else min(requested, cap)


@dataclass(frozen=True, slots=True)
class Held:
    """What one session holds now."""

    subscriptions: int = 0
    monitored_items: int = 0


def monitored_items_in(sub: InternalSubscription) -> int:
    """The monitored items of a subscription. asyncua 2.1 keeps them in a private dict of
    its MonitoredItemService and counts them nowhere public: this is the one place that
    reads it (tests/opcua/test_limits.py fails if asyncua moves it)."""
    return len(sub.monitored_item_srv._monitored_items)


def held_by(service: SubscriptionService, session_id: ua.NodeId) -> Held:
    """What the session ``session_id`` holds, counted from the server's subscriptions."""
    subs = [s for s in service.subscriptions.values() if s.session_id == session_id]
    return Held(len(subs), sum(monitored_items_in(s) for s in subs))


class Refusals:
    """Refusals counted by kind, and logged at most once per period per session and kind
    (the line says how many were held back since the last one)."""

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, period: float = LOG_PERIOD
    ) -> None:
        self.clock = clock
        self.counts: dict[Limit, int] = dict.fromkeys(Limit, 0)
        self._log = LogRateLimit(period)

    def refuse(self, client: str, kind: Limit, count: int, limit: int) -> None:
        self.counts[kind] += count
        held = self._log.admit((client, kind), self.clock(), count)
        if held is None:
            return
        more = f" ({held} more refused since the last line)" if held else ""
        log.warning(
            "OPC UA %s: %d %s refused, the session holds its limit of %d ([opcua] %s)%s",
            client,
            count,
            kind.value.replace("_", " "),
            limit,
            _KEY[kind],
            more,
        )

    def by_reason(self) -> dict[str, int]:
        return {k.value: n for k, n in self.counts.items()}


@dataclass(frozen=True, slots=True)
class SessionGuard:
    """The limits of the server's sessions and where their refusals are counted."""

    limits: SessionLimits
    refusals: Refusals

    def admit_subscription(
        self, service: SubscriptionService, session_id: ua.NodeId, client: str
    ) -> None:
        """Raise BadTooManySubscriptions when the session holds its limit."""
        held = held_by(service, session_id).subscriptions
        if held >= self.limits.max_subscriptions:
            self.refusals.refuse(client, Limit.SUBSCRIPTIONS, 1, self.limits.max_subscriptions)
            raise ServiceError(_STATUS[Limit.SUBSCRIPTIONS])

    def revised(self, params: ua.CreateSubscriptionParameters) -> ua.CreateSubscriptionParameters:
        interval = self.limits.publishing_interval(params.RequestedPublishingInterval)
        return replace(params, RequestedPublishingInterval=interval)

    @staticmethod
    def modified(
        params: ua.ModifyMonitoredItemsParameters, cap: int
    ) -> ua.ModifyMonitoredItemsParameters:
        """The queue sizes of a ModifyMonitoredItems revised as asyncua revises them at
        creation (it takes them as asked on a modify: 0 there is a queue without end)."""
        items = [
            replace(
                item,
                RequestedParameters=replace(
                    item.RequestedParameters,
                    QueueSize=queue_size(item.RequestedParameters.QueueSize, cap),
                ),
            )
            for item in params.ItemsToModify
        ]
        return replace(params, ItemsToModify=items)

    def room_for_items(self, service: SubscriptionService, owner: ua.NodeId) -> int:
        """How many more monitored items the session ``owner`` may hold."""
        held = held_by(service, owner).monitored_items
        return max(0, self.limits.max_monitored_items - held)

    def refuse_items(self, client: str, count: int) -> list[ua.MonitoredItemCreateResult]:
        """The answers of ``count`` items over the limit."""
        limit = self.limits.max_monitored_items
        self.refusals.refuse(client, Limit.MONITORED_ITEMS, count, limit)
        status = ua.StatusCode(_STATUS[Limit.MONITORED_ITEMS])
        return [ua.MonitoredItemCreateResult(StatusCode=status) for _ in range(count)]

    def transfer_refusal(
        self, service: SubscriptionService, session_id: ua.NodeId, client: str, sub_id: int
    ) -> ua.TransferResult | None:
        """The answer to a transfer of ``sub_id`` to the session that would take it over
        its limits, else None (asyncua transfers it, or says it does not know it)."""
        sub = service.subscriptions.get(sub_id)
        if sub is None or sub.session_id == session_id:
            return None
        held = held_by(service, session_id)
        kind = None
        if held.subscriptions >= self.limits.max_subscriptions:
            kind = Limit.SUBSCRIPTIONS
        elif held.monitored_items + monitored_items_in(sub) > self.limits.max_monitored_items:
            kind = Limit.MONITORED_ITEMS
        if kind is None:
            return None
        self.refusals.refuse(client, kind, 1, self.limits.limit(kind))
        return ua.TransferResult(StatusCode=ua.StatusCode(_STATUS[kind]))


def server_wide_subscriptions(max_sessions: int, limits: SessionLimits) -> int:
    """asyncua's bound on the subscriptions of the whole server: never below what the
    sessions may hold together, so that the per-session limit is the one that speaks."""
    return max(ASYNCUA_MAX_SUBSCRIPTIONS, max_sessions * limits.max_subscriptions)


class OwnRefusalLines(logging.Filter):
    """Drops asyncua's ERROR line ("sending service fault response") for the refusals the
    guard made and logged itself, once per period: otherwise a client repeating a refused
    CreateSubscription writes one line per request."""

    def __init__(self, codes: Iterable[int] = (_STATUS[Limit.SUBSCRIPTIONS],)) -> None:
        super().__init__()
        self.names = {ua.StatusCode(c).name for c in codes}

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args if isinstance(record.args, tuple) else ()
        return not (
            record.msg == "sending service fault response: %s (%s)"
            and len(args) == 2
            and args[1] in self.names
        )


UAPROCESSOR_LOG = "asyncua.server.uaprocessor"
