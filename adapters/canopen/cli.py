"""CANopen command-line tools (the only printing in this package).

``drive-gateway sim canopen``: simulated CiA 402 drives on a CAN bus, standalone.

Example: ``drive-gateway sim canopen --interface socketcan --channel vcan0 --node 5 --node 6``.
``virtual`` works in-process only, so a standalone simulator is useful on SocketCAN
(``vcan0`` or a real ``can0``); ``udp_multicast`` is refused.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from pathlib import Path
from typing import Any

from adapters.canopen.sim import BootState, SimNodeConfig, SimRunner
from adapters.canopen.sim.node import DEFAULT_EDS, EdsUnreadable, load_od
from adapters.link.can import REFUSED_INTERFACES
from gateway.errors import AdapterError

log = logging.getLogger(__name__)


def _interface(text: str) -> str:
    reason = REFUSED_INTERFACES.get(text)
    if reason is not None:
        raise argparse.ArgumentTypeError(reason)
    return text


def _node_id(text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a node id") from None
    if not 1 <= value <= 127:
        raise argparse.ArgumentTypeError(f"{text!r}: CANopen node ids are 1-127")
    return value


def _eds(text: str) -> Path:
    path = Path(text)
    try:
        load_od(path)
    except EdsUnreadable as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return path


def add_sim(sub: Any) -> None:
    p = sub.add_parser(
        "canopen",
        help="simulated CiA 402 drives on a CAN bus (canopen LocalNode)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--interface", type=_interface, default="socketcan", help="python-can interface")
    p.add_argument("--channel", default="vcan0", help="CAN channel (default vcan0)")
    p.add_argument(
        "--node",
        dest="nodes",
        type=_node_id,
        action="append",
        required=True,
        help="a node id 1-127 (repeat for more nodes)",
    )
    p.add_argument("--eds", type=_eds, default=DEFAULT_EDS, help="the nodes' EDS")
    p.add_argument("--max-rpm", type=float, default=1800.0, help="maximum speed, rpm")
    p.add_argument("--ramp-time", type=float, default=2.0, help="0 -> max rpm ramp, seconds")
    p.add_argument(
        "--heartbeat-ms", type=int, default=None, help="0x1017 at boot (default: the EDS's)"
    )
    p.add_argument(
        "--abort-option",
        type=int,
        choices=range(4),
        default=None,
        help="0x6007 at boot: 0 none, 1 fault, 2 disable voltage, 3 quick stop",
    )
    p.add_argument(
        "--operational",
        action="store_true",
        help="boot straight to NMT operational (a self-starting node)",
    )
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument(
        "--log-level",
        default="INFO",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level (default: %(default)s)",
    )
    p.set_defaults(handler=cmd_sim)


def node_configs(args: argparse.Namespace) -> list[SimNodeConfig]:
    if len(set(args.nodes)) != len(args.nodes):
        raise ValueError(f"a node id is given twice: {args.nodes}")
    boot = BootState.OPERATIONAL if args.operational else BootState.PRE_OPERATIONAL
    return [
        SimNodeConfig(
            node_id=node_id,
            eds=args.eds,
            max_rpm=args.max_rpm,
            ramp_time=args.ramp_time,
            boot_state=boot,
            heartbeat_ms=args.heartbeat_ms,
            abort_connection_option=args.abort_option,
        )
        for node_id in args.nodes
    ]


async def run_sim(args: argparse.Namespace) -> int:
    runner = SimRunner(args.interface, args.channel, node_configs(args))
    loop = asyncio.get_running_loop()
    signals = (signal.SIGINT, signal.SIGTERM)
    for sig in signals:
        loop.add_signal_handler(sig, runner.stop)
    try:
        log.info(
            "simulating CiA 402 node(s) %s on %s %s",
            ",".join(map(str, args.nodes)),
            args.interface,
            args.channel,
        )
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(args.duration):
                await runner.run()
    finally:
        for sig in signals:
            loop.remove_signal_handler(sig)
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr)
    if args.log_level != "DEBUG":  # the library narrates every PDO map at INFO
        logging.getLogger("canopen").setLevel(logging.WARNING)
    try:
        return asyncio.run(run_sim(args))
    except AdapterError as exc:
        log.error("%s", exc)
        return 2
    except ValueError as exc:
        log.error("%s", exc)
        return 2
