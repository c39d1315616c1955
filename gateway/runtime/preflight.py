"""What the gateway would refuse at start that can be known without opening anything.

``check-config``, ``run`` and the daemon's SIGHUP check all ask it, so the three refuse
exactly the same files.
"""

from __future__ import annotations

from gateway.config import Config
from gateway.errors import ConfigError


def front_end_problems(config: Config) -> list[ConfigError]:
    """What a front end would refuse at start that can be known without opening
    anything: the Zenoh session config (the file's or the one made from [zenoh]) as
    Zenoh itself reads it."""
    if not config.zenoh.enabled:
        return []
    try:
        from gateway.zenoh.session import zenoh_config
    except ModuleNotFoundError:  # the Zenoh front end is not part of this build
        return []
    try:
        zenoh_config(config.zenoh)
    except ConfigError as exc:
        return [exc]
    return []
