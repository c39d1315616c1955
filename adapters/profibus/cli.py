"""Command-line tools of the Profibus line (the only printing in this package).

* ``drive-gateway profibus scan --port PORT [--baud B] [--from A --to B] [--rs485 MODE]
  [--gsd-dir DIR [--toml]]``: the live list, one FDL status request per address (fact sheet
  1.2, 1.3), then each slave's Ident_Number (Slave_Diag, 1.8) and configuration (Get_Cfg,
  1.7). With ``--gsd-dir`` each slave is matched to a GSD file of DIR by its Ident_Number
  and to the module its configuration is; ``--toml`` prints drive stanzas to paste into a
  config. Progress goes to stderr (a status line on a terminal, plain lines otherwise). A
  port another process holds (a running gateway) is refused before anything is sent: one
  master per line.
* ``drive-gateway sim profibus --port PORT --slaves SPEC...``: simulated slaves on a serial
  port (or ``--port pty``: a new pty pair, its path printed for the master), until Ctrl-C.
  SPEC is ``ADDRESS[-ADDRESS]:KIND[:SIZE]`` (KIND: the ``cli`` names of the registry's
  Profibus devices, :data:`.sim.devices.KINDS`; SIZE: bytes in and out of an echo slave),
  or ``--config FILE`` to simulate the drives of a gateway config's Profibus buses as they
  are configured.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from adapters.profibus.codec.fdl import MAX_STATION, StationType
from adapters.profibus.contract import PROFILES, load_profile
from adapters.profibus.driver import LineDriver
from adapters.profibus.link import OPEN_ERRORS, PortHeld, Rs485, open_link
from adapters.profibus.master.scan import Scanner, SlaveInfo
from adapters.profibus.master.timing import BAUD_RATES, BusParams
from adapters.profibus.options import DriveOptions, find_in_dir
from gateway.config import Config, DriveConfig
from gateway.model import Device

if TYPE_CHECKING:
    from adapters.profibus.sim.line import SimLine

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
    scan.add_argument("--gsd-dir", metavar="DIR", help="match each slave to a GSD file of DIR")
    scan.add_argument(
        "--toml", action="store_true", help="print config stanzas for the slaves (--gsd-dir)"
    )
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
    port: str,
    bus: BusParams,
    addresses: Iterable[int],
    rs485: Rs485 = Rs485.AUTO,
    progress: Callable[[Scanner], None] | None = None,
) -> dict[int, StationType]:
    """FDL status requests to ``addresses`` on ``port``; the stations that answered."""
    scanner = await run_scan(port, bus, addresses, rs485, progress)
    return dict(sorted(scanner.found.items()))


async def run_scan(
    port: str,
    bus: BusParams,
    addresses: Iterable[int],
    rs485: Rs485 = Rs485.AUTO,
    progress: Callable[[Scanner], None] | None = None,
) -> Scanner:
    """The scan of ``addresses`` on ``port``, done (its ``found`` and ``slaves``)."""
    loop = asyncio.get_running_loop()
    scanner = Scanner(bus, addresses, loop.time())
    done: asyncio.Future[None] = loop.create_future()
    failed: list[BaseException] = []
    seen = [-1]

    def on_error(exc: BaseException) -> None:
        failed.append(exc)
        if not done.done():
            done.set_result(None)

    def on_stepped() -> None:
        if progress is not None and scanner.probed != seen[0]:
            seen[0] = scanner.probed
            progress(scanner)
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
    return scanner


class Progress:
    """Scan progress on stderr: one status line rewritten on a terminal, else a plain line
    every ``every`` addresses and at the end."""

    def __init__(self, stream: Any = None, every: int = 16) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every = every

    def __call__(self, scanner: Scanner) -> None:
        n, total = scanner.probed, scanner.total
        text = f"scanned {n}/{total} addresses, {len(scanner.found)} station(s) answered"
        if self.tty:
            end = "\n" if n == total else ""
            print(f"\r{text}", end=end, file=self.stream, flush=True)
        elif n == total or n % self.every == 0:
            print(text, file=self.stream, flush=True)


def cmd_scan(args: argparse.Namespace) -> int:
    if args.first > args.last:
        print(f"error: --from {args.first} is above --to {args.last}", file=sys.stderr)
        return 2
    if args.toml and not args.gsd_dir:
        print("error: --toml needs --gsd-dir DIR (the GSD files to match)", file=sys.stderr)
        return 2
    bus = scan_params(args)
    addresses = range(args.first, args.last + 1)
    try:
        scanner = asyncio.run(run_scan(args.port, bus, addresses, args.rs485, Progress()))
    except PortHeld as exc:  # a gateway (or another tool) is master there: nothing was sent
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OPEN_ERRORS as exc:
        print(f"error: {args.port}: {exc}", file=sys.stderr)
        return 1
    found = dict(sorted(scanner.found.items()))
    matches = {a: match_gsd(args.gsd_dir, info) for a, info in scanner.slaves.items()}
    if args.json:
        print(
            json.dumps(
                {str(a): _json(t, scanner.slaves.get(a), matches.get(a)) for a, t in found.items()}
            )
        )
        return 0
    if args.toml:
        for address in found:
            match = matches.get(address)
            if match is not None:
                print(stanza(address, match))
        return 0
    print(f"{args.port}: {len(found)} station(s) answered, addresses {args.first}-{args.last}")
    for address, station in found.items():
        text = _station_text(station, scanner.slaves.get(address), matches.get(address))
        print(f"  {address:>3}  {text}")
    return 0


@dataclass(frozen=True)
class GsdMatch:
    """A slave matched to a GSD file (and to its module, where its Get_Cfg is one)."""

    gsd: Any  # adapters.profibus.codec.gsd.Gsd
    modules: tuple[str, ...] | None
    cfg: bytes | None
    by_sizes: bool = False  # the module has the slave's I/O sizes, in other identifier bytes


def match_gsd(directory: str | None, info: SlaveInfo) -> GsdMatch | None:
    """The GSD of ``directory`` with the slave's Ident_Number (the first by file name)."""
    from adapters.profibus.codec.gsd import match_modules

    if directory is None or info.ident_number is None:
        return None
    files = find_in_dir(directory, info.ident_number)
    for gsd in files:  # the first whose modules make the slave's configuration
        modules = match_modules(gsd, info.cfg) if info.cfg else None
        if modules is not None:
            return GsdMatch(gsd, tuple(m.name for m in modules), info.cfg)
    for gsd in files:  # a compact station's one module of the same I/O sizes
        sized = module_of_sizes(gsd, info.cfg)
        if sized is not None:
            return GsdMatch(gsd, (sized,), info.cfg, by_sizes=True)
    return GsdMatch(files[0], None, info.cfg) if files else None


