"""What the web front end admits: who may connect, how many, and how long they may take.

Every connection passes :class:`Gate` before aiohttp sees a byte of it.
:class:`AdmissionSite` listens with :class:`AdmittedConnection` as its protocol, which
wraps aiohttp's own per-connection protocol:

- at accept (``connection_made``): a peer outside ``web.allow``, a connection beyond
  ``web.max_connections``, or beyond ``web.max_connections_per_peer`` from one address, is
  aborted there and then, before anything is read, and counted;
- the head of a request (request line and headers) must arrive within
  ``web.header_timeout`` of the connection's opening or of the end of its previous request;
  a connection that began a head and did not finish it in time is closed and counted
  (``timeouts["header"]``); one that sent nothing in that time is closed as idle,
  uncounted;
- while a request runs, its answer must be written within ``web.body_timeout`` and
  :data:`ANSWER_TIMEOUT` of its head, else the connection is cut and counted
  (``timeouts["answer"]``): a client that does not read its answer holds its place no
  longer. A page has no deadline here: the feed watches it. The front end tells the
  connection where a request begins and ends (:meth:`AdmittedConnection.request_started`,
  :meth:`AdmittedConnection.page_opened`, :meth:`AdmittedConnection.expect_request`);
- pages (WebSocket feeds): at most ``web.max_pages`` open, ``web.max_pages_per_peer`` from
  one address (:meth:`Gate.page_refusal`).

A refusal repeated any number of times writes one log line per kind and
:data:`LOG_PERIOD` (:class:`RefusalLog`, on :class:`gateway.ratelimit.LogRateLimit`). So
does a request aiohttp itself answers with an error (a malformed one: 400), through
:class:`RequestLog`, the logger the front end gives aiohttp's per-connection protocol.
"""

from __future__ import annotations

import asyncio
import collections
import ipaddress
import logging
import ssl
import time
from collections.abc import Callable
from dataclasses import dataclass

from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError

from gateway.errors import StartupError
from gateway.ratelimit import LogRateLimit
from gateway.web.counters import WebCounters
from gateway.web.rate import RequestRate
from gateway.webconfig import IpNetwork, WebSection

log = logging.getLogger("gateway.web")

LOG_PERIOD = 10.0  # s: one log line per kind of refusal and period, with the count held back
BACKLOG = 128  # connections the kernel holds before they are accepted
ANSWER_TIMEOUT = 30.0  # s an answer may take to be written, beyond web.body_timeout


def address_of(peer: str | None) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    """The client's address (an IPv4 address in IPv6 form as IPv4), None if it is none."""
    if not peer:
        return None
    try:
        address = ipaddress.ip_address(peer.partition("%")[0])
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped
    return address


def allowed(peer: str | None, networks: tuple[IpNetwork, ...]) -> bool:
    address = address_of(peer)
    return address is not None and any(address in net for net in networks)


def peer_of(transport: asyncio.BaseTransport) -> str:
    """The connection's client address, as :func:`address_of` writes it ("" if none)."""
    peername = transport.get_extra_info("peername")
    address = address_of(str(peername[0])) if peername else None
    return str(address) if address is not None else ""


# ---------------------------------------------------------------- log lines


@dataclass(frozen=True, slots=True)
class Refusal:
    """A kind of refusal: its log level, its line and what its summary line counts."""

    level: int
    line: str  # %-format: the peer, then a figure (the limit, a count)
    summary: str  # "<count> more <summary> since the last line"


