"""Web sessions: a random id in an HttpOnly cookie, a CSRF token per session.

Sans-IO (the caller passes the time). A session ends :data:`IDLE` seconds after its last
use, :data:`LIFETIME` seconds after its login whatever its use, or at logout; at most
:data:`MAX_SESSIONS` live at once (a login beyond ends the one used least recently). Only
a digest of each id is kept, so the table holds nothing a reader could present as a
cookie. A state-changing request of a session carries its CSRF token in a header
(:data:`CSRF_HEADER`), which a page of another site cannot read nor set.
"""

from __future__ import annotations

import collections
import hashlib
import hmac
import secrets
from dataclasses import dataclass

from gateway.access.roles import Identity

COOKIE = "dg_session"
CSRF_HEADER = "X-CSRF-Token"
IDLE = 900.0  # s without a request before a session ends
LIFETIME = 8 * 3600.0  # s after its login a session ends
MAX_SESSIONS = 256
ID_BYTES = 32


def _digest(session_id: str) -> str:
    return hashlib.sha256(session_id.encode("utf-8", "replace")).hexdigest()


@dataclass(slots=True)
class Session:
    identity: Identity
    csrf: str
    started: float
    used: float


@dataclass(frozen=True, slots=True)
class Opened:
    """A new session: the cookie's value and the CSRF token the page gives back."""

    session_id: str
    csrf: str


class Sessions:
    def __init__(
        self, idle: float = IDLE, lifetime: float = LIFETIME, limit: int = MAX_SESSIONS
    ) -> None:
        self.idle = idle
        self.lifetime = lifetime
        self.limit = limit
        self._by_digest: collections.OrderedDict[str, Session] = collections.OrderedDict()

    def open(self, identity: Identity, now: float) -> Opened:
        session_id = secrets.token_urlsafe(ID_BYTES)
        csrf = secrets.token_urlsafe(ID_BYTES)
        self._by_digest[_digest(session_id)] = Session(identity, csrf, now, now)
        while len(self._by_digest) > self.limit:
            self._by_digest.popitem(last=False)
        return Opened(session_id, csrf)

    def find(self, session_id: str | None, now: float) -> Session | None:
        """The live session of a cookie's value (its use noted), else None."""
        if not session_id:
            return None
        key = _digest(session_id)
        session = self._by_digest.get(key)
        if session is None:
            return None
        if now - session.used > self.idle or now - session.started > self.lifetime:
            del self._by_digest[key]
            return None
        session.used = now
        self._by_digest.move_to_end(key)
        return session

    def close(self, session_id: str | None) -> Session | None:
        return self._by_digest.pop(_digest(session_id), None) if session_id else None

    def close_user(self, name: str) -> int:
        """End every session of ``name`` (a user removed or changed); how many ended."""
        gone = [k for k, s in self._by_digest.items() if s.identity.name == name]
        for key in gone:
            del self._by_digest[key]
        return len(gone)

    def __len__(self) -> int:
        return len(self._by_digest)


def csrf_ok(session: Session, given: str | None) -> bool:
    """Whether a request's CSRF header is its session's token (a constant-time compare)."""
    return given is not None and hmac.compare_digest(
        session.csrf.encode(), given.encode("utf-8", "replace")
    )
