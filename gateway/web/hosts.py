"""Which host names the page answers to: the Host of every request, the Origin of a feed.

A page of another site can have the operator's browser ask the gateway for it under the
other site's own name (DNS rebinding: the name is made to point at the gateway), and a
browser then lets that page read the answers. Such a request names the other site in its
``Host``; so every request whose ``Host`` names no name of ``web.names``
(:attr:`gateway.webconfig.WebSection.host_names`) is refused with 421 before any handler
runs, and a feed (``/ws``, which a browser opens for a page of any site) is refused to a
page whose ``Origin`` names none of them. Both compare the name alone, never the port: a
reverse proxy or an SSH tunnel serves the page on a port of its own. An ``Origin`` is
never compared with the request's own ``Host``, which the other site chooses.
"""

from __future__ import annotations

import re
from collections.abc import Set

from gateway.webconfig import host_name

# name[:port]: a bracketed IPv6 address, or anything without a colon or bracket
_HOST = re.compile(r"(\[[^\]]*\]|[^:\[\]]*)(?::[0-9]*)?", re.ASCII)
_ORIGIN_SCHEMES = ("http", "https")
SHOWN_MAX = 80  # characters of a refused Host a log line shows


def name_of_host(header: str) -> str | None:
    """The host name of a ``Host`` header (``name[:port]``) as
    :func:`gateway.webconfig.host_name` writes it; None if the header is none."""
    match = _HOST.fullmatch(header.strip())
    return host_name(match.group(1)) if match else None


def host_admitted(header: str | None, version: tuple[int, int], names: Set[str]) -> bool:
    """Whether a request with this ``Host`` (None: none) is one for this gateway: its name
    is one of ``names``. A request without one is admitted only below HTTP/1.1 (which does
    not require it; a browser always sends it)."""
    if header is None:
        return version < (1, 1)
    return name_of_host(header) in names


def origin_admitted(origin: str | None, names: Set[str]) -> bool:
    """Whether a page with this ``Origin`` may open the feed: none (not a browser), or an
    http or https origin whose host is one of ``names``, whatever its port."""
    if origin is None:
        return True
    scheme, sep, rest = origin.partition("://")
    return bool(sep) and scheme.lower() in _ORIGIN_SCHEMES and name_of_host(rest) in names


def shown(header: str | None) -> str:
    """A refused ``Host`` as a log line shows it: quoted, escaped, cut short."""
    if header is None:
        return "(none)"
    return repr(header[:SHOWN_MAX]) + ("..." if len(header) > SHOWN_MAX else "")
