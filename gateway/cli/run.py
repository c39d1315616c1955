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


def setup_logging(level: str) -> None:
    under_journal = "JOURNAL_STREAM" in os.environ
    fmt = "%(levelname)s %(name)s: %(message)s"
    if not under_journal:
        fmt = "%(asctime)s " + fmt
    logging.basicConfig(level=getattr(logging, level), format=fmt, stream=sys.stderr, force=True)


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
    config = load_or_report(args.config)
    if config is None:
        return 2
    try:
        config = config.with_overrides(args.zenoh_endpoint, args.modbus_bind, args.web_bind)
    except ConfigError as exc:
        print_config_errors(exc)
        return 2
    setup_logging(args.log_level or config.gateway.log_level)
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
