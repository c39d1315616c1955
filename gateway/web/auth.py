"""Who a web request comes from, and what that identity may do (gateway/access).

A request is identified, in this order, by:

- its session cookie (:data:`gateway.access.sessions.COOKIE`), set by ``POST /api/login``
  (a ``[[users]]`` password): HttpOnly, SameSite=Strict, Secure over TLS. Every request of
  a session that changes something carries the session's CSRF token in the
  ``X-CSRF-Token`` header (``GET /api/session`` gives it to the page);
- an API token (``Authorization: Bearer``): a user's ``token_sha256``, or the shared
  ``web.token_sha256`` (the operator ``token``, on a page for this machine alone);
- else it is anonymous: a viewer unless ``web.anonymous = "none"``.

Failed logins and wrong tokens are each limited per client address
(``web.token_failures`` within ``web.token_window``, gateway/web/tokens.py): beyond, the
address is refused unchecked (429) until the window passes. A password is checked with
scrypt (about 0.1 s, 32 MiB) on a worker thread, one at a time: logins never hold up the
event loop, and a flood of them costs one core at most. Every login, failed or refused,
every refusal by role or CSRF, and every accepted or refused command is audited.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import hmac
import math
import time
from typing import Any

import orjson
from aiohttp import hdrs, web

from gateway import jsontext
from gateway.access.audit import AuditTrail, Kind, Result
from gateway.access.passwords import ScryptHash, hash_password, token_digest, verify_password
from gateway.access.roles import ANONYMOUS, Action, Identity, Role, refusal
from gateway.access.sessions import COOKIE, CSRF_HEADER, Session, Sessions, csrf_ok
from gateway.access.users import User
from gateway.errors import GatewayError
from gateway.web.admission import RefusalLog, peer_of
from gateway.web.counters import WebCounters
from gateway.web.hosts import origin_admitted
from gateway.web.tokens import TokenFailures
from gateway.webconfig import WebSection

INTERFACE = "web"
SHARED_TOKEN = "token"  # the identity of web.token_sha256
MAX_FIELD = 256  # characters of a user name or password a login may give
MAX_LOGINS_WAITING = 8  # logins waiting for the KDF's thread; more are refused (503)
_NO_USER = hash_password("no such user", salt=b"drive-gateway-no-user")
"""Checked for a name no user has: an unknown name takes as long as a wrong password."""


def peer(request: web.BaseRequest) -> str:
    transport = request.transport
    return peer_of(transport) if transport is not None else str(request.remote or "")


class Refused(GatewayError):
    """A request refused: its HTTP status, the reason (the answer's ``error``), the
    counter's reason and headers."""

    def __init__(
        self, status: int, reason: str, counter: str, headers: tuple[tuple[str, str], ...] = ()
    ) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason
        self.counter = counter
        self.headers = headers

    def response(self) -> web.Response:
        return web.Response(
            body=orjson.dumps({"accepted": False, "error": self.reason}),
            status=self.status,
            content_type="application/json",
            headers=dict(self.headers),
        )


class WebAuth:
    """The web front end's identities, sessions and access decisions."""

    def __init__(
        self,
        section: WebSection,
        users: tuple[User, ...],
        audit: AuditTrail,
        counters: WebCounters,
        refusals: RefusalLog,
    ) -> None:
        self.section = section
        self.users = {u.name: u for u in users}
        self.by_token = {u.token_sha256: u for u in users if u.token_sha256}
        self.audit = audit
        self.counters = counters
        self.refusals = refusals
        self.sessions = Sessions()
        self.names = section.host_names
        limits = section.limits
        self.tokens = TokenFailures(limits.token_failures, limits.token_window)
        self.logins = TokenFailures(limits.token_failures, limits.token_window)
        # one worker thread for the KDF: a flood of logins costs one core at most, and the
        # loop runs on meanwhile
        self._kdf = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="web-kdf")
        self._waiting = 0  # logins submitted to the KDF's thread, not yet checked

    def close(self) -> None:
        """The KDF's thread ends (after the login it may be checking)."""
        self._kdf.shutdown(wait=False, cancel_futures=True)

    # ------------------------------------------------------------ identity

    def session(self, request: web.BaseRequest) -> Session | None:
        return self.sessions.find(request.cookies.get(COOKIE), time.monotonic())

    def _token_identity(self, token: str) -> Identity | None:
        digest = token_digest(token)
        user = self.by_token.get(digest)
        if user is not None:
            return user.identity
        shared = self.section.token_sha256
        if shared is not None and hmac.compare_digest(digest, shared):
            return Identity(SHARED_TOKEN, Role.OPERATOR)
        return None

    def _bearer(self, request: web.BaseRequest) -> str | None:
        scheme, _, token = request.headers.get("Authorization", "").partition(" ")
        return token.strip() if scheme.lower() == "bearer" and token.strip() else None

    def reader(self, request: web.BaseRequest) -> Identity | None:
        """Who reads: the session's user, a token's (a wrong token refused and counted, as
        for a command), else anonymous (a viewer, or None with ``web.anonymous = "none"``)."""
        session = self.session(request)
        if session is not None:
            return session.identity
        identity = self._token_check(request, peer(request), required=False)
        if identity is not None:
            return identity
        return Identity(ANONYMOUS, Role.VIEWER) if self.section.anonymous else None

    def check_read(self, request: web.BaseRequest, action: Action = Action.READ) -> Identity:
        """The identity of a reading request; :class:`Refused` if it may not read this."""
        identity = self.reader(request)
        if identity is None:
            where = peer(request)
            self.audit.refused_request(INTERFACE, "login_required", where, request.path)
            raise Refused(401, "log in first (POST /api/login) or give a token", "login_required")
        self._allow(request, identity, action)
        return identity

    def _allow(self, request: web.BaseRequest, identity: Identity, action: Action) -> None:
        why = refusal(identity, action)
        if why is None:
            return
        self.refusals.note("role", peer(request), why)
        self.audit.record(
            Kind.REFUSED,
            Result.FAILURE,
            interface=INTERFACE,
            peer=peer(request),
            identity=identity,
            detail=f"{request.method} {request.path}: {why}",
        )
        raise Refused(403, why, "role")

    def check_change(self, request: web.BaseRequest, action: Action) -> Identity:
        """The identity of a request that changes something (a command): its session with
        the session's CSRF token, or a valid token; the role checked. :class:`Refused`."""
        where = peer(request)
        session = self.session(request)
        if session is not None:
            if not csrf_ok(session, request.headers.get(CSRF_HEADER)):
                why = f"a {CSRF_HEADER} header with the session's token is needed"
                self.refusals.note("csrf", where, request.path)
                self.audit.record(
                    Kind.CSRF,
                    Result.FAILURE,
                    interface=INTERFACE,
                    peer=where,
                    identity=session.identity,
                    detail=f"{request.method} {request.path}: no valid CSRF token",
                )
                raise Refused(403, why, "csrf")
            identity = session.identity
            self._allow(request, identity, action)
            return identity
        token_identity = self._token_check(request, where, required=True)
        if token_identity is None:  # not reached: a required token is there or refused
            raise Refused(401, "log in, or give a valid token (Authorization: Bearer)", "token")
        self._allow(request, token_identity, action)
        return token_identity

    def _token_check(self, request: web.BaseRequest, where: str, required: bool) -> Identity | None:
        """The identity of the request's API token; None when it gives none and none is
        ``required``. :class:`Refused` for a wrong or missing one (counted against the
        address) and, unchecked, for an address over ``web.token_failures``."""
        token = self._bearer(request)
        if token is None and not required:
            return None
        now = time.monotonic()
        wait = self.tokens.wait(where, now)
        if wait > 0:
            self.refusals.note("token_limit", where, math.ceil(wait))
            raise Refused(
                429,
                "too many wrong tokens from this address: try again later",
                "token_limit",
                (("Retry-After", str(math.ceil(wait))),),
            )
        identity = self._token_identity(token) if token is not None else None
        if identity is None:
            self.tokens.failed(where, now)
            self.refusals.note("token", where, self.tokens.count(where))
            self.audit.record(
                Kind.TOKEN,
                Result.FAILURE,
                interface=INTERFACE,
                peer=where,
                detail=f"{request.method} {request.path}: no login and no valid token",
            )
            raise Refused(401, "log in, or give a valid token (Authorization: Bearer)", "token")
        self.tokens.succeeded(where)
        return identity

    # ------------------------------------------------------------ login

    def same_site(self, request: web.BaseRequest) -> None:
        """A login or logout from a page of this gateway only: its ``Origin`` (when a
        browser gives one) names one of ``web.names``, and a login's body is declared JSON,
        which a form of another site cannot send (a text/plain form can forge the JSON
        itself, and log the user's browser in as someone else)."""
        if not origin_admitted(request.headers.get(hdrs.ORIGIN), self.names):
            raise Refused(403, "a login from a page of another site is refused", "origin")
        login = request.method == "POST" and request.path == "/api/login"
        if login and request.content_type != "application/json":
            raise Refused(415, "a login is JSON (Content-Type: application/json)", "login")

    async def login(self, request: web.Request, body: bytes) -> web.Response:
        self.same_site(request)
        where = peer(request)
        now = time.monotonic()
        wait = self.logins.wait(where, now)
        if wait > 0:
            self.counters.logins["limited"] += 1
            self.refusals.note("login_limit", where, math.ceil(wait))
            self.audit.record(
                Kind.LOGIN_LIMITED,
                Result.FAILURE,
                interface=INTERFACE,
                peer=where,
                detail=f"refused unchecked: too many failed logins; {math.ceil(wait)} s to wait",
            )
            raise Refused(
                429,
                "too many failed logins from this address: try again later",
                "login_limit",
                (("Retry-After", str(math.ceil(wait))),),
            )
        name, password = _credentials(body)
        if self._waiting >= MAX_LOGINS_WAITING:  # logins from many addresses at once
            self.refusals.note("login_busy", where, MAX_LOGINS_WAITING)
            raise Refused(
                503, "too many logins at once: try again", "login_busy", (("Retry-After", "1"),)
            )
        user = self.users.get(name)
        stored: ScryptHash = user.password if user and user.password else _NO_USER
        loop = asyncio.get_running_loop()
        self._waiting += 1
        try:
            right = await loop.run_in_executor(self._kdf, verify_password, password, stored)
        finally:
            self._waiting -= 1
        if user is None or user.password is None or not right:
            self.logins.failed(where, time.monotonic())
            self.counters.logins["failure"] += 1
            self.refusals.note("login", where, self.logins.count(where))
            self.audit.record(
                Kind.LOGIN,
                Result.FAILURE,
                interface=INTERFACE,
                peer=where,
                identity=_shown_name(name),
                detail="wrong user name or password",
            )
            raise Refused(401, "wrong user name or password", "login")
        self.logins.succeeded(where)
        self.counters.logins["success"] += 1
        opened = self.sessions.open(user.identity, time.monotonic())
        self.audit.record(
            Kind.LOGIN, Result.SUCCESS, interface=INTERFACE, peer=where, identity=user.identity
        )
        response = _json({"user": user.name, "role": user.role.label, "csrf": opened.csrf})
        response.set_cookie(
            COOKIE,
            opened.session_id,
            httponly=True,
            samesite="Strict",
            secure=self.section.tls,
            path="/",
        )
        return response

    def logout(self, request: web.Request) -> web.Response:
        self.same_site(request)
        session = self.session(request)
        if session is not None:
            self.check_change(request, Action.READ)  # the CSRF token: no logging out by others
            self.sessions.close(request.cookies.get(COOKIE))
            self.audit.record(
                Kind.LOGOUT,
                Result.SUCCESS,
                interface=INTERFACE,
                peer=peer(request),
                identity=session.identity,
            )
        response = _json({"user": None})
        response.del_cookie(COOKIE, path="/")
        return response

    def whoami(self, request: web.Request) -> web.Response:
        session = self.session(request)
        if session is not None:
            identity = session.identity
            return _json({"user": identity.name, "role": identity.role.label, "csrf": session.csrf})
        identity_or_none = self.reader(request)
        return _json(
            {
                "user": None,
                "role": identity_or_none.role.label if identity_or_none else None,
                "users": bool(self.users),
            }
        )

    def command_audited(self, request: web.Request, identity: Identity, detail: str) -> None:
        """A command refused before it was one (its body not a command)."""
        self.audit.record(
            Kind.COMMAND,
            Result.FAILURE,
            interface=INTERFACE,
            peer=peer(request),
            identity=identity,
            detail=detail,
        )


def _json(body: Any, status: int = 200) -> web.Response:
    return web.Response(body=orjson.dumps(body), status=status, content_type="application/json")


def _shown_name(name: str) -> str:
    return name if name.isprintable() else repr(name)


def _credentials(body: bytes) -> tuple[str, str]:
    """The user name and password of a login's JSON body; :class:`Refused` (400) else."""
    try:
        data = jsontext.loads(body)
    except (ValueError, RecursionError, jsontext.DuplicateKey):
        data = None
    if (
        not isinstance(data, dict)
        or set(data) != {"user", "password"}
        or not all(isinstance(v, str) and 0 < len(v) <= MAX_FIELD for v in data.values())
    ):
        raise Refused(
            400, 'a login is {"user": NAME, "password": PASSWORD} (JSON, each at most 256)', "login"
        )
    return data["user"], data["password"]
