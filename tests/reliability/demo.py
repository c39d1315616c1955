"""The demo's buses (config/demo.toml), simulated in the daemon, with test timings.

The buses and drives are read from the demo file itself, so the fault and safety tests
run the very devices ``make run`` shows: the CFW-11, CFW700, CFW320 and MCD 600 on the
Profibus line, the CFW-08 on the DeviceNet line and the two CiA 402 drives on the CANopen
line. Only timings change (faster retries, short ramps), the CAN channels (one per test
and bus) and what a test overrides per drive.
"""

from __future__ import annotations

import asyncio
import contextlib
import tomllib
import uuid
from collections.abc import AsyncIterator, Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.sim.runner import SimRunner as CanOpenRunner
from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.sim import SimRunner
from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.slave import DpSlave
from gateway.adapter import Event
from gateway.model import DriveState
from tests.e2e.harness import TIMEOUT, Gateway, running_gateway
from tests.support import simulated
from tests.zenoh.client import Got, Inbox

T = TypeVar("T")

ROOT = Path(__file__).resolve().parents[2]
DEMO_FILE = ROOT / "config" / "demo.toml"
DEMO: dict[str, Any] = tomllib.loads(DEMO_FILE.read_text())

PROFIBUS = "profibus"
DEVICENET = "devicenet"
CANOPEN = "canopen"
WEG = ("cfw11", "cfw700", "cfw320")  # the inverters of the demo's Profibus line
CIA402 = ("cia402a", "cia402b")  # the CiA 402 drives of the demo's CANopen line
DRIVES = (*WEG, "mcd600", "cfw08", *CIA402)
UNITS: dict[str, int] = {
    d["id"]: d["modbus_unit"] for bus in DEMO["buses"].values() for d in bus["drives"]
}
ADDRESSES: dict[str, int] = {
    d["id"]: d["address"] for bus in DEMO["buses"].values() for d in bus["drives"]
}

PROFIBUS_TIMINGS: dict[str, Any] = {
    "latency": 0.02,
    "absent_retry": 0.2,
    "fault_retry": 0.2,
    "acyclic_timeout": 0.5,
    "live_list_period": 0.0,
}
DEVICENET_TIMINGS: dict[str, Any] = {
    "poll_interval": 0.01,
    "expected_packet_rate": 0.05,
    "response_timeout": 0.05,
    "explicit_timeout": 0.3,
    "dupmac_timeout": 0.05,
    "retry_max": 0.3,
    "status_interval": 0.2,
}
CANOPEN_TIMINGS: dict[str, Any] = {
    "sync_period": 0.02,
    "sdo_timeout": 0.3,
    "retry": 0.2,
}
# The WEG drives programmed at connect as a site would program them: the command sources
# on the network (P0105, P0220-P0228; docs/devices.md) and 0.3 s ramps (P0100/P0101).
WEG_STARTUP: dict[str, int] = {
    "P0105": 5,
    "P0220": 10,
    "P0222": 11,
    "P0226": 9,
    "P0227": 4,
    "P0228": 5,
    "P0100": 3,
    "P0101": 3,
}
DRIVE_TIMINGS: dict[str, dict[str, Any]] = {
    **{d: {"startup_params": WEG_STARTUP} for d in WEG},
    "cfw08": {"sim_ramp_time": 0.3},
    "mcd600": {"sim_time_scale": 20.0},
    "cia402a": {"sim_ramp_time": 0.3},
    "cia402b": {"sim_ramp_time": 0.3, "startup_sdo": {"0x6083": 6000, "0x6084": 6000}},
}


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"no TOML form for {v!r}")


def toml_buses(buses: Mapping[str, Mapping[str, Any]]) -> str:
    """``[buses.<name>]`` tables and their ``[[buses.<name>.drives]]`` as TOML text."""
    out: list[str] = []
    for name, bus in buses.items():
        out.append(f"[buses.{name}]")
        out += [f"{k} = {_value(v)}" for k, v in bus.items() if k != "drives"]
        for drive in bus.get("drives", []):
            out.append(f"[[buses.{name}.drives]]")
            out += [f"{k} = {_value(v)}" for k, v in drive.items()]
    return "\n".join(out) + "\n"


def demo_buses(
    channel: str,
    drives: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    profibus: Mapping[str, Any] | None = None,
    devicenet: Mapping[str, Any] | None = None,
    extra: Mapping[str, list[dict[str, Any]]] | None = None,
) -> dict[str, dict[str, Any]]:
    """The demo's bus tables with test timings; ``drives`` overrides keys per drive id,
    ``profibus`` / ``devicenet`` per bus, ``extra`` appends drives to a bus."""
    buses: dict[str, dict[str, Any]] = {}
    for name, table in DEMO["buses"].items():
        bus = {k: v for k, v in table.items() if k != "drives"}
        if name == PROFIBUS:
            bus.update(PROFIBUS_TIMINGS, **(profibus or {}))
        elif name == CANOPEN:  # a channel of its own: DeviceNet and CANopen share no line
            bus.update(CANOPEN_TIMINGS, channel=f"{channel}-co")
        else:
            bus.update(DEVICENET_TIMINGS, channel=channel, **(devicenet or {}))
        bus["drives"] = [_drive(d, (drives or {}).get(d["id"], {})) for d in table["drives"]]
        bus["drives"] += list((extra or {}).get(name, []))
        buses[name] = bus
    return buses


