"""What an adapter says when it is built without what its line needs (safety rule 6: a
config error naming the bus, never a silent simulation)."""

from __future__ import annotations

from gateway.errors import ConfigError

WHERE = "configuration"


def missing_options(bus: str) -> ConfigError:
    """The bus was built without its options table (never read from a config file)."""
    return ConfigError(
        WHERE,
        f"buses.{bus}",
        "the bus has no options table: an adapter is built from a parsed configuration "
        "(gateway.config), and a line is simulated only where it says simulate = true",
    )


def unsimulated(bus: str) -> ConfigError:
    """``simulate = true`` but nobody gave the adapter the simulated line."""
    return ConfigError(
        WHERE,
        f"buses.{bus}.simulate",
        "simulate = true, but the adapter was given no simulated line: the composition "
        "root (gateway.runtime.daemon) makes it from the bus's simulator package",
    )
