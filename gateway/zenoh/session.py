"""The Zenoh session configuration: always explicit, never a bare ``zenoh.Config()``.

A bare ``zenoh.Config()`` listens on every interface and joins multicast
scouting. The gateway instead sets the mode, the listen and connect endpoints
and the scouting switches from the ``[zenoh]`` section every time, so no Zenoh
traffic leaves the endpoints the config names. Gossip scouting follows
``multicast_scouting``: off, the session meets only the peers it connects to or
that connect to it. A ``zenoh.config_file`` (JSON5) replaces all of this and
is given to Zenoh as it is (routers, TLS/mTLS, access control): the text checked
when the config was loaded (gateway.config.read_zenoh_config_file: size, nesting
depth, JSON5 syntax), never the file read again by Zenoh. One exception: shared
memory stays off unless that file sets ``transport.shared_memory`` itself. Zenoh
enables it by default, and then any same-host client that puts more than about
3 KB makes the gateway map 16 MB segments that it never gives back (issue 18).

:func:`open_session` turns Zenoh's refusal to open (an endpoint it cannot parse or
bind) into a :class:`StartupError` naming the cause and the fix: the daemon stops
at start-up on it instead of retrying for ever.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import zenoh

from gateway.config import ZenohSection, read_zenoh_config_file
from gateway.errors import ConfigError, StartupError


def config_document(section: ZenohSection) -> dict[str, Any]:
    """The JSON5 document the gateway gives Zenoh when no config file is named."""
    scouting = section.multicast_scouting
    return {
        "mode": section.mode,
        "listen": {"endpoints": list(section.listen)},
        "connect": {"endpoints": list(section.connect)},
        "scouting": {
            "multicast": {"enabled": scouting},
            "gossip": {"enabled": scouting},
        },
        "transport": {"shared_memory": {"enabled": False}},
    }


SHARED_MEMORY_KEY = "transport/shared_memory/enabled"


def zenoh_config(section: ZenohSection) -> zenoh.Config:
    """The session config for ``section``; raises ConfigError if Zenoh refuses it."""
    if section.config_file is not None:
        text = section.config_text
        if text is None:  # a section made in code: checked the same way as at load
            text = read_zenoh_config_file(Path(section.config_file))
        try:
            config = zenoh.Config.from_json5(text)
        except zenoh.ZError as exc:
            reason = f"not a Zenoh config: {zenoh_reason(exc)}"
            raise ConfigError(str(section.config_file), "", reason) from None
        if "shared_memory" not in text:  # the file does not decide: off (module docstring)
            config.insert_json5(SHARED_MEMORY_KEY, "false")
        return config
    try:
        return zenoh.Config.from_json5(json.dumps(config_document(section)))
    except zenoh.ZError as exc:
        reason = f"Zenoh refuses the session config: {zenoh_reason(exc)}"
        raise ConfigError("[zenoh]", "", reason) from None


_SOURCE = re.compile(r"\s+at \S+\.rs:\d+\.?")


def zenoh_reason(exc: BaseException) -> str:
    """Zenoh's message without the Rust source locations it appends."""
    return _SOURCE.sub("", str(exc)).strip()


_HINTS = (
    ("already in use", "another drive-gateway instance (or another Zenoh peer) holds it: stop it"),
    ("permission denied", "ports below 1024 need CAP_NET_BIND_SERVICE: use a port above 1023"),
    ("cannot assign requested address", "this machine has no such address"),
)


def open_session(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open(config)``; raises :class:`StartupError` if Zenoh cannot open it."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        cause = zenoh_reason(exc)
        hint = next((h for k, h in _HINTS if k in cause.lower()), "fix the endpoint")
        fix = f"{hint}, or choose another endpoint: --zenoh-endpoint or [zenoh] listen"
        fix += " (or the endpoints in zenoh.config_file when one is used)"
        raise StartupError("zenoh", f"cannot open the session: {cause}", fix) from None
