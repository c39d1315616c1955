"""OPC UA sessions as the gateway's clients: who calls a method, and what they may do.

Safety rule 3: control belongs to a client, not to a protocol. An OPC UA client is its
session: the server names it ``session <id>`` (an id the server chose, which a client
cannot pick or copy), and every method call it makes is submitted to the hub under that
name. asyncua gives a method callback its object and arguments only, so the server makes
its sessions of :class:`GatewaySession`, which marks the calling session in a context
variable for the time of its Call request (the callbacks run inside it).

Roles: :data:`RoleMap` maps a session's user to a :class:`Role`. The default
(:func:`default_roles`) lets every session operate when the server listens on loopback
only (the demo), and lets none operate elsewhere: commanding drives over the network
waits for users mapped to roles (:func:`set_role_map` is the hook a user directory plugs
into; reading and subscribing stay open to every session).

Limits: what a client's session may hold (subscriptions, monitored items, the fastest
publishing) is checked by its :class:`~gateway.opcua.limits.SessionGuard` before asyncua
creates it (gateway/opcua/limits.py); the server's own session has none.
"""

from __future__ import annotations

import contextvars
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

from asyncua import ua
from asyncua.server.internal_server import InternalServer
from asyncua.server.internal_session import InternalSession

from gateway.opcua.limits import SessionGuard
from gateway.opcuaconfig import OpcuaSection, is_loopback


class Role(Enum):
    """What a session may do."""

    OBSERVE = "observe"  # browse, read, subscribe, read history
    OPERATE = "operate"  # and call the drives' methods, acknowledge alarms


@dataclass(frozen=True, slots=True)
class SessionUser:
    """Who a session is, as a role map sees it."""

    client: str
    """The hub's name of the session: ``session <id>``."""
    user_name: str | None
    """The user name the session activated with (None: anonymous or a certificate)."""
    peer: str
    """The client's address as the server saw it."""


RoleMap = Callable[[SessionUser], Role]


def default_roles(section: OpcuaSection) -> RoleMap:
    """Every session operates on a loopback-only server; elsewhere none does until users
    and roles are configured."""
    role = Role.OPERATE if is_loopback(section.host) else Role.OBSERVE
    return lambda _user: role


