"""The file descriptors the configured limits may need, against the process's limit.

Every connection a front end admits holds a file descriptor, and so do the bus ports, the
Zenoh session's sockets, the log and the event loop itself. A process at its descriptor
limit (``RLIMIT_NOFILE``; under systemd the soft limit is 1024 unless the unit sets
``LimitNOFILE=``) can accept no connection on any front end until one closes. At start,
:func:`descriptor_problems` adds up what the config admits (:func:`descriptor_need`),
raises the soft limit when it is short (up to the hard limit: no privilege needed), and
says what is short when even the hard limit is.
"""

from __future__ import annotations

import logging
import resource
from dataclasses import dataclass

from gateway.config import Config

log = logging.getLogger(__name__)

WEB_CONNECTIONS_WITHOUT_A_LIMIT = 128
"""``web.max_connections`` counted for a web front end whose config names no such limit."""
LISTENING_SOCKETS = 2  # per TCP front end: one IPv4 and one IPv6 socket at most
DESCRIPTORS_PER_BUS = 8  # a port or CAN socket, its lock, a line's own event loop, a simulator
FIXED_MARGIN = 256  # Zenoh's sockets, the log, the event loop's, stdio, the systemd sockets
SOFT_LIMIT_WANTED = 65536
"""The soft limit asked for when it is short (capped by the hard limit): the unit's
``LimitNOFILE=``, so a gateway started by hand has the room the service has."""


@dataclass(frozen=True, slots=True)
class DescriptorNeed:
    """What the configured limits may hold open at once, by part."""

    modbus: int  # modbus.max_connections and its listening sockets (0: Modbus off)
    web: int  # web.max_connections and its listening sockets (0: web off)
    buses: int
    margin: int = FIXED_MARGIN

    @property
    def total(self) -> int:
        return self.modbus + self.web + self.buses + self.margin

    def describe(self) -> str:
        """The sum, as the problem text names it."""
        return (
            f"Modbus {self.modbus}, web {self.web}, buses {self.buses},"
            f" Zenoh, the log and the event loop {self.margin}"
        )


def web_connections(config: Config) -> int:
    """``web.max_connections``, or :data:`WEB_CONNECTIONS_WITHOUT_A_LIMIT` where the web
    config has no such limit."""
    limits = getattr(config.web, "limits", None)
    value = getattr(limits, "max_connections", WEB_CONNECTIONS_WITHOUT_A_LIMIT)
    return int(value)


def descriptor_need(config: Config) -> DescriptorNeed:
    """The descriptors ``config`` may need at once, its front ends' limits reached."""
    modbus = config.modbus.max_connections + LISTENING_SOCKETS if config.modbus.enabled else 0
    web = web_connections(config) + LISTENING_SOCKETS if config.web.enabled else 0
    return DescriptorNeed(modbus=modbus, web=web, buses=DESCRIPTORS_PER_BUS * len(config.buses))


def _shortfall(need: DescriptorNeed, hard: int) -> str:
    return (
        f"the file descriptor limit ({hard}, the hard limit) is below the {need.total}"
        f" descriptors the configured limits may need ({need.describe()}): once they are"
        " used up no front end accepts a connection; raise LimitNOFILE= in the unit"
        " (systemctl edit drive-gateway) or lower modbus.max_connections or"
        " web.max_connections"
    )


def descriptor_problems(config: Config) -> list[str]:
    """Check the process's descriptor limit against ``config``'s limits: the soft limit
    is raised when short (to :data:`SOFT_LIMIT_WANTED`, at most the hard limit, logged);
    the problems left, one sentence each (none: the limit covers the config)."""
    need = descriptor_need(config)
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= need.total:
        return []
    wanted = max(need.total, SOFT_LIMIT_WANTED)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    except (OSError, ValueError) as exc:
        return [
            f"the file descriptor limit ({soft}) is below the {need.total} descriptors the"
            f" configured limits may need ({need.describe()}), and raising it failed: {exc};"
            " set LimitNOFILE= in the unit (systemctl edit drive-gateway)"
        ]
    log.info(
        "file descriptor limit raised from %d to %d: the configured limits may need %d",
        soft,
        target,
        need.total,
    )
    if target < need.total:
        return [_shortfall(need, hard)]
    return []