REFUSALS: dict[str, Refusal] = {
    "allow": Refusal(
        logging.WARNING,
        "web connection from %s refused: not in web.allow (%s)",
        "connections refused (not in web.allow)",
    ),
    "over_limit": Refusal(
        logging.WARNING,
        "web connection from %s refused: web.max_connections (%s) are open",
        "connections refused (web.max_connections open)",
    ),
    "over_peer_limit": Refusal(
        logging.WARNING,
        "web connection from %s refused: web.max_connections_per_peer (%s) are open from it",
        "connections refused (web.max_connections_per_peer open)",
    ),
    "header": Refusal(
        logging.INFO,
        "web connection from %s closed: no request head within web.header_timeout (%s s)",
        "connections closed (a request head slower than web.header_timeout)",
    ),
    "answer": Refusal(
        logging.INFO,
        "web connection from %s cut: its answer was not taken within %s s",
        "connections cut (an answer not taken in time)",
    ),
    "body": Refusal(
        logging.INFO,
        "web request from %s refused (408): its body took over web.body_timeout (%s s)",
        "requests refused (a body slower than web.body_timeout)",
    ),
    "pages": Refusal(
        logging.WARNING,
        "web page from %s refused (503): web.max_pages (%s) are open",
        "pages refused (web.max_pages open)",
    ),
    "pages_per_peer": Refusal(
        logging.WARNING,
        "web page from %s refused (503): web.max_pages_per_peer (%s) are open from it",
        "pages refused (web.max_pages_per_peer open)",
    ),
    "over_budget": Refusal(
        logging.INFO,
        "web page at %s dropped: more than web.page_send_budget_kib (%s KiB) left unsent",
        "pages dropped (over web.page_send_budget_kib)",
    ),
    "token": Refusal(
        logging.INFO,
        "web command from %s refused (401): no valid token (%s wrong within web.token_window)",
        "commands refused (no valid token)",
    ),
    "token_limit": Refusal(
        logging.WARNING,
        "web commands from %s refused (429) unchecked: web.token_failures wrong tokens"
        " within web.token_window; %s s to wait",
        "commands refused unchecked (too many wrong tokens)",
    ),
    "login": Refusal(
        logging.WARNING,
        "web login from %s failed (%s wrong within web.token_window)",
        "logins failed",
    ),
    "login_limit": Refusal(
        logging.WARNING,
        "web logins from %s refused (429) unchecked: web.token_failures failed logins"
        " within web.token_window; %s s to wait",
        "logins refused unchecked (too many failed logins)",
    ),
    "login_busy": Refusal(
        logging.WARNING,
        "web login from %s refused (503): %s logins are waiting for their check",
        "logins refused (too many at once)",
    ),
    "role": Refusal(
        logging.INFO,
        "web request from %s refused (403): %s",
        "requests refused (the role does not allow them)",
    ),
    "csrf": Refusal(
        logging.WARNING,
        "web request from %s refused (403): no valid CSRF token (%s)",
        "requests refused (no valid CSRF token)",
    ),
    "request_rate": Refusal(
        logging.INFO,
        "web requests from %s held back: over web.request_rate (%s)",
        "requests held back (over web.request_rate)",
    ),
    "host": Refusal(
        logging.WARNING,
        "web request from %s refused (421): its Host %s is not in web.names",
        "requests refused (a Host not in web.names)",
    ),
    "bad_request": Refusal(
        logging.INFO,
        "web request from %s refused (400): %s",
        "malformed requests refused (400)",
    ),
    "request_error": Refusal(
        logging.ERROR,
        "web request from %s failed in the gateway: %s",
        "requests failed in the gateway",
    ),
}