def _sizes(cfg: bytes) -> tuple[int, int] | None:
    from adapters.profibus.codec.chkcfg import (
        decode_identifiers,
        total_input_bytes,
        total_output_bytes,
    )

    try:
        ids = decode_identifiers(cfg)
    except ValueError:
        return None
    return total_input_bytes(ids), total_output_bytes(ids)


def module_of_sizes(gsd: Any, cfg: bytes | None) -> str | None:
    """The one module of a compact station (``Modular_Station = 0``) with the I/O sizes of
    ``cfg``, written in other identifier bytes (a slave not yet configured answers Get_Cfg
    with its own default form: the simulated CFW-11 ``F1``, its GSD module ``C0 C1 C1``),
    or None (no such module, several, or a modular station)."""
    if not cfg or gsd.modular:
        return None
    sizes = _sizes(cfg)
    same = [m.name for m in gsd.modules if sizes is not None and _sizes(m.config) == sizes]
    return same[0] if len(same) == 1 else None


def _station_text(station: StationType, info: SlaveInfo | None, match: GsdMatch | None) -> str:
    from adapters.profibus.master.events import describe_cfg

    parts = [STATION_NAMES[station]]
    if info is not None and info.ident_number is not None:
        parts.append(f"Ident_Number 0x{info.ident_number:04X}")
        if info.master_address not in (None, 0xFF):
            parts.append(f"parameterised by master {info.master_address}")
    if info is not None and info.cfg is not None:
        parts.append(f"configuration {describe_cfg(info.cfg)}")
    if match is not None:
        parts.append(f"GSD {match.gsd.path}")
        if match.modules is not None:
            parts.append(f"module {', '.join(map(repr, match.modules))}")
        else:
            parts.append("no module of it matches the configuration")
    return ", ".join(parts)