def _drive(demo: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    out = {**demo, **DRIVE_TIMINGS.get(demo["id"], {}), **overrides}
    startup = {
        **demo.get("startup_params", {}),
        **DRIVE_TIMINGS.get(demo["id"], {}).get("startup_params", {}),
        **overrides.get("startup_params", {}),
    }
    if startup:
        out["startup_params"] = startup
    return out


def new_channel() -> str:
    return f"rel-{uuid.uuid4().hex[:8]}"


@contextlib.asynccontextmanager
async def demo_gateway(
    tmp_path: Path,
    drives: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    wait_for: tuple[str, ...] = DRIVES,
    shutdown_timeout: float = 3.0,
    **bus_overrides: Any,
) -> AsyncIterator[Gateway]:
    """The daemon on the demo's buses (simulated), every drive in ``wait_for`` online."""
    buses = demo_buses(new_channel(), drives, **bus_overrides)
    async with running_gateway(
        tmp_path,
        lambda: toml_buses(buses),
        list(wait_for),
        shutdown_timeout=shutdown_timeout,
    ) as gw:
        yield gw


# ---------------------------------------------------------------- the simulated devices


def profibus_adapter(gw: Gateway) -> ProfibusAdapter:
    adapter = gw.adapter(PROFIBUS)
    assert isinstance(adapter, ProfibusAdapter)
    return adapter


def sim_line(gw: Gateway) -> SimLine:
    line = simulated.sim_line(profibus_adapter(gw))
    assert line is not None, "the Profibus line is not simulated"
    return line


def slave(gw: Gateway, drive: str) -> DpSlave:
    return sim_line(gw)[ADDRESSES[drive]]


def devicenet_adapter(gw: Gateway) -> DeviceNetAdapter:
    adapter = gw.adapter(DEVICENET)
    assert isinstance(adapter, DeviceNetAdapter)
    return adapter


def canopen_sim(gw: Gateway) -> CanOpenRunner:
    adapter = gw.adapter(CANOPEN)
    assert isinstance(adapter, CanOpenAdapter)
    runner = simulated.canopen_runner(adapter)
    assert runner is not None, "the CANopen line is not simulated"
    return runner


def can_sim(gw: Gateway) -> SimRunner:
    runner = simulated.sim_runner(devicenet_adapter(gw))
    assert runner is not None, "the DeviceNet line is not simulated"
    return runner


# Each bus runs on a thread and an event loop of its own, its simulator too: a test reads
# a simulated device or an adapter from here (a counter, a flag), and changes one only on
# its line (``on_line``); the adapter's figures are its line's (``figures``).


async def on_line(gw: Gateway, bus: str, fn: Callable[[], T]) -> T:
    """``fn()`` run on the bus's line (its own thread and loop), its result: a change to a
    simulated device or to the adapter, made without racing the line."""
    return await gw.on_line(bus, fn)


def figures(gw: Gateway, bus: str) -> dict[str, Any]:
    """The bus adapter's figures as its line last made them (every 0.25 s): for a bounded
    wait on a figure; ``await gw.diagnostics(bus)`` for one made now."""
    return gw.line(bus).diagnostics()


def now() -> float:
    return asyncio.get_running_loop().time()


async def until(cond: Callable[[], bool], within: float = TIMEOUT, step: float = 0.01) -> None:
    """Wait for a condition that has no event of its own (simulator counters), bounded."""
    async with asyncio.timeout(within):
        while not cond():  # noqa: ASYNC110
            await asyncio.sleep(step)


def stopped(s: DriveState) -> bool:
    return s.online and not s.running


class Events:
    """Every hub event from now on, kept; ``wait`` finds one (seen before or still to come)."""

    def __init__(self, gw: Gateway) -> None:
        self._sub = gw.daemon.hub.subscribe_events()
        self.seen: list[Event] = []

    def __enter__(self) -> Events:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.seen += self._sub.drain()
        self._sub.close()

    def texts(self, drive: str | None = None) -> list[str]:
        self.seen += self._sub.drain()
        return [e.text for e in self.seen if drive is None or e.drive_id == drive]

    async def wait(self, predicate: Callable[[Event], bool], within: float = TIMEOUT) -> Event:
        self.seen += self._sub.drain()
        for ev in self.seen:
            if predicate(ev):
                return ev

        async def find() -> Event:
            while True:
                ev = await self._sub.get()
                self.seen.append(ev)
                if predicate(ev):
                    return ev

        return await asyncio.wait_for(find(), within)

    async def text(self, drive: str, part: str, within: float = TIMEOUT) -> Event:
        """The first event of ``drive`` whose text holds ``part``."""
        return await self.wait(lambda e: e.drive_id == drive and part in e.text, within)


def at_speed(rpm: float) -> Callable[[DriveState], bool]:
    """Running at ``rpm`` (within the 13-bit resolution of the WEG speed words)."""

    def check(s: DriveState) -> bool:
        return s.running and s.speed_rpm is not None and abs(s.speed_rpm - rpm) < 1.0

    return check


async def drain(inbox: Inbox[Got], within: float = 0.3) -> list[Got]:
    """What an inbox holds, and what arrives within ``within`` seconds."""
    out: list[Got] = []
    end = now() + within
    with contextlib.suppress(TimeoutError):
        while (left := end - now()) > 0:
            out.append(await inbox.aget(left))
    return out
