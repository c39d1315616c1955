"""The ``[web]`` table: where the status page listens, who may see it, who may command.

Part of the core's configuration (the web front end reads it, the core never imports the
front end): the config loader reads this table whether or not the web front end is part of
the build (docs/operations.md, "Web status page and metrics").

- ``bind``: HOST:PORT. Absent: the web front end is off (a site config says so on purpose).
- ``allow``: client addresses or CIDR networks; absent: loopback only. An empty list is an
  error (it would refuse everyone); ``["0.0.0.0/0", "::/0"]`` admits any address.
- ``names``: the host names (or addresses) users reach the page by; a request whose Host
  names another is refused (421), and the feed is refused to a page whose Origin names
  another. Absent: ``localhost``, ``127.0.0.1``, ``[::1]`` and the bind address itself
  (:meth:`WebSection.host_names`); a site binding a wider address lists its names.
- ``commands``: false (default) serves a read-only page and refuses every command request.
- ``token_sha256``: the hex SHA-256 of a shared token that commands as the operator
  ``token``: for a page on this machine alone (``allow`` loopback only). Commands on a page
  other machines reach need ``[[users]]`` (gateway/access/users.py): the config is refused
  otherwise. The config file holds the digest, never the token itself.
- ``anonymous``: what a request with no login may do: ``"viewer"`` (default: the
  read-only page, the API, /metrics) or ``"none"`` (only the page's files and the login).
- ``tls_cert``, ``tls_key``: PEM files (both or neither): the page is served over HTTPS,
  and the session cookie is marked Secure.
- the admission limits (:class:`WebLimits`, docs/operations.md, "Web status page and
  metrics"): connections in all and per client address, the time a client has to send a
  request's head and body, pages in all and per address with what each may have unsent,
  wrong tokens per address, and how often ``/metrics`` is rendered.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass, field
from pathlib import Path

from gateway.errors import ConfigError
from gateway.schema import Table

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
LOOPBACK: tuple[IpNetwork, ...] = (
    ipaddress.ip_network("127.0.0.0/8"),
    ipaddress.ip_network("::1/128"),
)
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")
"""The names a page on this very machine is reached by: the default of ``web.names``."""
MAX_NAMES = 64
_LABEL = r"(?!-)[a-z0-9_-]{1,63}(?<!-)"
_HOST_NAME = re.compile(rf"{_LABEL}(?:\.{_LABEL})*", re.ASCII)
_NAMES_HINT = "a host name or address, without scheme or port (like edge-box-3.plant.example)"


def host_name(text: str) -> str | None:
    """``text`` as a host name the page is reached by, in the one form names are compared
    in (lower case, no final dot, an IPv6 address compressed and in brackets); None if it
    is neither a host name nor an address."""
    name = text.strip().lower()
    bracketed = name.startswith("[") and name.endswith("]")
    inner = name[1:-1] if bracketed else name
    if ":" in inner:
        try:
            return f"[{ipaddress.IPv6Address(inner).compressed}]"
        except ValueError:
            return None
    name = inner.removesuffix(".")
    if bracketed or len(name) > 253 or not _HOST_NAME.fullmatch(name):
        return None
    return name


def _is_wildcard(host: str) -> bool:
    """Whether the bind host is "every address" (0.0.0.0, ::), which names no host."""
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False


@dataclass(frozen=True, slots=True)
class WebLimits:
    """What the web front end admits, so that no client can slow the gateway."""

    max_connections: int = 128  # connections open at once; more are closed at accept
    max_connections_per_peer: int = 64  # from one client address
    header_timeout: float = 10.0  # s to send a request's head, from opening or the last answer
    body_timeout: float = 10.0  # s to send a request's body once its head arrived
    max_pages: int = 48  # live pages (WebSocket feeds) open at once
    max_pages_per_peer: int = 24  # from one client address
    page_send_budget_kib: int = 512  # KiB a page may leave unsent before it is dropped
    token_failures: int = 5  # wrong tokens one address may give within token_window
    token_window: float = 60.0  # s; beyond token_failures the address gets 429 unchecked
    metrics_max_age: float = 0.5  # s one /metrics render serves every scrape
    request_rate: float = 50.0  # requests per second one address may send; beyond, unread
    request_burst: int = 100  # requests one address may send at once before request_rate

    @property
    def page_send_budget(self) -> int:
        """Bytes a page may leave unsent."""
        return self.page_send_budget_kib * 1024


@dataclass(frozen=True, slots=True)
class WebSection:
    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = 8080
    allow: tuple[IpNetwork, ...] = LOOPBACK
    commands: bool = False
    token_sha256: str | None = None
    limits: WebLimits = field(default_factory=WebLimits)
    names: tuple[str, ...] | None = None  # as host_name writes them; None: the default
    anonymous: bool = True  # a request with no login may read (the viewer role)
    tls_cert: Path | None = None
    tls_key: Path | None = None

    @property
    def tls(self) -> bool:
        return self.tls_cert is not None and self.tls_key is not None

    @property
    def loopback_only(self) -> bool:
        """Whether only this machine may reach the page (every ``allow`` is loopback)."""
        return all(
            net.network_address.is_loopback and net.broadcast_address.is_loopback
            for net in self.allow
        )

    @property
    def host_names(self) -> frozenset[str]:
        """The names a request's Host and a page's Origin may give: ``names`` as given,
        else the loopback names and the bind host itself (unless it is 0.0.0.0 or ::)."""
        if self.names is not None:
            return frozenset(self.names)
        own = host_name(self.host) if not _is_wildcard(self.host) else None
        return frozenset(LOOPBACK_NAMES) | ({own} if own else set())

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}/"


def host_port(t: Table, text: str, example: str = "127.0.0.1:8080") -> tuple[str, int] | None:
    """A ``bind`` of a front end's table as (host, port); None with the error noted."""
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not (port_text.isascii() and port_text.isdigit()):
        t.errors.append(t.error("bind", f"{text!r} is not HOST:PORT (like {example})"))
        return None
    port = int(port_text)
    if not 0 <= port <= 65535:
        t.errors.append(t.error("bind", f"port {port} is not 0-65535"))
        return None
    return host, port


