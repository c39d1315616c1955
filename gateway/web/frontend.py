"""The web front end: what the daemon runs as ``WebFrontEnd(runtime).run()``.

An aiohttp server on the daemon's own event loop serves, on ``web.bind``:

- ``/`` the status page, ``/app.js`` and ``/style.css`` (package data: gateway/web/static);
- ``/ws`` the push feed (WebSocket, gateway/web/feed.py);
- ``/api/health``, ``/api/drives``, ``/api/drives/<id>``, ``/api/buses``, ``/api/events``,
  ``/api/history`` and ``/api/history/<id>`` (JSON, docs/operations.md);
- ``POST /api/drives/<id>/command`` only with ``web.commands = true``, by an operator
  or above (a session with its CSRF token, or an API token: gateway/web/auth.py);
- ``POST /api/login``, ``POST /api/logout``, ``GET /api/session`` (the session cookie),
  ``GET /api/audit`` (the audit trail, engineers and above);
- ``/metrics`` (gateway/web/metrics.py), from a render shared by the scrapes within
  ``web.metrics_max_age``.

What it admits (gateway/web/admission.py): a connection from an address outside
``web.allow``, or beyond ``web.max_connections`` (in all, or per address), is closed at
accept before a byte is read; a request's head and body have ``web.header_timeout`` and
``web.body_timeout``; at most ``web.max_pages`` pages, each dropped once it leaves more
than ``web.page_send_budget_kib`` unsent; an address that gave ``web.token_failures``
wrong tokens within ``web.token_window`` gets 429 unchecked (gateway/web/tokens.py).
A request whose Host names no name of ``web.names`` gets 421, and a feed asked for by a
page whose Origin names none of them 403 (gateway/web/hosts.py); a malformed request gets
aiohttp's own 400, logged once per period (:class:`gateway.web.admission.RequestLog`).
A command goes through ``hub.submit`` as source ``web`` and client
``<peer address> <page id>``, under the same safety rules as Zenoh and Modbus.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import re
import ssl
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from functools import partial
from importlib import resources
from typing import Any

import orjson
from aiohttp import WSCloseCode, WSMsgType, hdrs, web
from prometheus_client import CONTENT_TYPE_LATEST

from gateway import jsontext
from gateway.access.audit import Result
from gateway.access.roles import Action, Identity, may
from gateway.adapter import EventKind
from gateway.errors import CommandRejected, HistoryError, StartupError, UnknownDrive
from gateway.frontend import FrontEndCounters, RuntimeView
from gateway.history.query import answer, off_loop, parse_range
from gateway.model import DriveCommand, Source, client_label
from gateway.web.admission import (
    AdmissionSite,
    Gate,
    RefusalLog,
    RequestLog,
    allowed,
    connection_of,
    peer_of,
)
from gateway.web.auth import Refused, WebAuth
from gateway.web.counters import WebCounters
from gateway.web.feed import PUSH_PERIOD, SEND_TIMEOUT, ClientQueue, Feed
from gateway.web.history import ring_json
from gateway.web.hosts import host_admitted, origin_admitted, shown
from gateway.web.metrics import MetricsSnapshot, make_registry
from gateway.web.page import check_template
from gateway.web.page import render as render_page
from gateway.web.views import bus_diagnostics, buses_json, drive_row, drives_json, health_json
from gateway.webconfig import LOOPBACK

log = logging.getLogger(__name__)

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]

STATIC: dict[str, str] = {
    "/": "index.html",
    "/app.js": "app.js",
    "/style.css": "style.css",
}
CONTENT_TYPES = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
}
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; "
        "img-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
MAX_BODY = 4096  # bytes of a command request
AUDITED_AT_THE_DOOR = frozenset(
    {
        "allow",
        "over_limit",
        "over_peer_limit",
        "pages",
        "pages_per_peer",
        "token_limit",
        "request_rate",
        "host",
        "bad_request",
        "login_busy",
    }
)
"""The refusals of :class:`RefusalLog` that are access decisions: on the audit trail."""
OPEN_PATHS = frozenset({*STATIC, "/favicon.ico", "/api/login", "/api/logout", "/api/session"})
"""Served without a login even with ``web.anonymous = "none"``: the page and the login."""
SHUTDOWN_TIMEOUT = 2.0  # s open requests and pages get when the gateway stops
WS_HEARTBEAT = 20.0  # s between pings: a page that went away is noticed
WS_MAX_MESSAGE = 1024  # bytes a page may send on the feed (it sends nothing we read)
PAGE_ID = re.compile(r"[A-Za-z0-9-]{1,40}")
PAGES_RETRY_AFTER = 10  # s a refused page is told to wait (it retries by itself, up to 8 s)
MISDIRECTED = (
    "misdirected request: this gateway does not answer to the host name this request gives "
    "(web.names)\n"
)
_BIND_FIXES = {
    errno.EADDRINUSE: ("the address is in use", "stop what uses it, or set [web] bind"),
    errno.EACCES: ("permission denied", "use a port above 1023, or set [web] bind"),
    errno.EADDRNOTAVAIL: ("no such local address", "set [web] bind to an address of this host"),
}


def load_static() -> dict[str, tuple[bytes, str]]:
    """The page's files, read once: path -> (body, content type)."""
    folder = resources.files("gateway.web") / "static"
    out: dict[str, tuple[bytes, str]] = {}
    for path, name in STATIC.items():
        suffix = name[name.rfind(".") :]
        out[path] = (folder.joinpath(name).read_bytes(), CONTENT_TYPES[suffix])
    return out


