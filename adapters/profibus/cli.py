"""Command-line tools of the Profibus line (the only printing in this package).

* ``drive-gateway profibus scan --port PORT [--baud B] [--from A --to B] [--rs485 MODE]``:
  the live list, one FDL status request per address (fact sheet 1.2, 1.3). A port another
  process holds (a running gateway) is refused before anything is sent: one master per line.
* ``drive-gateway sim profibus --port PORT --slaves SPEC...``: simulated slaves on a serial
  port (or ``--port pty``: a new pty pair, its path printed for the master), until Ctrl-C.
  SPEC is ``ADDRESS[-ADDRESS]:KIND[:SIZE]`` (KIND: cfw11, cfw700, cfw320, mcd600, echo;
  SIZE: bytes in and out of an echo slave), or ``--config FILE`` to simulate the drives of
  a gateway config's Profibus buses as they are configured.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from gateway.config import Config, DriveConfig

from .driver import LineDriver
from .fdl import MAX_STATION, StationType
from .link import OPEN_ERRORS, Rs485, open_link
from .options import ProfibusDriveOptions
from .portlock import PortHeld
from .scan import Scanner
from .timing import BAUD_RATES, BusParams

if TYPE_CHECKING:
    from .sim.line import SimLine

STATION_NAMES = {
    StationType.SLAVE: "slave",
    StationType.MASTER_NOT_READY: "master (not ready)",
    StationType.MASTER_READY: "master (ready for the ring)",
    StationType.MASTER_IN_RING: "master (in the ring)",
}


# ---------------------------------------------------------------------------------------
# profibus scan


def add_profibus(sub: Any) -> None:
    p = sub.add_parser("profibus", help="Profibus DP line tools")
    tools = p.add_subparsers(dest="tool", metavar="TOOL", required=True)
    scan = tools.add_parser("scan", help="list the stations answering on a line (live list)")
    scan.add_argument("--port", required=True, help="device path or pyserial URL")
    scan.add_argument(
        "--baud",
        type=int,
        default=500000,
        choices=BAUD_RATES,
        metavar="B",
        help="baud rate (default 500000)",
    )
    scan.add_argument(
        "--from",
        dest="first",
        type=_address,
        default=0,
        metavar="A",
        help="first address (default 0)",
    )
    scan.add_argument(
        "--to",
        dest="last",
        type=_address,
        default=MAX_STATION,
        metavar="B",
        help="last address (default 125)",
    )
    scan.add_argument(
        "--master-address",
        type=_address,
        default=2,
        metavar="N",
        help="our own address (default 2)",
    )
    _add_rs485(scan)
    scan.add_argument("--tsl", type=int, help="slot time in bit times (default: per baud rate)")
    scan.add_argument("--latency", type=float, default=0.01, help="s added to each reply wait")
    scan.add_argument(
        "--retries",
        type=int,
        default=1,
        choices=range(1, 16),
        metavar="N",
        help="repeats per address (1-15, default 1)",
    )
    scan.add_argument("--json", action="store_true", help="print JSON")
    scan.set_defaults(handler=cmd_scan)


def _add_rs485(parser: Any) -> None:
    parser.add_argument(
        "--rs485",
        type=Rs485,
        default=Rs485.AUTO,
        choices=list(Rs485),
        metavar="MODE",
        help="kernel RS-485 mode: auto (default: where the driver has it), on, off",
    )


def _address(text: str) -> int:
    value = int(text)
    if not 0 <= value <= MAX_STATION:
        raise argparse.ArgumentTypeError(f"{value} is not a station address (0-{MAX_STATION})")
    return value


def scan_params(args: argparse.Namespace) -> BusParams:
    changes: dict[str, Any] = {
        "master_address": args.master_address,
        "latency": args.latency,
        "retries": args.retries,
    }
    if args.tsl is not None:
        changes["tsl"] = args.tsl
    return BusParams.for_baudrate(args.baud, **changes)


async def scan(
    port: str, bus: BusParams, addresses: Iterable[int], rs485: Rs485 = Rs485.AUTO
) -> dict[int, StationType]:
    """FDL status requests to ``addresses`` on ``port``; the stations that answered."""
    loop = asyncio.get_running_loop()
    scanner = Scanner(bus, addresses, loop.time())
    done: asyncio.Future[None] = loop.create_future()
    failed: list[BaseException] = []

    def on_error(exc: BaseException) -> None:
        failed.append(exc)
        if not done.done():
            done.set_result(None)

    def on_stepped() -> None:
        if scanner.done and not done.done():
            done.set_result(None)

    link = await open_link(port, bus.baudrate, loop, lambda data, now: None, on_error, rs485=rs485)
    driver = LineDriver(scanner, link, on_stepped=on_stepped)
    try:
        driver.start()
        await done
    finally:
        driver.stop()
        await link.aclose()
    if failed:
        raise failed[0]
    return dict(sorted(scanner.found.items()))


def cmd_scan(args: argparse.Namespace) -> int:
    if args.first > args.last:
        print(f"error: --from {args.first} is above --to {args.last}", file=sys.stderr)
        return 2
    bus = scan_params(args)
    addresses = range(args.first, args.last + 1)
    try:
        found = asyncio.run(scan(args.port, bus, addresses, args.rs485))
    except PortHeld as exc:  # a gateway (or another tool) is master there: nothing was sent
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OPEN_ERRORS as exc:
        print(f"error: {args.port}: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({str(a): STATION_NAMES[t] for a, t in found.items()}))
        return 0
    print(f"{args.port}: {len(found)} station(s) answered, addresses {args.first}-{args.last}")
    for address, station in found.items():
        print(f"  {address:>3}  {STATION_NAMES[station]}")
    return 0


# ---------------------------------------------------------------------------------------
# sim profibus


@dataclass(frozen=True)
class SlaveSpec:
    address: int
    kind: str
    size: int | None = None


def parse_spec(text: str) -> list[SlaveSpec]:
    """``5:cfw11``, ``3-34:echo``, ``7:echo:8`` -> one SlaveSpec per address."""
    from .sim.devices import KINDS

    parts = text.split(":")
    if len(parts) not in (2, 3) or parts[1] not in KINDS:
        kinds = ", ".join(KINDS)
        raise argparse.ArgumentTypeError(
            f"{text!r} is not ADDRESS[-ADDRESS]:KIND[:SIZE] (KIND: {kinds})"
        )
    first, _, last = parts[0].partition("-")
    try:
        low, high = _address(first), _address(last or first)
        size = int(parts[2]) if len(parts) == 3 else None
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    if size is not None and (parts[1] != "echo" or not 1 <= size <= 64):
        raise argparse.ArgumentTypeError(f"{text!r}: SIZE (1-64) is for echo slaves only")
    return [SlaveSpec(a, parts[1], size) for a in range(low, high + 1)]


def add_sim(sub: Any) -> None:
    p = sub.add_parser("profibus", help="simulated DP slaves on a serial port")
    p.add_argument("--port", required=True, help="device path, pyserial URL, or 'pty'")
    p.add_argument(
        "--baud",
        type=int,
        default=500000,
        choices=BAUD_RATES,
        metavar="B",
        help="baud rate (default 500000)",
    )
    p.add_argument(
        "--slaves",
        nargs="+",
        type=parse_spec,
        default=[],
        metavar="SPEC",
        help="ADDRESS[-ADDRESS]:KIND[:SIZE], KIND: cfw11 cfw700 cfw320 mcd600 echo",
    )
    _add_rs485(p)
    p.add_argument("--config", help="simulate the drives of this gateway config's Profibus buses")
    p.add_argument("--noise", type=float, default=0.0, help="bit flips per byte (line noise)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=cmd_sim)


def build_line(
    specs: Iterable[SlaveSpec], config: Config | None = None, noise: float = 0.0, seed: int = 0
) -> SimLine:
    """The simulated line of the command line's slaves and a config's Profibus drives."""
    from gateway.sim import FaultInjector

    from .sim.devices import KINDS, make_device, with_setup
    from .sim.echo import EchoSim
    from .sim.line import SimLine
    from .sim.slave import DpSlave

    line = SimLine(faults=FaultInjector(seed=seed, bit_error_rate=noise))
    for spec in specs:
        if spec.kind == "echo":
            device: Any = EchoSim(spec.size or 4)
        else:
            device = make_device(KINDS[spec.kind])
        line.add(DpSlave(spec.address, device))
    for drive in _profibus_drives(config):
        inner = replace(drive, options=drive.options.profile)
        sim = with_setup(make_device(drive.device, inner), drive.device, drive.options.setup)
        line.add(DpSlave(drive.address, sim))
    return line


def _profibus_drives(config: Config | None) -> list[DriveConfig]:
    """The drives of a config's Profibus buses (their options are the master's)."""
    if config is None:
        return []
    return [
        d for bus in config.buses for d in bus.drives if isinstance(d.options, ProfibusDriveOptions)
    ]


async def run_sim(
    port: str,
    baudrate: int,
    line: SimLine,
    stop: asyncio.Event,
    ready: Callable[[str], None] = print,
    *,
    rs485: Rs485 = Rs485.AUTO,
) -> None:
    """Serve ``line`` on ``port`` until ``stop`` is set."""
    from .sim.port import SimPort

    if port == "pty":
        sim, path = SimPort.on_pty(line)
    else:
        sim, path = SimPort.on_serial(line, port, baudrate, rs485=rs485), port
    sim.start()
    try:
        ready(f"simulating {len(line.slaves)} slave(s) on {path}: {sorted(line.slaves)}")
        await stop.wait()
    finally:
        sim.close()


def cmd_sim(args: argparse.Namespace) -> int:
    from gateway.config import load
    from gateway.errors import ConfigError, ConfigErrors

    specs = [s for group in args.slaves for s in group]
    config = None
    if args.config:
        try:
            config = load(args.config)
        except (ConfigErrors, ConfigError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    try:
        line = build_line(specs, config, args.noise, args.seed)
    except (ValueError, LookupError, ImportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not line.slaves:
        print("error: no slaves to simulate (give --slaves or --config)", file=sys.stderr)
        return 2

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await run_sim(
            args.port, args.baud, line, stop, lambda text: print(text, flush=True), rs485=args.rs485
        )

    try:
        asyncio.run(main())
    except PortHeld as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OPEN_ERRORS as exc:
        print(f"error: {args.port}: {exc}", file=sys.stderr)
        return 1
    return 0
