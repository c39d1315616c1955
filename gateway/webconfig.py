"""The ``[web]`` table: where the status page listens, who may see it, who may command.

Part of the core's configuration (the web front end reads it, the core never imports the
front end): the config loader reads this table whether or not the web front end is part of
the build (docs/operations.md, "Web status page and metrics").

- ``bind``: HOST:PORT. Absent: the web front end is off (a site config says so on purpose).
- ``allow``: client addresses or CIDR networks; absent: loopback only. An empty list is an
  error (it would refuse everyone); ``["0.0.0.0/0", "::/0"]`` admits any address.
- ``commands``: false (default) serves a read-only page and refuses every command request.
- ``token_sha256``: the hex SHA-256 of the token a user gives to command (required when
  ``commands = true``). The config file holds the digest, never the token itself.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass

from gateway.errors import ConfigError
from gateway.schema import Table

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
LOOPBACK: tuple[IpNetwork, ...] = (
    ipaddress.ip_network("127.0.0.0/8"),
    ipaddress.ip_network("::1/128"),
)
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True, slots=True)
class WebSection:
    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = 8080
    allow: tuple[IpNetwork, ...] = LOOPBACK
    commands: bool = False
    token_sha256: str | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"


def _host_port(t: Table, text: str) -> tuple[str, int] | None:
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not (port_text.isascii() and port_text.isdigit()):
        t.errors.append(t.error("bind", f"{text!r} is not HOST:PORT (like 127.0.0.1:8080)"))
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
    if commands and digest is None and not t.has("token_sha256"):
        t.errors.append(
            t.error(
                "commands",
                "commands = true needs token_sha256 (the SHA-256 of the token a user gives)",
            )
        )
    return digest


def read_web_section(t: Table) -> WebSection:
    """The ``[web]`` table (every problem recorded in ``t.errors``, as the loader reads)."""
    d = WebSection()
    bind: str | None = t.string("bind", None)
    where = _host_port(t, bind) if bind is not None else None
    commands: bool = t.boolean("commands", d.commands)
    return WebSection(
        enabled=where is not None,
        host=where[0] if where else d.host,
        port=where[1] if where else d.port,
        allow=_allow(t),
        commands=commands,
        token_sha256=_token(t, commands),
    )


def web_bind(section: WebSection, text: str) -> WebSection:
    """``section`` listening on ``text`` (HOST:PORT) instead; ConfigError if it is not one."""
    from dataclasses import replace

    t = Table({"bind": text}, "--web-bind", collect=True)
    where = _host_port(t, text)
    if where is None:
        raise ConfigError("--web-bind", "", t.errors[0].reason)
    return replace(section, enabled=True, host=where[0], port=where[1])