def _allow(t: Table) -> tuple[IpNetwork, ...]:
    texts: tuple[str, ...] | None = t.str_list("allow", None)
    if texts is None:
        return LOOPBACK
    if not texts:
        t.errors.append(
            t.error(
                "allow",
                'an empty list refuses everyone; name the client networks ("0.0.0.0/0" '
                'and "::/0" admit any address), or leave the key out for loopback only',
            )
        )
        return LOOPBACK
    out: list[IpNetwork] = []
    for i, text in enumerate(texts):
        try:
            out.append(ipaddress.ip_network(text, strict=False))
        except ValueError:
            t.errors.append(t.error(f"allow[{i}]", f"{text!r} is not an address or CIDR network"))
    return tuple(out) or LOOPBACK


def _names(t: Table) -> tuple[str, ...] | None:
    texts: tuple[str, ...] | None = t.str_list("names", None)
    if texts is None:
        return None
    if not texts or len(texts) > MAX_NAMES:
        t.errors.append(
            t.error(
                "names",
                f"give 1 to {MAX_NAMES} names users reach the page by, or leave the key out "
                "for the loopback names and the bind address",
            )
        )
        return None
    out: list[str] = []
    for i, text in enumerate(texts):
        name = host_name(text)
        if name is None:
            t.errors.append(t.error(f"names[{i}]", f"{text!r} is not {_NAMES_HINT}"))
        elif name not in out:
            out.append(name)
    return tuple(out) or None


def _token(t: Table, commands: bool) -> str | None:
    digest: str | None = t.string("token_sha256", None)
    if digest is not None and not _SHA256_HEX.fullmatch(digest):
        t.errors.append(
            t.error(
                "token_sha256",
                "must be 64 lower-case hex digits: the SHA-256 of the token "
                "(printf %s TOKEN | sha256sum)",
            )
        )
        digest = None
    return digest


def _positive(t: Table, key: str, default: float, maximum: float) -> float:
    value: float = t.number(key, default, maximum=maximum)
    if value <= 0:
        t.errors.append(t.error(key, f"must be above 0 s, not {value:g}"))
        return default
    return value


def _at_most(t: Table, key: str, value: int, limit: tuple[str, int], why: str) -> int:
    """``value`` of ``key`` within ``limit`` (a key and its value): a default above it is
    lowered to it, a value given above it is an error."""
    limit_key, most = limit
    if value <= most:
        return value
    if t.has(key):
        t.errors.append(t.error(key, f"{value} is above {limit_key} ({most}): {why}"))
    return most


