"""What the web front end counts itself: requests refused by reason, logins, commands
(exported by :mod:`gateway.web.metrics`, counted by the front end, its admission and its
authentication)."""

from __future__ import annotations


class WebCounters:
    """What the web front end counts itself (besides the feed's counters)."""

    def __init__(self) -> None:
        self.refused: dict[str, int] = dict.fromkeys(
            (
                "host",
                "origin",
                "token",
                "token_limit",
                "commands_off",
                "pages",
                "pages_per_peer",
                "login",
                "login_limit",
                "login_busy",
                "role",
                "csrf",
                "login_required",
            ),
            0,
        )
        """Requests refused, by reason."""
        self.logins: dict[str, int] = {"success": 0, "failure": 0, "limited": 0}
        """Web logins by result (limited: refused unchecked, too many failures)."""
        self.commands: dict[str, int] = {"accepted": 0, "refused": 0}
        self.connections: dict[str, int] = dict.fromkeys(
            ("accepted", "refused", "over_limit", "over_peer_limit"), 0
        )
        """Connections by what became of them at accept (refused: not in web.allow)."""
        self.connections_open = 0
        self.timeouts: dict[str, int] = {"header": 0, "body": 0, "answer": 0}
        self.clients_open = 0  # pages
        self.clients_over_budget = 0
        self.metrics_renders = 0
        self.throttled = 0  # requests held back: their address was over web.request_rate