class RefusalLog:
    """One line per kind of refusal and :data:`LOG_PERIOD`: the first one of a period is
    written, naming its peer and how many were held back since the last line."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._limit = LogRateLimit(LOG_PERIOD)
        self.listener: Callable[[str, str, str], None] | None = None
        """Told of every refusal, logged or not: its kind, peer and line (the audit)."""

    def note(
        self, kind: str, peer: str, figure: object, exc_info: BaseException | None = None
    ) -> None:
        """A refusal of ``kind`` (a key of :data:`REFUSALS`) of ``peer``; ``exc_info``: the
        failure whose traceback the line carries, if it is written."""
        if self.listener is not None:
            self.listener(kind, peer, REFUSALS[kind].line % (peer, figure))
        held = self._limit.admit(kind, self.clock())
        if held is None:
            return
        refusal = REFUSALS[kind]
        more = f"; {held} more since the last line" if held else ""
        log.log(refusal.level, refusal.line + "%s", peer, figure, more, exc_info=exc_info)

    def flush(self) -> None:
        """A summary line for each kind held back over a whole period."""
        for kind, held in self._limit.flush(self.clock()):
            refusal = REFUSALS[str(kind)]
            log.log(refusal.level, "web: %d more %s since the last line", held, refusal.summary)


REASON_MAX = 120  # characters of aiohttp's reason a line shows


def _first_line(text: str) -> str:
    line = text.strip().partition("\n")[0].strip()
    return line[:REASON_MAX] or "no reason given"


class RequestLog(logging.Logger):
    """The logger of aiohttp's per-connection protocol (``logger=``): what it logs as an
    error becomes one line per kind and :data:`LOG_PERIOD` on :class:`RefusalLog`, and its
    answer stays aiohttp's own. A malformed request (aiohttp answers 400) is the client's
    doing: its line gives aiohttp's reason, no traceback. A request that failed in the
    gateway (a handler's exception: 500) is its own fault: the line written carries the
    traceback. aiohttp's debug lines pass as they are."""

    def __init__(self, refusals: RefusalLog) -> None:
        super().__init__(f"{log.name}.requests")
        self.parent = log
        self._refusals = refusals

    def handle(self, record: logging.LogRecord) -> None:
        if record.levelno < logging.WARNING:
            super().handle(record)
            return
        failure = record.exc_info[1] if record.exc_info else None
        peer = _record_peer(record)
        if isinstance(failure, HttpProcessingError):
            self._refusals.note("bad_request", peer, _first_line(failure.message))
            return
        what = (
            f"{type(failure).__name__}: {_first_line(str(failure))}"
            if failure is not None
            else record.getMessage()
        )
        self._refusals.note("request_error", peer, what, exc_info=failure)


def _record_peer(record: logging.LogRecord) -> str:
    """The client address aiohttp's line names ("Error handling request from %s")."""
    args = record.args
    if isinstance(args, tuple) and args and isinstance(args[0], str):
        address = address_of(args[0])
        if address is not None:
            return str(address)
    return "an unknown address"


# ---------------------------------------------------------------- the gate


class Gate:
    """The counts of open connections and pages, in all and per client address."""

    def __init__(self, section: WebSection, counters: WebCounters, refusals: RefusalLog) -> None:
        self.allow = section.allow
        self._allow_text = ", ".join(str(n) for n in section.allow)
        self.limits = section.limits
        self.counters = counters
        self.refusals = refusals
        self._connections: collections.Counter[str] = collections.Counter()
        self._pages: collections.Counter[str] = collections.Counter()
        self.rate = RequestRate(section.limits.request_rate, section.limits.request_burst)

    @property
    def answer_timeout(self) -> float:
        """Seconds from a request's head to its answer written."""
        return self.limits.body_timeout + ANSWER_TIMEOUT

    # ------------------------------------------------------------ connections

    def _connection_refusal(self, peer: str) -> tuple[str, object] | None:
        limits = self.limits
        if not allowed(peer, self.allow):
            return "refused", self._allow_text
        if self.counters.connections_open >= limits.max_connections:
            return "over_limit", limits.max_connections
        if self._connections[peer] >= limits.max_connections_per_peer:
            return "over_peer_limit", limits.max_connections_per_peer
        return None

    def admit(self, peer: str) -> bool:
        """Whether a new connection from ``peer`` may stay; counted either way."""
        refusal = self._connection_refusal(peer)
        if refusal is not None:
            reason, limit = refusal
            self.counters.connections[reason] += 1
            self.refusals.note("allow" if reason == "refused" else reason, peer, limit)
            return False
        self._connections[peer] += 1
        self.counters.connections["accepted"] += 1
        self.counters.connections_open += 1
        return True

    def request_wait(self, peer: str, now: float) -> float:
        """A request of ``peer`` arrived: seconds its connection is not to be read (0: none)."""
        wait = self.rate.take(peer, now)
        if wait:
            self.counters.throttled += 1
            self.refusals.note("request_rate", peer, f"{self.limits.request_rate:g}/s")
        return wait

    def release(self, peer: str) -> None:
        """An admitted connection from ``peer`` is gone."""
        self.counters.connections_open -= 1
        self._connections[peer] -= 1
        if self._connections[peer] <= 0:
            del self._connections[peer]

    def late(self, phase: str, peer: str) -> None:
        """A connection of ``peer`` was cut: its request's head or its answer was late."""
        self.counters.timeouts[phase] += 1
        figure = self.limits.header_timeout if phase == "header" else self.answer_timeout
        self.refusals.note(phase, peer, f"{figure:g}")

    # ------------------------------------------------------------ pages

    def page_refusal(self, peer: str) -> str | None:
        """Why a new page from ``peer`` is refused (counted and logged), or None."""
        limits = self.limits
        if self.counters.clients_open >= limits.max_pages:
            reason, limit = "pages", limits.max_pages
        elif self._pages[peer] >= limits.max_pages_per_peer:
            reason, limit = "pages_per_peer", limits.max_pages_per_peer
        else:
            return None
        self.counters.refused[reason] += 1
        self.refusals.note(reason, peer, limit)
        return reason

    def page_opened(self, peer: str) -> None:
        self._pages[peer] += 1
        self.counters.clients_open += 1

    def page_closed(self, peer: str) -> None:
        self.counters.clients_open -= 1
        self._pages[peer] -= 1
        if self._pages[peer] <= 0:
            del self._pages[peer]


# ---------------------------------------------------------------- one connection


def _abort(transport: asyncio.BaseTransport) -> None:
    """Close at once, dropping whatever is unsent (a socket transport can)."""
    if isinstance(transport, asyncio.WriteTransport):
        transport.abort()
    else:
        transport.close()


class AdmittedConnection(asyncio.Protocol):
    """One accepted connection: refused at once, or handed to aiohttp's own protocol
    (made by ``make_protocol`` only once admitted) under a deadline: for the next request's
    head while it waits for one, for the answer while a request runs, none for a page."""

    def __init__(
        self,
        gate: Gate,
        make_protocol: Callable[[], asyncio.Protocol],
        loop: asyncio.AbstractEventLoop,
    ) -> None:
        self._gate = gate
        self._make_protocol = make_protocol
        self._loop = loop
        self._inner: asyncio.Protocol | None = None
        self._transport: asyncio.BaseTransport | None = None
        self._deadline: asyncio.TimerHandle | None = None
        self._awaiting_head = False
        self._heard = False  # bytes came while a head was awaited: a head begun
        self._held = False  # not read until the address's next request is due
        self.peer = ""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        peer = peer_of(transport)
        if not self._gate.admit(peer):
            _abort(transport)
            return
        self.peer = peer
        self._transport = transport
        self._inner = self._make_protocol()
        self._inner.connection_made(transport)
        self.expect_request()
        self._hold(self._gate.rate.wait(peer, self._loop.time()))

    def data_received(self, data: bytes) -> None:
        if self._inner is None:
            return
        if self._awaiting_head:
            self._heard = True
        self._inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self._inner.eof_received() if self._inner is not None else None

    def pause_writing(self) -> None:
        if self._inner is not None:
            self._inner.pause_writing()

    def resume_writing(self) -> None:
        if self._inner is not None:
            self._inner.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_deadline()
        inner, self._inner = self._inner, None
        self._transport = None
        if inner is None:
            return
        self._gate.release(self.peer)
        inner.connection_lost(exc)

    # ------------------------------------------------------------ request boundaries

    def request_started(self) -> None:
        """A request's head has arrived: its answer is due within ``web.body_timeout`` (for
        its body) and :data:`ANSWER_TIMEOUT` (for the answer to be written). An address over
        ``web.request_rate`` has this connection left unread until its next request is due:
        the client slows down, and the gateway spends nothing on it meanwhile."""
        self._arm(self._gate.answer_timeout, self._answer_late)
        self._hold(self._gate.request_wait(self.peer, self._loop.time()))

    def _hold(self, wait: float) -> None:
        transport = self._transport
        if wait <= 0 or not isinstance(transport, asyncio.ReadTransport) or self._held:
            return
        self._held = True
        transport.pause_reading()
        self._loop.call_later(wait, self._release_hold)

    def _release_hold(self) -> None:
        self._held = False
        transport = self._transport
        if isinstance(transport, asyncio.ReadTransport) and not transport.is_closing():
            transport.resume_reading()

    def page_opened(self) -> None:
        """The request became a page: the feed watches it from now on (its send budget,
        its send timeout and its ping), with no deadline here."""
        self._stop_deadline()

    def expect_request(self) -> None:
        """The next request's head is due within ``web.header_timeout`` from now."""
        self._arm(self._gate.limits.header_timeout, self._head_late)
        self._awaiting_head = True
        self._heard = False

    def _stop_deadline(self) -> None:
        self._awaiting_head = False
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _arm(self, delay: float, late: Callable[[], None]) -> None:
        """The deadline from now on: ``late`` runs in ``delay`` seconds."""
        self._stop_deadline()
        if self._transport is not None:
            self._deadline = self._loop.call_later(delay, late)

    def _head_late(self) -> None:
        self._deadline = None
        if self._transport is None:
            return
        if self._heard:
            self._gate.late("header", self.peer)
        _abort(self._transport)

    def _answer_late(self) -> None:
        self._deadline = None
        if self._transport is not None:
            self._gate.late("answer", self.peer)
            _abort(self._transport)


def connection_of(request: web.BaseRequest) -> AdmittedConnection | None:
    """The admitted connection a request came on (None for one made otherwise)."""
    transport = request.transport
    protocol = transport.get_protocol() if transport is not None else None
    return protocol if isinstance(protocol, AdmittedConnection) else None


# ---------------------------------------------------------------- the site


class AdmissionSite(web.BaseSite):
    """A TCP site whose every connection passes the :class:`Gate` first."""

    __slots__ = ("_gate", "_host", "_port")

    def __init__(
        self,
        runner: web.BaseRunner,
        host: str,
        port: int,
        gate: Gate,
        ssl_context: ssl.SSLContext | None = None,
    ) -> None:
        super().__init__(runner, backlog=BACKLOG, ssl_context=ssl_context)
        self._gate = gate
        self._host = host
        self._port = port

    @property
    def name(self) -> str:
        host = f"[{self._host}]" if ":" in self._host else self._host
        scheme = "https" if self._ssl_context is not None else "http"
        return f"{scheme}://{host}:{self._port}"

    @property
    def bound(self) -> tuple[str, int] | None:
        """The address it listens on (the port chosen by the system for port 0)."""
        server = self._server
        sockets = server.sockets if isinstance(server, asyncio.Server) else ()
        if not sockets:
            return None
        host, port = sockets[0].getsockname()[:2]
        return str(host), int(port)

    async def start(self) -> None:
        await super().start()
        loop = asyncio.get_running_loop()
        http = self._runner.server
        if http is None:
            raise StartupError(
                "web front end",
                "its site was started before its runner was set up",
                "report this as a bug of drive-gateway",
            )
        self._server = await loop.create_server(
            lambda: AdmittedConnection(self._gate, http, loop),
            self._host,
            self._port,
            backlog=self._backlog,
            reuse_address=True,
            ssl=self._ssl_context,
            # a TLS handshake is part of a request's head: the same deadline
            ssl_handshake_timeout=self._gate.limits.header_timeout
            if self._ssl_context is not None
            else None,
        )