def _json(body: Any, status: int = 200, headers: dict[str, str] | None = None) -> web.Response:
    return web.Response(
        body=orjson.dumps(body), status=status, content_type="application/json", headers=headers
    )


def _peer(request: web.BaseRequest) -> str:
    """The client's address, as the admission counts it."""
    transport = request.transport
    return peer_of(transport) if transport is not None else str(request.remote or "")


def _loopback(host: str) -> bool:
    """Whether the bind host is this machine only (localhost, 127.x, ::1)."""
    return host == "localhost" or allowed(host, LOOPBACK)


@dataclass(frozen=True, slots=True, eq=False)
class Page:
    """An open page: its feed, its connection and its client's address."""

    ws: web.WebSocketResponse
    transport: asyncio.Transport
    peer: str


class WebFrontEnd:
    """Serve the status page, the API and the metrics until cancelled."""

    def __init__(self, runtime: RuntimeView) -> None:
        self.runtime = runtime
        self.section = runtime.config.web
        self.limits = self.section.limits
        self.hub = runtime.hub
        self.feed = Feed(runtime, commands=self.section.commands)
        self.counters = WebCounters()
        self.registry = make_registry(runtime, self.feed.counters, self.counters)
        self.metrics = MetricsSnapshot(self.registry, self.limits.metrics_max_age, self.counters)
        self.refusals = RefusalLog()
        self.gate = Gate(self.section, self.counters, self.refusals)
        self.names = self.section.host_names
        self.request_log = RequestLog(self.refusals)
        self.auth = WebAuth(
            self.section, runtime.config.users, runtime.audit, self.counters, self.refusals
        )
        self.tokens = self.auth.tokens
        self.refusals.listener = self._audit_refusal
        self.static = load_static()
        check_template(self.static["/"][0].decode("utf-8"))
        self.address: tuple[str, int] | None = None
        self.ready = asyncio.Event()  # set while the server listens
        self._writers: set[asyncio.Task[None]] = set()
        self._pages: set[Page] = set()

    def counted(self) -> FrontEndCounters:
        c = self.counters
        return FrontEndCounters(
            refused=dict(c.refused),
            commands_accepted=c.commands["accepted"],
            commands_refused=c.commands["refused"],
            connections_accepted=c.connections["accepted"],
            connections_refused=c.connections["refused"],
            connections_over_limit=c.connections["over_limit"] + c.connections["over_peer_limit"],
            connections_open=c.clients_open,
        )

    # ------------------------------------------------------------ life cycle

    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._guard], client_max_size=MAX_BODY)
        for path in STATIC:
            app.router.add_get(path, self._static)
        app.router.add_get("/favicon.ico", self._no_icon)
        app.router.add_get("/ws", self._ws)
        app.router.add_get("/metrics", self._metrics)
        app.router.add_get("/api/health", self._health)
        app.router.add_get("/api/drives", self._drives)
        app.router.add_get("/api/drives/{drive}", self._drive)
        app.router.add_get("/api/drives/{drive}/history", self._drive_history)
        app.router.add_post("/api/drives/{drive}/command", self._command)
        app.router.add_get("/api/buses", self._buses)
        app.router.add_get("/api/events", self._events)
        app.router.add_get("/api/history", self._history)
        app.router.add_get("/api/history/{drive}", self._history_of)
        app.router.add_post("/api/login", self._login)
        app.router.add_post("/api/logout", self._logout)
        app.router.add_get("/api/session", self._session)
        app.router.add_get("/api/audit", self._audit)
        return app

    async def run(self) -> None:
        runner = web.AppRunner(
            self.app(),
            access_log=None,
            handle_signals=False,
            shutdown_timeout=SHUTDOWN_TIMEOUT,
            # what aiohttp answers with an error itself (a malformed request: 400) is logged
            # once per period, a client's mistake without a traceback
            logger=self.request_log,
            # aiohttp's own idle close, behind the header deadline of gateway/web/admission.py
            keepalive_timeout=2 * self.limits.header_timeout,
            # a body left unread (a refused request) is not waited for: the connection closes
            lingering_time=0,
        )
        await runner.setup()
        self.feed.open()
        try:
            site = AdmissionSite(
                runner, self.section.host, self.section.port, self.gate, self._tls_context()
            )
            try:
                await site.start()
            except OSError as exc:
                raise self._bind_error(exc) from None
            self.address = site.bound
            self._log_serving()
            self.ready.set()
            await self._push()
        finally:
            self.ready.clear()
            self.feed.close()
            for task in list(self._writers):
                task.cancel()
            await self._close_sockets()
            await runner.cleanup()
            self.auth.close()
            log.info("web front end stopped")

    async def _close_sockets(self) -> None:
        """Tell every open page the gateway is going (it shows so, and reconnects later)."""

        async def close(ws: web.WebSocketResponse) -> None:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(SHUTDOWN_TIMEOUT):
                    await ws.close(code=WSCloseCode.GOING_AWAY, message=b"gateway stopping")

        await asyncio.gather(*(close(page.ws) for page in list(self._pages)))

    def _audit_refusal(self, kind: str, peer: str, line: str) -> None:
        """A refusal at the door on the audit trail (those of an identity are audited
        where they are decided, gateway/web/auth.py)."""
        if kind in AUDITED_AT_THE_DOOR:
            self.runtime.audit.refused_request("web", kind, peer, line)

    def _tls_context(self) -> ssl.SSLContext | None:
        """The server's TLS context from ``web.tls_cert`` and ``web.tls_key`` (None: plain
        HTTP); StartupError naming the file and the cause when they do not load."""
        cert, key = self.section.tls_cert, self.section.tls_key
        if cert is None or key is None:
            return None
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        try:
            context.load_cert_chain(cert, key)
        except (OSError, ssl.SSLError) as exc:
            reason = getattr(exc, "strerror", None) or str(exc)
            raise StartupError(
                "web",
                f"cannot load web.tls_cert {cert} and web.tls_key {key}: {reason}",
                "give a PEM certificate and its private key",
            ) from None
        return context

    def _bind_error(self, exc: OSError) -> StartupError:
        where = f"{self.section.host}:{self.section.port}"
        cause, fix = _BIND_FIXES.get(
            exc.errno or 0, ((exc.strerror or str(exc)).lower(), "check [web] bind")
        )
        return StartupError("web", f"cannot listen on {where}: {cause}", fix)

    @property
    def url(self) -> str:
        host, port = self.address or (self.section.host, self.section.port)
        shown = f"[{host}]" if ":" in host else host
        return f"{'https' if self.section.tls else 'http'}://{shown}:{port}/"

    def _log_serving(self) -> None:
        log.info(
            "web status page on %s (metrics at %smetrics; commands %s)",
            self.url,
            self.url,
            "on, by operators" if self.section.commands else "off",
        )
        users = self.runtime.config.users
        log.info(
            "web users: %d; without a login: %s",
            len(users),
            "viewer" if self.section.anonymous else "nothing but the page and the login",
        )
        if self.section.commands and self.section.token_sha256 is not None and not users:
            log.warning(
                "web commands by the shared token_sha256 (operator 'token'): it names no "
                "person; give each user a [[users]] table (drive-gateway users hash)"
            )
        networks = ", ".join(str(n) for n in self.section.allow)
        log.info("web clients allowed from %s", networks)
        log.info("web host names: %s", ", ".join(sorted(self.names)))
        if self.section.names is None and not _loopback(self.section.host):
            log.warning(
                "web.names is not set: a request naming this host otherwise than %s is "
                "refused (421); list the names users reach the page by",
                ", ".join(sorted(self.names)),
            )
        limits = self.limits
        log.info(
            "web limits: %d connections (%d per address), %d pages (%d per address), "
            "%g s for a request head, %g s for a body",
            limits.max_connections,
            limits.max_connections_per_peer,
            limits.max_pages,
            limits.max_pages_per_peer,
            limits.header_timeout,
            limits.body_timeout,
        )

    async def _push(self) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        failing = False
        while True:
            try:
                self.feed.step()
                failing = False
            except Exception:  # a figure that cannot be read this time: the next push tries
                if not failing:
                    log.exception("web feed: a push failed (logged once until one succeeds)")
                failing = True
            self._drop_over_budget()
            self.refusals.flush()
            next_at += PUSH_PERIOD
            delay = next_at - loop.time()
            if delay < 0:  # the loop was held up: no burst of steps to catch up
                next_at = loop.time()
                delay = 0.0
            await asyncio.sleep(delay)

    # ------------------------------------------------------------ guard

    @web.middleware
    async def _guard(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        """Every request: the connection's header deadline is off while the request runs
        (it is due again once the answer is written), a Host not in ``web.names`` refused,
        and the security headers."""
        connection = connection_of(request)
        task = asyncio.current_task()
        if connection is not None and task is not None:
            connection.request_started()
            task.add_done_callback(lambda _: connection.expect_request())
        misdirected = self._misdirected(request)
        try:
            if misdirected is not None:
                response: web.StreamResponse = misdirected
            else:
                if request.path not in OPEN_PATHS:
                    self.auth.check_read(request)
                response = await handler(request)
        except Refused as refused:
            self.counters.refused[refused.counter] += 1
            response = refused.response()
        if not response.prepared:
            response.headers.update(SECURITY_HEADERS)
        return response

    def _misdirected(self, request: web.Request) -> web.Response | None:
        """421 for a request whose Host names no name of ``web.names`` (a page of another
        site, its name pointed at the gateway, would be let read the answer), else None."""
        host = request.headers.get(hdrs.HOST)
        if host_admitted(host, request.version, self.names):
            return None
        self.counters.refused["host"] += 1
        self.refusals.note("host", _peer(request), shown(host))
        response = web.Response(status=421, text=MISDIRECTED)
        response.force_close()  # the connection's next request would name the same host
        return response

    # ------------------------------------------------------------ page and feed

    async def _static(self, request: web.Request) -> web.Response:
        body, content_type = self.static[request.path]
        if request.path == "/":  # the drives as they are now, shown before the script runs
            # ... to a reader who may see them: with web.anonymous = "none" a visitor without
            # a session gets the page's frame only (it asks for the login)
            shown = may(self.auth.reader(request), Action.READ)
            page = render_page(body.decode("utf-8"), self.runtime, drives=shown)
            body = page.encode("utf-8")
        return web.Response(body=body, content_type=content_type, charset="utf-8")

    async def _no_icon(self, request: web.Request) -> web.Response:
        return web.Response(status=204)

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if not origin_admitted(request.headers.get(hdrs.ORIGIN), self.names):
            # a WebSocket is not held to the same-origin rule: a page of another site open
            # in the operator's browser could otherwise read the feed
            self.counters.refused["origin"] += 1
            origin = request.headers.get(hdrs.ORIGIN, "")
            self.runtime.audit.refused_request("web", "origin", _peer(request), shown(origin))
            return web.Response(status=403, text="forbidden: the feed serves this page only\n")
        peer = _peer(request)
        if self.gate.page_refusal(peer) is not None:
            return web.Response(
                status=503,
                text="too many pages are open: try again later\n",
                headers={"Retry-After": str(PAGES_RETRY_AFTER)},
            )
        self.gate.page_opened(peer)  # from the handshake on: handshakes in flight count
        try:
            return await self._page(request, peer)
        finally:
            self.gate.page_closed(peer)

    async def _page(self, request: web.Request, peer: str) -> web.StreamResponse:
        """One page's feed, from the handshake until it closes."""
        # no compression: every page gets the same text, each would compress it again
        ws = web.WebSocketResponse(
            heartbeat=WS_HEARTBEAT, max_msg_size=WS_MAX_MESSAGE, compress=False
        )
        ws.headers.update(SECURITY_HEADERS)
        await ws.prepare(request)
        transport = request.transport
        if transport is None:  # gone during the handshake
            return ws
        connection = connection_of(request)
        if connection is not None:
            connection.page_opened()
        # the writer waits for the socket only beyond the budget: a page that reads keeps
        # up, one that does not is dropped by the next push (_drop_over_budget)
        transport.set_write_buffer_limits(high=self.limits.page_send_budget)
        page = Page(ws, transport, peer)
        self._pages.add(page)
        client = self.feed.add()
        writer = asyncio.create_task(self._write(ws, client, request), name="web-ws-writer")
        self._writers.add(writer)
        try:
            async for msg in ws:
                if msg.type is WSMsgType.ERROR:
                    break  # the page sends nothing the gateway reads
        finally:
            self._pages.discard(page)
            self.feed.remove(client)
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer
            self._writers.discard(writer)
            if transport.get_write_buffer_size():
                # closed with data unsent (its ping unanswered, say): a close would wait for
                # a page that does not read, holding its connection
                transport.abort()
        return ws

    async def _write(
        self, ws: web.WebSocketResponse, client: ClientQueue, request: web.Request
    ) -> None:
        while not ws.closed:
            message = await client.next(self.feed.snapshot)
            try:
                async with asyncio.timeout(SEND_TIMEOUT):
                    await ws.send_str(message)
            except TimeoutError:
                self.feed.counters.clients_stuck += 1
                log.info(
                    "web page at %s disconnected: a message took over %g s",
                    request.remote,
                    SEND_TIMEOUT,
                )
                if request.transport is not None:
                    request.transport.abort()
                return
            except ConnectionError:
                return

    def _drop_over_budget(self) -> None:
        """Drop every page that left more than its budget unsent (it does not read)."""
        budget = self.limits.page_send_budget
        for page in list(self._pages):
            transport = page.transport
            if transport.is_closing() or transport.get_write_buffer_size() <= budget:
                continue
            self.counters.clients_over_budget += 1
            self.refusals.note("over_budget", page.peer, self.limits.page_send_budget_kib)
            transport.abort()

    # ------------------------------------------------------------ API

    async def _metrics(self, request: web.Request) -> web.Response:
        body = self.metrics.body()
        return web.Response(body=body, headers={"Content-Type": CONTENT_TYPE_LATEST})

    async def _health(self, request: web.Request) -> web.Response:
        return _json(health_json(self.runtime))

    async def _drives(self, request: web.Request) -> web.Response:
        return _json({"drives": drives_json(self.runtime)})

    def _state(self, request: web.Request) -> Any:
        drive_id = request.match_info["drive"]
        try:
            return self.hub.state(drive_id)
        except UnknownDrive:
            raise web.HTTPNotFound(
                text=orjson.dumps({"error": f"no drive {drive_id!r}"}).decode(),
                content_type="application/json",
            ) from None

    async def _drive(self, request: web.Request) -> web.Response:
        return _json(drive_row(self.runtime, self._state(request)))

    async def _buses(self, request: web.Request) -> web.Response:
        return _json({"buses": buses_json(self.runtime, bus_diagnostics(self.runtime))})

    async def _events(self, request: web.Request) -> web.Response:
        return _json({"events": list(self.feed.events)})

    async def _history(self, request: web.Request) -> web.Response:
        return _json(self.feed.history.all_json())

    async def _history_of(self, request: web.Request) -> web.Response:
        state = self._state(request)
        history = self.feed.history
        return _json({"period": history.period, "span": history.span, **history.to_json(state.id)})

    async def _drive_history(self, request: web.Request) -> web.Response:
        """``/api/drives/<id>/history?start=&end=&step=``: any time range, from the history
        store (the forms of the Zenoh history key); without ``[history]``, the trend's
        ring of the last 10 minutes."""
        state = self._state(request)
        try:
            asked = parse_range(dict(request.query), time.time())
            store = self.runtime.history
            if store is None and asked.events:
                raise HistoryError("this gateway keeps no history of events ([history] is off)")
            if store is None:
                return _json(ring_json(self.feed.history, state.id, asked))
            body = await off_loop(partial(answer, store, state.id, asked))
        except HistoryError as exc:
            return _json({"error": str(exc)}, 400)
        return _json(body)

    # ------------------------------------------------------------ commands

    def _refuse(
        self, reason: str, status: int, text: str, headers: dict[str, str] | None = None
    ) -> web.Response:
        self.counters.refused[reason] += 1
        return _json({"accepted": False, "error": text}, status, headers)

    # ------------------------------------------------------------ identities

    async def _login(self, request: web.Request) -> web.Response:
        return await self.auth.login(request, await self._body(request))

    async def _logout(self, request: web.Request) -> web.Response:
        return self.auth.logout(request)

    async def _session(self, request: web.Request) -> web.Response:
        return self.auth.whoami(request)

    async def _audit(self, request: web.Request) -> web.Response:
        self.auth.check_read(request, Action.AUDIT_READ)
        since = _count(request.query.get("since"), 0)
        limit = _count(request.query.get("limit"), 200)
        return _json({"records": self.runtime.audit.newest(min(limit, 1000), since)})

    async def _body(self, request: web.Request) -> bytes:
        """The command's body, within ``web.body_timeout`` (408 and closed beyond it)."""
        try:
            async with asyncio.timeout(self.limits.body_timeout):
                return await request.read()
        except TimeoutError:
            self.counters.timeouts["body"] += 1
            self.refusals.note("body", _peer(request), f"{self.limits.body_timeout:g}")
            raise web.HTTPRequestTimeout(
                text="the request's body came too slowly (web.body_timeout)\n",
                headers={"Connection": "close"},
            ) from None
        except web.HTTPRequestEntityTooLarge:
            raise CommandRejected("the body is not a JSON command of at most 4 KiB") from None

    async def _command(self, request: web.Request) -> web.Response:
        if not self.section.commands:
            return self._refuse(
                "commands_off", 403, "commands from the web page are off (web.commands)"
            )
        try:
            identity = self.auth.check_change(request, Action.COMMAND)
        except Refused as refused:
            if refused.counter == "role":  # refused as any command: on the drive's events too
                self._role_refusal_event(request, refused.reason)
            raise
        state = self._state(request)
        page = request.headers.get("X-Page-Id", "")
        # the page id is the page's own choice: only its label is published (docs/safety.md)
        client = (
            f"{request.remote} {client_label(page)}"
            if PAGE_ID.fullmatch(page)
            else str(request.remote)
        )
        try:
            cmd = _parse_command(await self._body(request))
        except CommandRejected as exc:
            self.auth.command_audited(request, identity, f"drive {state.id}: {exc.reason}")
            self.hub.event(
                state.id,
                EventKind.COMMAND_REFUSED,
                f"command from {Source.WEB.value} {client} refused: {exc.reason}",
                source=Source.WEB.value,
                client=client,
            )
            self.counters.commands["refused"] += 1
            return _json({"accepted": False, "error": exc.reason}, 400)
        try:
            self.hub.submit(state.id, Source.WEB, cmd, client)  # reports its own refusals
        except CommandRejected as exc:
            self._audit_command(request, identity, state.id, cmd, Result.FAILURE, exc.reason)
            self.counters.commands["refused"] += 1
            return _json({"accepted": False, "error": exc.reason}, 409)
        if not cmd.is_empty:  # a keep-alive of the page in control is no audited command
            self._audit_command(request, identity, state.id, cmd, Result.SUCCESS)
        self.counters.commands["accepted"] += 1
        return _json({"accepted": True, "client": client})

    def _role_refusal_event(self, request: web.Request, reason: str) -> None:
        drive_id = request.match_info["drive"]
        if drive_id not in self.hub.drive_ids():
            return
        client = str(request.remote)
        self.hub.event(
            drive_id,
            EventKind.COMMAND_REFUSED,
            f"command from {Source.WEB.value} {client} refused: {reason}",
            source=Source.WEB.value,
            client=client,
        )

    def _audit_command(  # noqa: PLR0917 (a record's fields)
        self,
        request: web.Request,
        identity: Identity,
        drive: str,
        cmd: DriveCommand,
        result: Result,
        why: str = "",
    ) -> None:
        self.runtime.audit.command(
            cmd,
            result,
            interface="web",
            peer=_peer(request),
            identity=identity,
            drive=drive,
            why=why,
        )


def _count(text: str | None, default: int) -> int:
    """A non-negative whole number of a query string (``default`` if absent or not one)."""
    if text is None or not text.isascii() or not text.isdigit() or len(text) > 12:
        return default
    return int(text)


def _parse_command(body: bytes) -> DriveCommand:
    """The command in a request's body; CommandRejected naming what is wrong with it."""
    try:
        data = jsontext.loads(body)
    except jsontext.DuplicateKey as exc:
        raise CommandRejected(f"the body is refused: {exc}") from None
    except (ValueError, RecursionError):
        raise CommandRejected("the body is not a JSON command of at most 4 KiB") from None
    return DriveCommand.from_json(data)
