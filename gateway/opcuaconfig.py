"""The ``[opcua]`` table: where the OPC UA server listens and how a client must connect.

Part of the core's configuration (the OPC UA front end, gateway/opcua, reads it; the core
never imports the front end), read whether or not the front end is part of the build
(docs/operations.md, "OPC UA server").

- ``enabled``: the server runs. Absent: on when the table gives ``bind``, else off (a site
  config without ``[opcua]`` serves no OPC UA).
- ``bind``: HOST:PORT (default ``127.0.0.1:4840``); the endpoint is
  ``opc.tcp://HOST:PORT/drive-gateway``.
- ``security``: the security modes offered, among ``"none"``, ``"sign"`` and
  ``"sign_and_encrypt"`` (Basic256Sha256). ``"none"`` only on a loopback bind: anyone on
  the network could otherwise read and command the drives unauthenticated.
- ``certificate`` / ``private_key``: the server's certificate (DER) and key (PEM), needed
  by the signed modes; written at first start (self-signed) when both are absent. Paths
  are relative to the config file.
- ``trusted_clients``: a folder of client application certificates (DER or PEM, or the
  CAs that signed them): given, a client of a signed mode whose certificate is not trusted
  there is refused (BadCertificateUntrusted); absent, every client certificate is admitted.
- ``publish_interval``: s between the batches in which drive values reach the server (and
  the fastest a subscription sees them change).
- ``max_sessions``: OPC UA sessions open at once.
- ``max_subscriptions``: subscriptions one session may hold at once (beyond:
  BadTooManySubscriptions).
- ``max_monitored_items``: monitored items one session may hold at once, over all its
  subscriptions (beyond: BadTooManyMonitoredItems for each item over).
- ``min_publishing_interval``: s, the shortest publishing (and sampling) interval a
  subscription gets: a shorter one asked for is revised up to it.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from gateway.schema import Table
from gateway.webconfig import host_port


class OpcuaSecurity(Enum):
    """A security mode the server offers (policy Basic256Sha256 for the signed ones)."""

    NONE = "none"
    SIGN = "sign"
    SIGN_AND_ENCRYPT = "sign_and_encrypt"


DEFAULT_PORT = 4840
ENDPOINT_PATH = "drive-gateway"
LOOPBACK_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost"})


@dataclass(frozen=True, slots=True)
class OpcuaSection:
    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    security: tuple[OpcuaSecurity, ...] = (OpcuaSecurity.NONE,)
    certificate: Path | None = None
    private_key: Path | None = None
    trusted_clients: Path | None = None
    publish_interval: float = 0.1
    max_sessions: int = 32
    max_subscriptions: int = 20
    max_monitored_items: int = 10_000
    min_publishing_interval: float = 0.05

    @property
    def endpoint(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"opc.tcp://{host}:{self.port}/{ENDPOINT_PATH}"

    @property
    def signed(self) -> bool:
        """Whether a signed mode is offered (a certificate is needed)."""
        return any(s is not OpcuaSecurity.NONE for s in self.security)


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.0.0.0/8, ::1, localhost)."""
    if host.lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _bind(t: Table) -> tuple[str, int] | None:
    text: str | None = t.string("bind", None)
    if text is None:
        return None
    return host_port(t, text, "127.0.0.1:4840")


def _security(t: Table) -> tuple[OpcuaSecurity, ...]:
    default = OpcuaSection().security
    texts: tuple[str, ...] | None = t.str_list("security", None)
    if texts is None:
        return default
    choices = ", ".join(repr(s.value) for s in OpcuaSecurity)
    if not texts:
        t.errors.append(t.error("security", f"give at least one mode of {choices}"))
        return default
    out: list[OpcuaSecurity] = []
    for i, text in enumerate(texts):
        try:
            mode = OpcuaSecurity(text)
        except ValueError:
            t.errors.append(t.error(f"security[{i}]", f"{text!r} is not one of {choices}"))
            continue
        if mode not in out:
            out.append(mode)
    return tuple(out) or default


def _path(t: Table, key: str, base: Path) -> Path | None:
    text: str | None = t.string(key, None)
    if text is None:
        return None
    if not text or "\x00" in text:
        t.errors.append(t.error(key, "must be a file path"))
        return None
    path = Path(text)
    return path if path.is_absolute() else base / path


def read_opcua_section(t: Table, base: Path) -> OpcuaSection:
    """The ``[opcua]`` table (every problem recorded in ``t.errors``, as the loader reads)."""
    d = OpcuaSection()
    where = _bind(t)
    enabled: bool = t.boolean("enabled", where is not None)
    host, port = where or (d.host, d.port)
    security = _security(t)
    certificate = _path(t, "certificate", base)
    private_key = _path(t, "private_key", base)
    trusted = _path(t, "trusted_clients", base)
    section = OpcuaSection(
        enabled=enabled,
        host=host,
        port=port,
        security=security,
        certificate=certificate,
        private_key=private_key,
        trusted_clients=trusted,
        publish_interval=t.number(
            "publish_interval", d.publish_interval, minimum=0.02, maximum=60.0
        ),
        max_sessions=t.integer("max_sessions", d.max_sessions, minimum=1, maximum=1000),
        max_subscriptions=t.integer(
            "max_subscriptions", d.max_subscriptions, minimum=1, maximum=1000
        ),
        max_monitored_items=t.integer(
            "max_monitored_items", d.max_monitored_items, minimum=1, maximum=1_000_000
        ),
        min_publishing_interval=t.number(
            "min_publishing_interval", d.min_publishing_interval, minimum=0.01, maximum=60.0
        ),
    )
    for key, reason in section_problems(section):
        t.errors.append(t.error(key, reason))
    return section


def section_problems(section: OpcuaSection) -> list[tuple[str, str]]:
    """What is wrong with a section as a whole: (key, reason) pairs."""
    problems: list[tuple[str, str]] = []
    if OpcuaSecurity.NONE in section.security and not is_loopback(section.host):
        problems.append(
            (
                "security",
                f'"none" is refused on {section.host}, which is not a loopback address: any '
                "client on the network could read and command the drives unauthenticated; "
                'offer only "sign" and "sign_and_encrypt" there, or bind 127.0.0.1',
            )
        )
    if section.signed and section.certificate is None:
        problems.append(
            (
                "certificate",
                "the signed modes need the server's certificate: give certificate and "
                "private_key (both are written at first start when absent)",
            )
        )
    if section.trusted_clients is not None and not section.signed:
        problems.append(
            ("trusted_clients", 'a trust list needs a signed mode ("sign", "sign_and_encrypt")')
        )
    if (section.certificate is None) != (section.private_key is None):
        problems.append(("private_key", "give certificate and private_key together"))
    return problems
