"""Every Zenoh object of the front end, in one place.

A :class:`ZenohLink` is opened, used and closed on the I/O thread
(:mod:`gateway.zenoh.worker`), with two exceptions. Its ``change_publishers``
(CongestionControl.DROP, they never wait on the network) are used by the event
loop to put state changes at once. Its callbacks run on Zenoh's own threads:
they copy the key and the payload out of the sample or query and hand them on
(the front end passes them to the event loop); they never touch the hub.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import zenoh
from zenoh.ext import CacheConfig, MissDetectionConfig, declare_advanced_publisher

from gateway.model import client_label
from gateway.zenoh.keys import KeyKind, KeySpace
from gateway.zenoh.requests import MAX_PAYLOAD, Answer
from gateway.zenoh.session import open_session

log = logging.getLogger(__name__)

JSON = zenoh.Encoding.APPLICATION_JSON
BLOCK = zenoh.CongestionControl.BLOCK
DROP = zenoh.CongestionControl.DROP
RECOVERY_HEARTBEAT = 1.0
"""s between two heartbeats of an advanced publisher's last sequence number (sent only when
it changed): a subscriber that missed a drive's last sample asks for it within this."""


@dataclass(frozen=True, slots=True)
class Oversize:
    """A payload over :data:`MAX_PAYLOAD`, not copied out of Zenoh: only its size."""

    size: int


Payload = bytes | Oversize | None


def _payload(zbytes: Any) -> Payload:
    """Copy a payload out of Zenoh, unless it is over the limit (then only its size)."""
    if zbytes is None:
        return None
    size = len(zbytes)
    return Oversize(size) if size > MAX_PAYLOAD else zbytes.to_bytes()


@dataclass(frozen=True, slots=True)
class Incoming:
    """A query, as handed from a Zenoh thread to the event loop.

    ``targets``: for a state query, the drives whose state key the query's key
    expression intersects (computed on the Zenoh thread, from the config).
    """

    kind: KeyKind
    key: str
    payload: Payload
    query: Any  # zenoh.Query: replied to and dropped on the I/O thread
    targets: tuple[str, ...] = ()
    client: str = ""  # the querier's session id (client_of)
    parameters: str = ""  # the selector's parameters ("numbers=1-20;describe")


ANONYMOUS = "anonymous"
"""The client id of a put or query that carries no source info (docs/operations.md)."""


@dataclass(frozen=True, slots=True)
class LinkSeen:
    """A link of the session opened or closed, as handed to the event loop: the remote
    session's label, where it is, and the name its link authenticated with (a TLS client
    certificate's common name), if any."""

    opened: bool
    client: str
    remote: str
    auth: str | None


LinkSink = Callable[[LinkSeen], None]


def client_of(source_info: Any) -> str:
    """The client behind a sample or query: the label (:func:`client_label`) of its
    session's id from the source info (``put(..., source_info=SourceInfo(publisher.id,
    sn))``), or :data:`ANONYMOUS`. Only the label is ever published, so no client can
    copy another's id from the gateway's states or events.

    Every Zenoh client that sends no source info is the same, anonymous client to
    the gateway: they share control of a drive and feed one command watchdog.
    """
    if source_info is None:
        return ANONYMOUS
    return client_label(str(source_info.source_id.zid))


CommandSink = Callable[[str, Payload, str], None]
QuerySink = Callable[[Incoming], None]


