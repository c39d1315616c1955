"""DeviceNet command-line tools (the only printing in this package).

``drive-gateway devicenet scan --interface socketcan --channel can0``: every MAC ID
0-63 that answers, with its Identity object (adapters.devicenet.scanner.probe). It
refuses to run beside a running scanner (its own Duplicate MAC ID check is answered).

``drive-gateway sim devicenet``: simulated CFW-08 nodes on a CAN bus, standalone.

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
from collections.abc import Callable
from typing import Any

from adapters.devicenet.cfw08 import DEFAULT_WEG_SPEED_SCALE, AssemblyPair
from adapters.devicenet.codec.eds import ConnectionType, Eds
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.errors import EdsError
from adapters.devicenet.link import REFUSED_INTERFACES, CanLink, LinkConfig, RxFrame
from adapters.devicenet.options import SCANNER_VENDOR_ID, load_eds
from adapters.devicenet.scanner.probe import (
    Finished,
    LineProbe,
    NodeInfo,
    ProbeConfig,
    Progress,
    Refused,
)
from adapters.devicenet.sim import SimNodeConfig, SimRunner
from adapters.devicenet.sim.objects import identity_from_eds as sim_identity
from gateway.errors import GatewayError

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
    p.add_argument(
        "--eds",
        type=_eds,
        default=None,
        help="an EDS file: the drives' identity and I/O sizes come from it",
    )
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument(
        "--log-level",
        default="INFO",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level (default: %(default)s)",
    )
    p.set_defaults(handler=cmd_sim)


def _eds(text: str) -> Eds:
    try:
        return load_eds(text)
    except EdsError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def node_configs(args: argparse.Namespace) -> list[SimNodeConfig]:
    p710 = AssemblyPair(args.assembly).p710
    eds: Eds | None = getattr(args, "eds", None)
    identity = None if eds is None else sim_identity(eds)
    sizes = None
    if eds is not None:
        conn = eds.io.connections.get(ConnectionType.POLL)
        inp = eds.io.inputs.get(conn.default_input) if conn is not None else None
        out = eds.io.outputs.get(conn.default_output) if conn is not None else None
        if inp is not None and out is not None:
            sizes = (inp.size, out.size)
    return [
        SimNodeConfig(
            identity=identity,
            io_sizes=sizes,
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


# ---------------------------------------------------------------------------------------
# devicenet scan


def add_devicenet(sub: Any) -> None:
    p = sub.add_parser("devicenet", help="DeviceNet line tools")
    tools = p.add_subparsers(dest="tool", metavar="TOOL", required=True)
    scan = tools.add_parser(
        "scan", help="list the MAC IDs answering on a line, with their identity"
    )
    scan.add_argument(
        "--interface", type=_interface, default="socketcan", help="python-can interface"
    )
    scan.add_argument("--channel", default="can0", help="CAN channel (default can0)")
    scan.add_argument(
        "--bitrate",
        type=int,
        default=125_000,
        choices=(125_000, 250_000, 500_000),
        help="the line's bit rate",
    )
    scan.add_argument(
        "--nodes", type=parse_nodes, default=list(range(64)), help="MAC IDs (default 0-63)"
    )
    scan.add_argument("--mac", type=int, default=0, help="the scan tool's own MAC ID (default 0)")
    scan.add_argument(
        "--vendor-id", type=int, default=SCANNER_VENDOR_ID, help="the scan tool's vendor id"
    )
    scan.add_argument("--timeout", type=float, default=0.2, help="s per answer (default 0.2)")
    scan.add_argument("--json", action="store_true", help="print JSON")
    scan.set_defaults(handler=cmd_scan)


class ScanRefused(GatewayError):
    """The scan tool's MAC ID is answered: a scanner runs on this line."""


async def scan_line(
    line: LinkConfig, config: ProbeConfig, progress: Callable[[Progress], None] | None = None
) -> tuple[NodeInfo, ...]:
    """Run a :class:`LineProbe` on a CAN channel; ScanRefused beside a running scanner."""
    engine = LineProbe(config)
    loop = asyncio.get_running_loop()
    async with CanLink(line) as link:
        events: list[object] = []
        while True:
            now = loop.time()
            actions = [*engine.step(now)]
            for event in events:
                if isinstance(event, RxFrame):
                    actions += engine.step(now, event.frame)
            frames = [a for a in actions if isinstance(a, CanFrame)]
            if frames:
                link.send(frames)
            for action in actions:
                if isinstance(action, Refused):
                    raise ScanRefused(action.text)
                if isinstance(action, Progress) and progress is not None:
                    progress(action)
                if isinstance(action, Finished):
                    return action.nodes
            deadline = engine.next_deadline()
            wait = 0.05 if deadline is None else max(deadline - loop.time(), 0.0)
            events = list(await link.receive(wait))


def describe(node: NodeInfo) -> dict[str, Any]:
    rev = node.revision
    return {
        "mac": node.mac,
        "vendor_id": node.vendor_id,
        "product_type": node.product_type,
        "product_code": node.product_code,
        "revision": None if rev is None else f"{rev[0]}.{rev[1]}",
        "serial_number": node.serial_number,
        "product_name": node.product_name,
        "problem": node.problem,
    }


def _line(node: NodeInfo) -> str:
    d = describe(node)
    vendor = "?" if node.vendor_id is None else f"0x{node.vendor_id:04X}"
    serial = "?" if node.serial_number is None else f"0x{node.serial_number:08X}"
    text = (
        f"  MAC {node.mac:>2}  vendor {vendor}  type {d['product_type']}  "
        f"product {d['product_code']}  rev {d['revision']}  serial {serial}  "
        f"{d['product_name']!r}"
    )
    return text + (f"  ({node.problem})" if node.problem else "")


def cmd_scan(args: argparse.Namespace) -> int:
    import json

    from adapters.devicenet.errors import DeviceNetDecodeError
    from gateway.errors import AdapterError

    def progress(p: Progress) -> None:
        found = f": {p.found.product_name or 'answered'}" if p.found is not None else ""
        print(f"\rscanning MAC {p.mac:>2} ({p.done}/{p.total}){found}   ", end="", file=sys.stderr)
        if p.found is not None:
            print(file=sys.stderr)

    config = ProbeConfig(
        mac=args.mac, vendor_id=args.vendor_id, macs=tuple(args.nodes), timeout=args.timeout
    )
    line = LinkConfig(args.interface, args.channel, args.bitrate)
    try:
        nodes = asyncio.run(scan_line(line, config, progress))
    except ScanRefused as exc:
        print(f"\nerror: {exc}", file=sys.stderr)
        return 1
    except (AdapterError, DeviceNetDecodeError, OSError) as exc:
        print(f"\nerror: {args.interface} {args.channel}: {exc}", file=sys.stderr)
        return 1
    print(file=sys.stderr)
    if args.json:
        print(json.dumps([describe(n) for n in nodes]))
        return 0
    print(f"{args.interface} {args.channel}: {len(nodes)} node(s) answered")
    for node in nodes:
        print(_line(node))
    return 0
