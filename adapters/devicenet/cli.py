"""``drive-gateway sim devicenet``: simulated CFW-08 nodes on a CAN bus, standalone.

Example: ``drive-gateway sim devicenet --interface socketcan --channel vcan0 --nodes 1-3,10``.
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
from typing import Any

from adapters.devicenet.cfw08 import DEFAULT_WEG_SPEED_SCALE, AssemblyPair
from adapters.devicenet.link import REFUSED_INTERFACES, LinkConfig
from adapters.devicenet.sim import SimNodeConfig, SimRunner

log = logging.getLogger(__name__)


def parse_nodes(text: str) -> list[int]:
    """``"1,2,5-8"`` -> [1, 2, 5, 6, 7, 8]; MAC IDs 0-63, each once."""
    macs: list[int] = []
    for raw in text.split(","):
        part = raw.strip()
        low, sep, high = part.partition("-")
        try:
            first = int(low)
            last = int(high) if sep else first
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part!r} is not a MAC ID or a range") from None
        if not 0 <= first <= last <= 63:
            raise argparse.ArgumentTypeError(f"{part!r}: MAC IDs are 0-63")
        macs.extend(range(first, last + 1))
    if len(set(macs)) != len(macs):
        raise argparse.ArgumentTypeError(f"{text!r} names a MAC ID twice")
    return macs


def _interface(text: str) -> str:
    reason = REFUSED_INTERFACES.get(text)
    if reason is not None:
        raise argparse.ArgumentTypeError(reason)
    return text


def add_sim(sub: Any) -> None:
    p = sub.add_parser(
        "devicenet",
        help="simulated WEG CFW-08 drives on a CAN bus (Group 2 Only servers)",
        description=__doc__,
    )
    p.add_argument("--interface", type=_interface, default="socketcan", help="python-can interface")
    p.add_argument("--channel", default="vcan0", help="CAN channel (default vcan0)")
    p.add_argument("--nodes", type=parse_nodes, required=True, help="MAC IDs, e.g. 1,2,5-8")
    p.add_argument(
        "--assembly",
        type=int,
        choices=[int(a) for a in AssemblyPair],
        default=21,
        help="I/O pair the drives' P710 selects: 20 (20/70), 21 (21/71), 100 (100/150)",
    )
    p.add_argument("--p313", type=int, choices=range(4), default=2, help="action on comm error")
    p.add_argument("--max-rpm", type=float, default=1800.0, help="maximum speed, rpm")
    p.add_argument("--ramp-time", type=float, default=2.0, help="P100/P101 ramps, seconds")
    p.add_argument(
        "--weg-speed-scale",
        type=int,
        default=DEFAULT_WEG_SPEED_SCALE,
        help="100/150 counts at max rpm (default 8192)",
    )
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    p.set_defaults(handler=cmd_sim)


def node_configs(args: argparse.Namespace) -> list[SimNodeConfig]:
    p710 = AssemblyPair(args.assembly).p710
    return [
        SimNodeConfig(
            mac=mac,
            p710=p710,
            p313=args.p313,
            max_rpm=args.max_rpm,
            ramp_time=args.ramp_time,
            weg_speed_scale=args.weg_speed_scale,
        )
        for mac in args.nodes
    ]


async def run_sim(args: argparse.Namespace) -> int:
    runner = SimRunner(LinkConfig(args.interface, args.channel), node_configs(args))
    task = asyncio.current_task()
    loop = asyncio.get_running_loop()
    signals = (signal.SIGINT, signal.SIGTERM)
    if task is not None:
        for sig in signals:
            loop.add_signal_handler(sig, task.cancel)
    try:
        log.info(
            "simulating CFW-08 MAC %s on %s %s",
            ",".join(map(str, args.nodes)),
            args.interface,
            args.channel,
        )
        with contextlib.suppress(asyncio.CancelledError, TimeoutError):
            async with asyncio.timeout(args.duration):
                await runner.run()
    finally:
        for sig in signals:
            loop.remove_signal_handler(sig)
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr)
    from gateway.errors import AdapterError

    try:
        return asyncio.run(run_sim(args))
    except AdapterError as exc:
        log.error("%s", exc)
        return 2
