"""The command line's parser: its subcommands and its help formatting.

Subcommands come from :data:`COMMANDS` (name -> "module:function" that adds the
subparser), so tools of later parts (scan, simulators, watch) plug in without the core
importing them at start-up.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from gateway import __version__
from gateway.loader import load_optional

PROG = "drive-gateway"

COMMANDS: dict[str, str] = {
    "run": "gateway.cli.run:add_run",
    "check-config": "gateway.cli.check:add_check_config",
    "watch": "gateway.cli.tools:add_watch",
    "cmd": "gateway.cli.tools:add_cmd",
    "param": "gateway.cli.tools:add_param",
    "params": "gateway.cli.params:add_params",
    "health": "gateway.cli.tools:add_health",
    "history": "gateway.cli.history:add_history",
    "profibus": "adapters.profibus.cli:add_profibus",
    "devicenet": "adapters.devicenet.cli:add_devicenet",
    "sim": "gateway.cli.sim:add_sim",
    "users": "gateway.cli.users:add_users",
    "completion": "gateway.cli.docs:add_completion",
    "manpage": "gateway.cli.docs:add_manpage",
}
"""Subcommand -> "module:function(subparsers)"; a module not in this build is skipped."""


class DefaultsFormatter(argparse.HelpFormatter):
    """Adds ``(default: X)`` to an argument's help when it has a default the help does not
    already name (the tools write theirs in the text where it needs words)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if (
            "default" in text
            or default in (None, False, argparse.SUPPRESS)
            or default == []
            or isinstance(action, argparse._SubParsersAction)
            or (not action.option_strings and action.nargs not in ("?", "*"))
        ):
            return text
        shown = default if not isinstance(default, list | tuple) else ",".join(map(str, default))
        return f"{text} (default: {shown})".lstrip()


class RawDefaultsFormatter(DefaultsFormatter, argparse.RawDescriptionHelpFormatter):
    """The same, keeping the line breaks of the description and the epilog."""


def walk(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = (PROG,)
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every parser under ``parser`` with its command path, ``parser`` first."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from walk(sub, (*path, name))


def apply_formatter(parser: argparse.ArgumentParser) -> None:
    for _path, p in walk(parser):
        kind = p.formatter_class
        raw = isinstance(kind, type) and issubclass(kind, argparse.RawDescriptionHelpFormatter)
        p.formatter_class = RawDefaultsFormatter if raw else DefaultsFormatter


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Profibus DP, DeviceNet and CANopen drives on Zenoh and Modbus TCP.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for target in COMMANDS.values():
        add = load_optional(target)
        if add is not None:
            add(sub)
    apply_formatter(parser)  # every argument's help shows its default
    return parser