def _limits(t: Table) -> WebLimits:
    d = WebLimits()
    connections: int = t.integer("max_connections", d.max_connections, minimum=1, maximum=1000)
    per_peer: int = t.integer(
        "max_connections_per_peer", d.max_connections_per_peer, minimum=1, maximum=1000
    )
    pages: int = t.integer("max_pages", d.max_pages, minimum=1, maximum=1000)
    pages_per_peer: int = t.integer(
        "max_pages_per_peer", d.max_pages_per_peer, minimum=1, maximum=1000
    )
    each_page = "every page holds a connection"
    per_peer = _at_most(
        t,
        "max_connections_per_peer",
        per_peer,
        ("max_connections", connections),
        "one address never holds more than all",
    )
    pages = _at_most(t, "max_pages", pages, ("max_connections", connections), each_page)
    pages_per_peer = _at_most(
        t,
        "max_pages_per_peer",
        pages_per_peer,
        ("max_pages", pages),
        "one address never holds more pages than all",
    )
    pages_per_peer = _at_most(
        t, "max_pages_per_peer", pages_per_peer, ("max_connections_per_peer", per_peer), each_page
    )
    return WebLimits(
        max_connections=connections,
        max_connections_per_peer=per_peer,
        header_timeout=_positive(t, "header_timeout", d.header_timeout, 3600.0),
        body_timeout=_positive(t, "body_timeout", d.body_timeout, 3600.0),
        max_pages=pages,
        max_pages_per_peer=pages_per_peer,
        page_send_budget_kib=t.integer(
            "page_send_budget_kib", d.page_send_budget_kib, minimum=16, maximum=65536
        ),
        token_failures=t.integer("token_failures", d.token_failures, minimum=1, maximum=1000),
        token_window=t.number("token_window", d.token_window, minimum=1.0, maximum=86400.0),
        metrics_max_age=t.number("metrics_max_age", d.metrics_max_age, minimum=0.5, maximum=3600.0),
        request_rate=t.number("request_rate", d.request_rate, minimum=1.0, maximum=100000.0),
        request_burst=t.integer("request_burst", d.request_burst, minimum=1, maximum=100000),
    )


ANONYMOUS_CHOICES = {"viewer": True, "none": False}


def _anonymous(t: Table) -> bool:
    text: str = t.string("anonymous", "viewer")
    if text not in ANONYMOUS_CHOICES:
        t.errors.append(t.error("anonymous", f'{text!r} is not "viewer" or "none"'))
        return True
    return ANONYMOUS_CHOICES[text]


def _tls(t: Table, base: Path | None) -> tuple[Path | None, Path | None]:
    cert: str | None = t.string("tls_cert", None)
    key: str | None = t.string("tls_key", None)
    if (cert is None) != (key is None):
        t.errors.append(
            t.error("tls_cert" if cert is None else "tls_key", "give tls_cert and tls_key both")
        )
        return None, None
    if cert is None or key is None:
        return None, None
    out: list[Path] = []
    for name, text in (("tls_cert", cert), ("tls_key", key)):
        path = Path(text)
        if not path.is_absolute() and base is not None:
            path = base / path
        if not path.is_file():
            t.errors.append(t.error(name, f"{str(path)!r} is not a file"))
        out.append(path)
    return out[0], out[1]


def read_web_section(t: Table, base: Path | None = None) -> WebSection:
    """The ``[web]`` table (every problem recorded in ``t.errors``, as the loader reads)."""
    d = WebSection()
    bind: str | None = t.string("bind", None)
    where = host_port(t, bind) if bind is not None else None
    commands: bool = t.boolean("commands", d.commands)
    tls = _tls(t, base)
    return WebSection(
        enabled=where is not None,
        host=where[0] if where else d.host,
        port=where[1] if where else d.port,
        allow=_allow(t),
        names=_names(t),
        commands=commands,
        token_sha256=_token(t, commands),
        limits=_limits(t),
        anonymous=_anonymous(t),
        tls_cert=tls[0],
        tls_key=tls[1],
    )


def web_bind(section: WebSection, text: str) -> WebSection:
    """``section`` listening on ``text`` (HOST:PORT) instead; ConfigError if it is not one."""
    from dataclasses import replace

    t = Table({"bind": text}, "--web-bind", collect=True)
    where = host_port(t, text)
    if where is None:
        raise ConfigError("--web-bind", "", t.errors[0].reason)
    return replace(section, enabled=True, host=where[0], port=where[1])