class ZenohLink:
    """The session, its publishers, subscriber, queryables and liveliness tokens."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: KeySpace,
        drive_ids: Sequence[str],
        on_command: CommandSink,
        on_query: QuerySink,
        *,
        recovery_cache: int = 0,
        on_link: LinkSink | None = None,
    ) -> None:
        self.session = session
        self.keys = keys
        self._drive_ids = tuple(drive_ids)
        self._state_keys = {d: zenoh.KeyExpr(keys.key(KeyKind.STATE, d)) for d in drive_ids}
        self._on_command = on_command
        self._on_query = on_query
        self._tokens: dict[str, Any] = {}
        self._gateway_token: Any = None
        self._publishers: dict[tuple[KeyKind, str], Any] = {}
        caches = {KeyKind.EVENTS: recovery_cache, KeyKind.STATE: min(recovery_cache, 1)}
        for drive_id in drive_ids:
            for kind in (KeyKind.STATE, KeyKind.EVENTS, KeyKind.DIAG):
                self._publishers[kind, drive_id] = self._publisher(
                    keys.key(kind, drive_id), caches.get(kind, 0)
                )
        self.change_publishers: dict[str, Any] = {
            drive_id: session.declare_publisher(
                keys.key(KeyKind.STATE, drive_id), encoding=JSON, congestion_control=DROP
            )
            for drive_id in drive_ids
        }
        """Drive id -> a DROP publisher of its state: the event loop puts changes with it."""
        self._entities: list[Any] = [
            session.declare_subscriber(keys.all_drives(KeyKind.COMMAND), self._command_sample)
        ]
        for kind in (KeyKind.STATE, KeyKind.COMMAND, KeyKind.PARAM, KeyKind.HISTORY):
            self._entities.append(self._queryable(keys.all_drives(kind), kind))
        self._entities.append(self._queryable(keys.key(KeyKind.HEALTH), KeyKind.HEALTH))
        self._entities.append(self._queryable(keys.key(KeyKind.AUDIT), KeyKind.AUDIT))
        self._on_link = on_link
        declare = getattr(getattr(session, "info", None), "declare_link_events_listener", None)
        if on_link is not None and declare is not None:
            self._entities.append(declare(self._link_event, history=True))

    def _link_event(self, event: Any) -> None:
        """A link opened or closed (a Zenoh thread): copied and handed over."""
        if self._on_link is None:
            return
        link = event.link
        auth = link.auth_identifier
        self._on_link(
            LinkSeen(
                opened=event.kind == zenoh.SampleKind.PUT,
                client=client_label(str(link.zid)),
                remote=str(link.dst),
                auth=None if auth is None else str(auth),
            )
        )

    def _publisher(self, key: str, cache: int) -> Any:
        """A BLOCK publisher; with ``cache``, Zenoh's advanced publisher keeping the last
        ``cache`` samples for subscribers that come back (docs/zenoh-keys.md, "Recovery")."""
        if cache <= 0:
            return self.session.declare_publisher(key, encoding=JSON, congestion_control=BLOCK)
        return declare_advanced_publisher(
            self.session,
            key,
            encoding=JSON,
            congestion_control=BLOCK,
            cache=CacheConfig(cache),
            sample_miss_detection=MissDetectionConfig(
                heartbeat=None, sporadic_heartbeat=RECOVERY_HEARTBEAT
            ),
            publisher_detection=True,
        )

    @classmethod
    def open(
        cls,
        config: zenoh.Config,
        keys: KeySpace,
        drive_ids: Sequence[str],
        on_command: CommandSink,
        on_query: QuerySink,
        *,
        recovery_cache: int = 0,
        on_link: LinkSink | None = None,
    ) -> ZenohLink:
        session = open_session(config)  # StartupError names the cause and the fix
        try:
            return cls(
                session,
                keys,
                drive_ids,
                on_command,
                on_query,
                recovery_cache=recovery_cache,
                on_link=on_link,
            )
        except BaseException:
            session.close()
            raise

    def _queryable(self, key: str, kind: KeyKind) -> Any:
        def callback(query: zenoh.Query) -> None:
            self._query(kind, query)

        return self.session.declare_queryable(key, callback)

    # ------------------------------------------------------------ Zenoh threads

    def _command_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind != zenoh.SampleKind.PUT:  # PyO3 enums: compare by value, not identity
            return
        self._on_command(
            str(sample.key_expr), _payload(sample.payload), client_of(sample.source_info)
        )

    def _query(self, kind: KeyKind, query: zenoh.Query) -> None:
        try:
            key = str(query.key_expr)
            payload = query.payload
            targets: tuple[str, ...] = ()
            if kind is KeyKind.STATE:
                asked = query.key_expr
                targets = tuple(d for d, k in self._state_keys.items() if asked.intersects(k))
            body = _payload(payload)
            client = client_of(query.source_info)
            parameters = str(query.parameters)
            self._on_query(Incoming(kind, key, body, query, targets, client, parameters))
        except Exception:
            log.exception("zenoh query on %s could not be handed over", query.key_expr)
            query.drop()

    # ------------------------------------------------------------ I/O thread

    def declare_gateway_token(self) -> None:
        self._gateway_token = self.session.liveliness().declare_token(
            self.keys.key(KeyKind.GATEWAY_TOKEN)
        )

    def set_live(self, drive_id: str, live: bool) -> None:
        token = self._tokens.pop(drive_id, None)
        if token is not None:
            token.undeclare()
        if live:
            key = self.keys.key(KeyKind.DRIVE_TOKEN, drive_id)
            self._tokens[drive_id] = self.session.liveliness().declare_token(key)

    def _put(self, kind: KeyKind, drive_id: str, payload: bytes) -> None:
        """A BLOCK put; a failure is logged (the next state or event goes on)."""
        publisher = self._publishers.get((kind, drive_id))
        try:
            if publisher is None:
                key = self.keys.key(kind, drive_id)
                self.session.put(key, payload, encoding=JSON, congestion_control=BLOCK)
            else:
                publisher.put(payload)
        except zenoh.ZError as exc:
            log.warning("zenoh put of %s %s failed: %s", drive_id, kind.value, exc)

    def publish_state(self, drive_id: str, payload: bytes) -> None:
        self._put(KeyKind.STATE, drive_id, payload)

    def publish_diag(self, drive_id: str, payload: bytes) -> None:
        self._put(KeyKind.DIAG, drive_id, payload)

    def publish_events(self, events: Sequence[tuple[str, bytes]]) -> None:
        for drive_id, payload in events:
            self._put(KeyKind.EVENTS, drive_id, payload)

    @staticmethod
    def reply(query: zenoh.Query, answers: Sequence[Answer]) -> None:
        """Send the answers, then drop the query (which finalises it for the querier)."""
        try:
            for answer in answers:
                if answer.ok:
                    query.reply(answer.key, answer.payload, encoding=JSON)
                else:
                    query.reply_err(answer.payload, encoding=JSON)
        except zenoh.ZError as exc:
            log.warning("zenoh reply to %s failed: %s", query.key_expr, exc)
        finally:
            query.drop()

    def close(self) -> None:
        """Close the session: every declaration and token goes with it."""
        self._tokens.clear()
        self._gateway_token = None
        self._publishers.clear()
        self.change_publishers.clear()
        self._entities.clear()
        self.session.close()
