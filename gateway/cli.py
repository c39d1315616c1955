"""``drive-gateway``: the command line (the only place that prints).

Subcommands come from :data:`COMMANDS` (name -> "module:function" that adds
the subparser), so tools of later parts (scan, simulators, watch) plug in
without the core importing them at start-up.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from gateway import __version__
from gateway.adapter import safety_warnings
from gateway.config import DEFAULT_CONFIG, Config, load
from gateway.errors import ConfigError, ConfigErrors
from gateway.loader import load_optional

Handler = Callable[[argparse.Namespace], int]

COMMANDS: dict[str, str] = {
    "run": "gateway.cli:add_run",
    "check-config": "gateway.cli:add_check_config",
    "watch": "gateway.cli_tools:add_watch",
    "cmd": "gateway.cli_tools:add_cmd",
    "param": "gateway.cli_tools:add_param",
    "params": "gateway.cli_params:add_params",
    "health": "gateway.cli_tools:add_health",
    "profibus": "adapters.profibus.cli:add_profibus",
    "devicenet": "adapters.devicenet.cli:add_devicenet",
    "sim": "gateway.simcli:add_sim",
    "completion": "gateway.cli_docs:add_completion",
    "manpage": "gateway.cli_docs:add_manpage",
}
"""Subcommand -> "module:function(subparsers)"; a module not in this build is skipped."""


def setup_logging(level: str) -> None:
    under_journal = "JOURNAL_STREAM" in os.environ
    fmt = "%(levelname)s %(name)s: %(message)s"
    if not under_journal:
        fmt = "%(asctime)s " + fmt
    logging.basicConfig(level=getattr(logging, level), format=fmt, stream=sys.stderr, force=True)


def _print_config_errors(exc: ConfigErrors | ConfigError) -> None:
    errors = exc.errors if isinstance(exc, ConfigErrors) else [exc]
    for err in errors:
        print(f"error: {err}", file=sys.stderr)


def front_end_problems(config: Config) -> list[ConfigError]:
    """What a front end would refuse at start that can be known without opening
    anything: the Zenoh session config (the file's or the one made from [zenoh]) as
    Zenoh itself reads it. ``check-config`` and ``run`` both ask it."""
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


def _load_or_report(path: str | Path) -> Config | None:
    """The config, or None once every error is printed; ``check-config`` and ``run``
    refuse exactly the same files, each with a message and never a traceback."""
    try:
        config = load(path)
    except (ConfigErrors, ConfigError) as exc:
        _print_config_errors(exc)
        return None
    except Exception as exc:  # a checker bug: still a message (and status 2), no traceback
        print(f"error: {path}: cannot be checked ({type(exc).__name__}: {exc})", file=sys.stderr)
        return None
    try:
        problems = front_end_problems(config)
    except Exception as exc:  # as above
        print(f"error: {path}: cannot be checked ({type(exc).__name__}: {exc})", file=sys.stderr)
        return None
    if problems:
        _print_config_errors(ConfigErrors(problems))
        return None
    return config


# ---------------------------------------------------------------- run


def add_run(sub: Any) -> None:
    p = sub.add_parser("run", help="run the gateway")
    p.add_argument("--config", default=str(DEFAULT_CONFIG), help="config file (default: demo)")
    p.add_argument("--zenoh-endpoint", help="Zenoh endpoint to listen on (overrides config)")
    p.add_argument("--modbus-bind", help="HOST:PORT of the Modbus server (overrides config)")
    p.add_argument("--web-bind", help="HOST:PORT of the status page (overrides config)")
    p.add_argument(
        "--log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level (default: the config's gateway.log_level)",
    )
    p.set_defaults(handler=cmd_run)


def cmd_run(args: argparse.Namespace) -> int:
    config = _load_or_report(args.config)
    if config is None:
        return 2
    try:
        config = config.with_overrides(args.zenoh_endpoint, args.modbus_bind, args.web_bind)
    except ConfigError as exc:
        _print_config_errors(exc)
        return 2
    setup_logging(args.log_level or config.gateway.log_level)
    if args.zenoh_endpoint and config.zenoh.config_file is not None:
        logging.getLogger("gateway.cli").warning(
            "--zenoh-endpoint %s is ignored: zenoh.config_file %s sets the endpoints",
            args.zenoh_endpoint,
            config.zenoh.config_file,
        )
    from gateway.daemon import run

    _leave_process(run(config))


def _leave_process(status: int) -> NoReturn:
    """End the daemon's process once it has shut down cleanly.

    The Zenoh runtime keeps native threads after its sessions are closed; if the
    interpreter then finalises while one of them calls back into Python, the process
    aborts ("FATAL: exception not rethrown", SIGABRT) although the gateway stopped
    cleanly. Everything the daemon owns is closed by now: flush and leave directly.
    """
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


# ---------------------------------------------------------------- check-config


def add_check_config(sub: Any) -> None:
    p = sub.add_parser(
        "check-config",
        help="validate a config file, list its drives and what is left to fill in",
        description="Check a config file as `run` would and list its drives; then list what "
        "is left to fill in: a CHANGE-ME, no drive, a line without drives, a serial port or "
        "CAN interface this machine does not have.",
        epilog="exit status: 0 ok; 1 valid, but something is left to fill in; 2 errors (each "
        "with the file, the key and the reason).",
    )
    p.add_argument("file", help="the config file (TOML)")
    p.add_argument(
        "--errors-only",
        action="store_true",
        help="report only what keeps the gateway from starting; exit 0 when it would start "
        "(the unit's ExecReload)",
    )
    p.set_defaults(handler=cmd_check_config)


PLACEHOLDER = "CHANGE-ME"
"""What config/site.example.toml marks as left to fill in."""


def left_to_fill(config: Config, text: str) -> list[str]:
    """What a valid config still lacks before it runs a real line (the site template's
    CHANGE-ME marks, no drives, a port or CAN interface this machine does not have)."""
    todo = []
    table = ""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith("["):
            table = stripped.strip("[]").strip()
        elif PLACEHOLDER in line and not stripped.startswith("#"):
            key = stripped.split("=", 1)[0].strip()
            todo.append(f"line {number}: {table}.{key}: replace {PLACEHOLDER}")
    if not config.drives:
        todo.append(
            "no drive is configured: uncomment the examples under [buses.<name>] "
            "(or add [[buses.<name>.drives]] tables)"
        )
    for bus in config.buses:
        if config.drives and not bus.drives:
            todo.append(f"buses.{bus.name}: no drive on this line (remove it or add drives)")
        todo += _missing_on_this_machine(bus)
    return todo


def _missing_on_this_machine(bus: Any) -> list[str]:
    options = bus.options
    if getattr(options, "simulate", False):
        return []
    port = getattr(options, "port", None)
    if isinstance(port, str) and port.startswith("/") and not Path(port).exists():
        return [
            f"buses.{bus.name}.port: {port} does not exist on this machine "
            "(ls -l /dev/serial/by-id/)"
        ]
    channel = getattr(options, "channel", None)
    if (
        getattr(options, "interface", None) == "socketcan"
        and isinstance(channel, str)
        and not Path("/sys/class/net", channel).exists()
    ):
        return [
            f"buses.{bus.name}.channel: no CAN interface {channel} on this machine "
            f"(ip link show {channel}; docs/operations.md)"
        ]
    return []


def cmd_check_config(args: argparse.Namespace) -> int:
    config = _load_or_report(args.file)
    if config is None:
        return 2
    if args.errors_only:
        print(f"{args.file}: ok, the gateway would start")
        return 0
    todo = left_to_fill(config, Path(args.file).read_text(encoding="utf-8", errors="replace"))
    status = "ok" if not todo else "valid, but not ready"
    print(f"{args.file}: {status}, {len(config.drives)} drive(s) on {len(config.buses)} bus(es)")
    for bus in config.buses:
        print(f"bus {bus.name} ({bus.adapter})")
        for d in bus.drives:
            unit = "-" if d.modbus_unit is None else str(d.modbus_unit)
            print(
                f"  {d.id:<16} {d.device.value:<8} address {d.address:<4} "
                f"modbus unit {unit:<4} control {d.control.value}"
            )
    warnings = [w for bus in config.buses for d in bus.drives for w in safety_warnings(bus, d)]
    if warnings:
        print(f"safety warnings ({len(warnings)}; docs/safety.md):")
        for warning in warnings:
            print(f"  {warning}")
    if todo:
        print(f"left to fill in ({len(todo)}):")
        for item in todo:
            print(f"  {item}")
        return 1
    return 0


# ---------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="drive-gateway",
        description="Profibus DP and DeviceNet drives on Zenoh and Modbus TCP.",
    )
    parser.add_argument("--version", action="version", version=f"drive-gateway {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for target in COMMANDS.values():
        add = load_optional(target)
        if add is not None:
            add(sub)
    from gateway.cli_docs import apply_formatter

    apply_formatter(parser)  # every argument's help shows its default
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return handler(args)
    except KeyboardInterrupt:
        return 130