class GatewaySession(InternalSession):  # type: ignore[misc]
    """An asyncua session that marks itself as the caller of its method calls and keeps
    the time of its last request (the command watchdog of the drives it controls)."""

    last_request: float = 0.0
    guard: SessionGuard | None = None
    """The limits of a client's session (None: the server's own session)."""

    async def call(self, params: list[ua.CallMethodRequest]) -> list[ua.CallMethodResult]:
        token = CALLER.set(self)
        try:
            results: list[ua.CallMethodResult] = await super().call(params)
            return results
        finally:
            CALLER.reset(token)

    async def create_subscription(
        self,
        params: ua.CreateSubscriptionParameters,
        callback: Callable[..., Any],
        request_callback: Callable[..., Any] | None = None,
    ) -> ua.CreateSubscriptionResult:
        if self.guard is not None:
            self.guard.admit_subscription(self.subscription_service, self.session_id, self.client)
            params = self.guard.revised(params)
        result: ua.CreateSubscriptionResult = await super().create_subscription(
            params, callback, request_callback
        )
        return result

    async def create_monitored_items(
        self, params: ua.CreateMonitoredItemsParameters
    ) -> list[ua.MonitoredItemCreateResult]:
        """The items within the limit of the subscription's session are created, the rest
        refused one by one (an unknown subscription: asyncua's answer)."""
        sub = self.subscription_service.subscriptions.get(params.SubscriptionId)
        if self.guard is None or sub is None:
            return await self._create_items(params)
        room = self.guard.room_for_items(self.subscription_service, sub.session_id)
        items = list(params.ItemsToCreate)
        if len(items) <= room:
            return await self._create_items(params)
        created = await self._create_items(replace(params, ItemsToCreate=items[:room]))
        return created + self.guard.refuse_items(self.client, len(items) - room)

    async def _create_items(
        self, params: ua.CreateMonitoredItemsParameters
    ) -> list[ua.MonitoredItemCreateResult]:
        if not params.ItemsToCreate:
            return []
        results: list[ua.MonitoredItemCreateResult] = await super().create_monitored_items(params)
        return results

    async def modify_monitored_items(
        self, params: ua.ModifyMonitoredItemsParameters
    ) -> list[ua.MonitoredItemModifyResult]:
        """The queue sizes revised as at creation (gateway/opcua/limits.py). asyncua
        echoes the sampling interval asked for; the items are sampled at their
        subscription's (revised) publishing interval, which the answer says."""
        if self.guard is not None:
            params = self.guard.modified(params, self.iserver.max_monitored_item_queue_size)
        results: list[ua.MonitoredItemModifyResult] = await super().modify_monitored_items(params)
        sub = self.subscription_service.subscriptions.get(params.SubscriptionId)
        if self.guard is not None and sub is not None:
            for result in results:
                result.RevisedSamplingInterval = sub.data.RevisedPublishingInterval
        return results

    async def transfer_subscriptions(
        self, params: ua.TransferSubscriptionsParameters, callback: Callable[..., Any]
    ) -> list[ua.TransferResult]:
        """A subscription taken over from another session counts like one created: over
        this session's limits it stays where it was."""
        if self.guard is None:
            results: list[ua.TransferResult] = await super().transfer_subscriptions(
                params, callback
            )
            return results
        out: list[ua.TransferResult] = []
        for sub_id in params.SubscriptionIds:
            result = self.guard.transfer_refusal(
                self.subscription_service, self.session_id, self.client, int(sub_id)
            )
            if result is None:
                one = replace(params, SubscriptionIds=[sub_id])
                (result,) = await super().transfer_subscriptions(one, callback)
            out.append(result)
        return out

    async def close_session(self, delete_subs: bool = True) -> None:
        """A client's session takes its subscriptions with it, whatever its CloseSession
        asks: one kept for a later TransferSubscriptions would be held by no session, out
        of every session's limits (a client could pile them up, closing and reopening)."""
        await super().close_session(delete_subs or self.guard is not None)

    def touch(self) -> None:
        super().touch()
        self.last_request = time.monotonic()

    @property
    def client(self) -> str:
        return f"session {self.session_id.Identifier}"

    def user_of(self) -> SessionUser:
        name = getattr(self.user, "name", None)
        return SessionUser(client=self.client, user_name=name, peer=str(self.name))


CALLER: contextvars.ContextVar[GatewaySession | None] = contextvars.ContextVar(
    "opcua_caller", default=None
)


class Sessions:
    """The open sessions of one server, at most ``limit`` at once."""

    def __init__(
        self, iserver: InternalServer, limit: int, guard: SessionGuard | None = None
    ) -> None:
        self._iserver = iserver
        self.limit = limit
        self.guard = guard
        self._open: dict[str, GatewaySession] = {}
        self.refused = 0
        self.opened = 0
        iserver.create_session = self._create

    def _create(self, name: str, user: Any = None, external: bool = False) -> InternalSession:
        self._forget_closed()
        if external and len(self._open) >= self.limit:
            self.refused += 1
            raise ua.UaStatusCodeError(ua.StatusCodes.BadTooManySessions)
        kwargs: dict[str, Any] = {} if user is None else {"user": user}
        iserver = self._iserver
        session = GatewaySession(
            iserver, iserver.aspace, iserver.subscription_service, name, external=external, **kwargs
        )
        session.touch()
        if external:
            session.guard = self.guard
            self._open[session.client] = session
            self.opened += 1
        return session

    def _forget_closed(self) -> None:
        closed = [k for k, s in self._open.items() if s.state.name == "Closed"]
        for key in closed:
            del self._open[key]

    def __iter__(self) -> Iterator[GatewaySession]:
        self._forget_closed()
        return iter(list(self._open.values()))

    def get(self, client: str) -> GatewaySession | None:
        session = self._open.get(client)
        if session is None or session.state.name == "Closed":
            return None
        return session

    def __len__(self) -> int:
        self._forget_closed()
        return len(self._open)
