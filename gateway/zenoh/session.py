"""The Zenoh session configuration: always explicit, never a bare ``zenoh.Config()``.

A bare ``zenoh.Config()`` listens on every interface and joins multicast
scouting. The gateway instead sets the mode, the listen and connect endpoints
and the scouting switches from the ``[zenoh]`` section every time, so no Zenoh
traffic leaves the endpoints the config names. Gossip scouting follows
``multicast_scouting``: off, the session meets only the peers it connects to or
that connect to it. A ``zenoh.config_file`` (JSON5) replaces all of this and
is given to Zenoh as it is (routers, TLS/mTLS, access control), with one
exception: shared memory stays off unless that file sets
``transport.shared_memory`` itself. Zenoh enables it by default, and then any
same-host client that puts more than about 3 KB makes the gateway map 16 MB
segments that it never gives back (issue 18).
"""

from __future__ import annotations

import json
from typing import Any

import zenoh

from gateway.config import ZenohSection
from gateway.errors import ConfigError


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


def _sets_shared_memory(path: Any) -> bool:
    """Whether a Zenoh config file names ``shared_memory`` (then it decides)."""
    try:
        with open(path, "rb") as f:
            return b"shared_memory" in f.read(MAX_CONFIG_FILE_BYTES + 1)
    except OSError:
        return False


MAX_CONFIG_FILE_BYTES = 1 << 20


def zenoh_config(section: ZenohSection) -> zenoh.Config:
    """The session config for ``section``; raises ConfigError if Zenoh refuses it."""
    if section.config_file is not None:
        try:
            config = zenoh.Config.from_file(str(section.config_file))
        except zenoh.ZError as exc:
            raise ConfigError(str(section.config_file), "", f"not a Zenoh config: {exc}") from None
        if not _sets_shared_memory(section.config_file):
            config.insert_json5(SHARED_MEMORY_KEY, "false")
        return config
    try:
        return zenoh.Config.from_json5(json.dumps(config_document(section)))
    except zenoh.ZError as exc:
        raise ConfigError("[zenoh]", "", f"Zenoh refuses the session config: {exc}") from None
