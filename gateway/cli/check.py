"""``drive-gateway check-config``: a config file checked as ``run`` would, its drives, its
safety warnings and what is left to fill in; and the loading both commands share."""

from __future__ import annotations

import argparse
import ipaddress
import sys
from pathlib import Path
from typing import Any

from gateway.config import Config, load, safety_warnings
from gateway.errors import ConfigError, ConfigErrors
from gateway.runtime.preflight import front_end_problems


def print_config_errors(exc: ConfigErrors | ConfigError) -> None:
    errors = exc.errors if isinstance(exc, ConfigErrors) else [exc]
    for err in errors:
        print(f"error: {err}", file=sys.stderr)


def load_or_report(path: str | Path) -> Config | None:
    """The config, or None once every error is printed; ``check-config`` and ``run``
    refuse exactly the same files, each with a message and never a traceback."""
    try:
        config = load(path)
    except (ConfigErrors, ConfigError) as exc:
        print_config_errors(exc)
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
        print_config_errors(ConfigErrors(problems))
        return None
    return config


def add_check_config(sub: Any) -> None:
    p = sub.add_parser(
        "check-config",
        help="validate a config file, list its drives and what is left to fill in",
        description="Check a config file as `run` would and list its drives; then list what "
        "is left to fill in: a value still CHANGE-ME, a modbus.allow network of the "
        "documentation ranges (the template's example), no drive, a line without drives, a "
        "serial port or CAN interface this machine does not have.",
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
"""What config/site.example.toml marks as left to fill in (in a value: a comment that says
CHANGE-ME is text, not a value still to change)."""

EXAMPLE_NETWORKS = tuple(
    ipaddress.ip_network(n)
    for n in ("192.0.2.0/24", "198.51.100.0/24", "203.0.113.0/24", "2001:db8::/32")
)
"""The documentation networks (RFC 5737, RFC 3849): the template's example ``allow``; no
plant's PLCs are in them."""


def code_part(line: str) -> str:
    """``line`` without its TOML comment (a ``#`` outside a string)."""
    quote = ""
    escaped = False
    for i, char in enumerate(line):
        if quote:
            if escaped:
                escaped = False
            elif char == "\\" and quote == '"':
                escaped = True
            elif char == quote:
                quote = ""
        elif char in "\"'":
            quote = char
        elif char == "#":
            return line[:i]
    return line


def _placeholders(text: str) -> list[str]:
    """Each value that still says CHANGE-ME, by line and key (a continued array: the key
    it continues)."""
    todo = []
    table = key = ""
    for number, line in enumerate(text.splitlines(), start=1):
        code = code_part(line).strip()
        if code.startswith("["):
            table, key = code.strip("[]").strip(), ""
            continue
        name, equals, _ = code.partition("=")
        if equals and not name.strip().startswith(('"', "'")):
            key = name.strip()
        if PLACEHOLDER in code:
            todo.append(f"line {number}: {table}.{key}: replace {PLACEHOLDER}")
    return todo


def _example_networks(config: Config) -> list[str]:
    return [
        f"modbus.allow: {net} is a documentation network (the template's example): "
        "give the PLC/HMI networks"
        for net in config.modbus.allow
        if any(net.version == doc.version and net.subnet_of(doc) for doc in EXAMPLE_NETWORKS)  # type: ignore[arg-type]
    ]


def left_to_fill(config: Config, text: str) -> list[str]:
    """What a valid config still lacks before it runs a real line (the site template's
    CHANGE-ME values and example networks, no drives, a port or CAN interface this
    machine does not have)."""
    todo = _placeholders(text) + _example_networks(config)
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
    config = load_or_report(args.file)
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