def _json(station: StationType, info: SlaveInfo | None, match: GsdMatch | None) -> dict[str, Any]:
    out: dict[str, Any] = {"station": STATION_NAMES[station]}
    if info is not None:
        out["ident_number"] = info.ident_number
        out["master_address"] = info.master_address
        out["cfg"] = None if info.cfg is None else info.cfg.hex(" ").upper()
    if match is not None:
        out["gsd"] = match.gsd.path
        out["modules"] = None if match.modules is None else list(match.modules)
    return out


def _device_of(gsd: Any) -> Device | None:
    """The device a GSD's Model_Name names, by the registry's ``gsd_names`` (None: not one
    the gateway knows)."""
    name = str(gsd.name).casefold()
    for device in PROFILES:
        if any(k in name for k in device.spec.gsd_names):
            return device
    return None


def stanza(address: int, match: GsdMatch) -> str:
    """A ``[[buses.profibus.drives]]`` table for a matched slave, ready to paste."""
    from adapters.profibus.codec.chkcfg import (
        decode_identifiers,
        total_input_bytes,
        total_output_bytes,
    )

    device = _device_of(match.gsd)
    lines = [
        "[[buses.profibus.drives]]",
        f'id = "station{address}"',
        f'device = "{device.value}"' if device else 'device = ""  # not a model the gateway knows',
        f"address = {address}",
        f"gsd = {json.dumps(str(Path(match.gsd.path).resolve()))}",  # pasted anywhere
    ]
    cfg = match.cfg.hex(" ").upper() if match.cfg else "none"
    if match.modules is None:  # no module line: pasted, check-config names the modules
        known = ", ".join(json.dumps(m.name) for m in match.gsd.modules) or "none"
        lines.append(f"# module: the slave's configuration {cfg} is no module of the GSD;")
        lines.append(f"# give the one the drive is set for: {known}")
        return "\n".join(lines) + "\n"
    if len(match.modules) == 1 and not match.gsd.modular:
        line = f"module = {json.dumps(match.modules[0])}"
        if match.by_sizes:
            line += f"  # its I/O sizes; the slave answered {cfg}"
        lines.append(line)
    else:
        lines.append(f"modules = {json.dumps(list(match.modules))}")
    ids = decode_identifiers(match.cfg or b"")
    sizes = (total_input_bytes(ids), total_output_bytes(ids))
    if device is not None:
        lines.extend(load_profile(device).telegram_keys(*sizes))
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------
# sim profibus


@dataclass(frozen=True)
class SlaveSpec:
    address: int
    kind: str
    size: int | None = None


def parse_spec(text: str) -> list[SlaveSpec]:
    """``5:cfw11``, ``3-34:echo``, ``7:echo:8`` -> one SlaveSpec per address."""
    from adapters.profibus.sim.devices import KINDS

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
    from adapters.profibus.sim.devices import KINDS

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
        help=f"ADDRESS[-ADDRESS]:KIND[:SIZE], KIND: {' '.join(KINDS)}",
    )
    _add_rs485(p)
    p.add_argument("--config", help="simulate the drives of this gateway config's Profibus buses")
    p.add_argument("--noise", type=float, default=0.0, help="bit flips per byte (line noise)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the line noise")
    p.set_defaults(handler=cmd_sim)


def build_line(
    specs: Iterable[SlaveSpec], config: Config | None = None, noise: float = 0.0, seed: int = 0
) -> SimLine:
    """The simulated line of the command line's slaves and a config's Profibus drives."""
    from adapters.profibus.sim.devices import KINDS, make_device, with_setup
    from adapters.profibus.sim.echo import EchoSim
    from adapters.profibus.sim.line import SimLine
    from adapters.profibus.sim.slave import DpSlave
    from gateway.sim import FaultInjector

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
    return [d for bus in config.buses for d in bus.drives if isinstance(d.options, DriveOptions)]


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
    from adapters.profibus.sim.port import SimPort

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
