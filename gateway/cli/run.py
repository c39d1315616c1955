"""``drive-gateway run``: the daemon, with the command line's overrides of its config."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from typing import Any, NoReturn

from gateway.cli.check import load_or_report, print_config_errors
from gateway.config import DEFAULT_CONFIG
from gateway.errors import ConfigError

LIBRARY_LOGGERS = ("canopen", "can", "asyncua")
"""The libraries whose own loggers are held at ``gateway.library_log_level`` (WARNING by
default): the canopen library logs every PDO map, SDO and NMT change at INFO (98 % of a
demo's log), python-can its interface set-up, asyncua every node of the standard address
space it could not place (about 1,100 lines at each start of the OPC UA server); the
gateway says what matters itself."""


def setup_logging(level: str, library_level: str = "WARNING") -> None:
    under_journal = "JOURNAL_STREAM" in os.environ
    fmt = "%(levelname)s %(name)s: %(message)s"
    if not under_journal:
        fmt = "%(asctime)s " + fmt
    logging.basicConfig(level=getattr(logging, level), format=fmt, stream=sys.stderr, force=True)
    set_library_level(library_level)


def set_library_level(level: str) -> None:
    """The libraries' loggers (:data:`LIBRARY_LOGGERS`) at ``level``."""
    for name in LIBRARY_LOGGERS:
        logging.getLogger(name).setLevel(getattr(logging, level))


SIMULATED_DEMO_BANNER = (
    "no --config given: running the SIMULATED demo ({path}); no real drive is driven. "
    "Give --config /etc/drive-gateway/site.toml (or your file) for a real line."
)


def add_run(sub: Any) -> None:
    p = sub.add_parser("run", help="run the gateway")
    p.add_argument(
        "--config",
        help="config file (default: the simulated demo, config/demo.toml, said loudly at start)",
    )
    p.add_argument("--zenoh-endpoint", help="Zenoh endpoint to listen on (overrides config)")
    p.add_argument("--modbus-bind", help="HOST:PORT of the Modbus server (overrides config)")
    p.add_argument("--web-bind", help="HOST:PORT of the status page (overrides config)")
    p.add_argument(
        "--log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level (default: the config's gateway.log_level)",
    )
    p.add_argument(
        "--library-log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level of the libraries' own loggers: canopen, python-can (default: the "
        "config's gateway.library_log_level, WARNING)",
    )
    p.set_defaults(handler=cmd_run)


def cmd_run(args: argparse.Namespace) -> int:
    demo = args.config is None
    if demo:
        banner = SIMULATED_DEMO_BANNER.format(path=DEFAULT_CONFIG)
        print(f"*** {banner} ***", file=sys.stderr, flush=True)
    config = load_or_report(DEFAULT_CONFIG if demo else args.config)
    if config is None:
        return 2
    try:
        config = config.with_overrides(args.zenoh_endpoint, args.modbus_bind, args.web_bind)
    except ConfigError as exc:
        print_config_errors(exc)
        return 2
    setup_logging(
        args.log_level or config.gateway.log_level,
        args.library_log_level or config.gateway.library_log_level,
    )
    if demo:
        logging.getLogger("gateway.cli").warning(SIMULATED_DEMO_BANNER.format(path=DEFAULT_CONFIG))
    if args.zenoh_endpoint and config.zenoh.config_file is not None:
        logging.getLogger("gateway.cli").warning(
            "--zenoh-endpoint %s is ignored: zenoh.config_file %s sets the endpoints",
            args.zenoh_endpoint,
            config.zenoh.config_file,
        )
    from gateway.runtime.daemon import run

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
