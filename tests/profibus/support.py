"""A small generic DP profile for the Profibus tests, and an adapter that accepts it.

The device is :class:`adapters.profibus.sim.echo.EchoSim`: ``size`` bytes out and in, the
inputs echo the outputs. The profile's output telegram: byte 0 bit 0 run, bit 1 fault
reset (one telegram per reset request), bit 2 reverse; bytes 1-2 the speed in rpm. The
inputs are the same bytes, so the drive "runs" at the speed it was told. Parameters are
DP-V1 records on slot 0, index = parameter number, a 16-bit big-endian value.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.contract import (
    PROFILES,
    DiagEvent,
    DiagKind,
    DpProfileBase,
    EventSink,
    RecordAccessError,
    RecordChannel,
    SlaveSetup,
)
from adapters.profibus.sim.echo import ECHO_IDENT, echo_cfg
from adapters.profibus.sim.line import SimLine
from gateway.adapter import Capabilities, ParamValue
from gateway.config import BusConfig, Config, DriveConfig, parse
from gateway.errors import GatewayError, ParameterError
from gateway.hub import Hub
from gateway.model import DesiredCommand, Device, Direction, DriveState, DriveStatus, SpeedScale
from gateway.runtime.daemon import build_hub
from gateway.schema import Table
from tests.support import simulated
from tests.support.heard import Heard

ADAPTER = "echo-profibus"  # registered by tests/support/plugins.py


@dataclass(frozen=True)
class EchoOptions:
    size: int = 4
    ident_number: int = ECHO_IDENT
    connect_fails: bool = False


class EchoProfile(DpProfileBase):
    device: ClassVar[Device] = Device.TEST

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> EchoOptions:
        return EchoOptions(
            size=table.integer("size", 4, minimum=3, maximum=32),
            ident_number=table.integer("ident_number", ECHO_IDENT, minimum=0, maximum=0xFFFF),
            connect_fails=table.boolean("connect_fails", False),
        )

    def __init__(self, drive: DriveConfig) -> None:
        self.options = drive.options if isinstance(drive.options, EchoOptions) else EchoOptions()
        self.size = self.options.size
        self.connects = 0
        self.comm_lost = 0
        self.resets_sent = 0
        self._reset_seen: int | None = None

    def setup(self) -> SlaveSetup:
        return SlaveSetup(
            ident_number=self.options.ident_number,
            cfg=echo_cfg(self.size),
            input_len=self.size,
            output_len=self.size,
            dpv1=True,
        )

    def capabilities(self) -> Capabilities:
        return Capabilities(speed_scale=SpeedScale(1500.0, 100.0, "test"))

    async def on_connect(self, channel: RecordChannel, event: EventSink) -> Mapping[str, Any]:
        self.connects += 1
        if self.options.connect_fails:
            raise GatewayError("the test profile refuses to connect")
        ident = await channel.read_record(0, 0, 4)
        event(f"echo device {ident.hex()}", DiagKind.INFO)
        return {"values": {"ident": int.from_bytes(ident[:2], "big")}}

    def outputs(self, desired: DesiredCommand, now: float) -> bytes:
        reset = False
        seq = desired.fault_reset_seq
        if self._reset_seen is None or seq < self._reset_seen:
            self._reset_seen = seq
        elif seq > self._reset_seen:
            self._reset_seen = seq
            reset = True
            self.resets_sent += 1
        flags = (
            (1 if desired.run else 0)
            | (2 if reset else 0)
            | (4 if desired.direction is Direction.REVERSE else 0)
        )
        rpm = desired.speed_rpm
        if rpm is None and desired.speed_pct is not None:
            rpm = desired.speed_pct * 15.0
        speed = min(0xFFFF, round(abs(rpm or 0.0)))
        return bytes((flags, speed >> 8, speed & 0xFF)) + bytes(self.size - 3)

    def inputs(self, data: bytes, now: float) -> Mapping[str, Any]:
        running = bool(data[0] & 1)
        speed = float(int.from_bytes(data[1:3], "big")) if running else 0.0
        return {
            "status": DriveStatus.RUNNING if running else DriveStatus.READY,
            "running": running,
            "remote": True,
            "speed_rpm": speed,
            "speed_pct": round(speed / 15.0, 2),
            "direction": Direction.REVERSE if data[0] & 4 else Direction.FORWARD,
        }

    def on_ext_diag(self, data: bytes) -> list[DiagEvent]:
        return [DiagEvent(f"device diagnosis {data.hex(' ')}", DiagKind.ALARM, {"raw": data.hex()})]

    def on_comm_lost(self) -> None:
        self.comm_lost += 1
        self._reset_seen = None

    async def read_param(self, channel: RecordChannel, number: int, subindex: int) -> ParamValue:
        try:
            data = await channel.read_record(0, number, 16)
        except RecordAccessError as exc:
            raise ParameterError(exc.text, exc.code_1) from exc
        return int.from_bytes(data[:2] or b"\0", "big")

    async def write_param(
        self, channel: RecordChannel, number: int, subindex: int, value: ParamValue
    ) -> None:
        try:
            await channel.write_record(0, number, int(value).to_bytes(2, "big"))
        except RecordAccessError as exc:
            raise ParameterError(exc.text, exc.code_1) from exc


class EchoProfibusAdapter(ProfibusAdapter):
    """The Profibus adapter with the test device added."""

    devices: ClassVar[frozenset[Device]] = ProfibusAdapter.devices | {Device.TEST}
    profiles: ClassVar[Mapping[Device, str]] = {
        **PROFILES,
        Device.TEST: "tests.profibus.support:EchoProfile",
    }


# ---------------------------------------------------------------------------------------
# Building a line in a test

FAST = {
    "baudrate": 500000,
    "latency": 0.02,
    "cycle_time": 0.002,
    "watchdog": 0.5,
    "absent_retry": 0.2,
    "fault_retry": 0.2,
    "acyclic_timeout": 0.5,
    "live_list_period": 0.0,
}


def line_config(
    addresses: list[int], *, drive: Mapping[str, Any] | None = None, **bus: Any
) -> Config:
    table: dict[str, Any] = {"adapter": ADAPTER, "simulate": True, **FAST, **bus}
    if "port" in bus:
        table.pop("simulate")
    table["drives"] = [
        {"id": f"d{a}", "device": "test", "address": a, "modbus_unit": None, **(drive or {})}
        for a in addresses
    ]
    for d in table["drives"]:
        d.pop("modbus_unit")
    return parse({"buses": {"pb": table}}, "test.toml")


@dataclass
class Line:
    adapter: EchoProfibusAdapter
    hub: Hub
    task: asyncio.Task[None]

    @property
    def sim(self) -> SimLine:
        line = simulated.sim_line(self.adapter)
        assert line is not None
        return line

    async def heard_until(self, cond: Callable[[], bool], limit: float = 5.0) -> None:
        """Wait for ``cond``, checked after each telegram a simulated slave takes (the master
        polls every slave of the line all the time, so no condition waits on a timer)."""
        with Heard(*(slave.counters for slave in self.sim.slaves.values())) as heard:
            async with asyncio.timeout(limit):
                await heard.until(cond)

    async def online(self, *ids: str, limit: float = 5.0) -> None:
        async with asyncio.timeout(limit):
            for drive_id in ids:
                await self.hub.wait_for(drive_id, lambda s: s.online)

    async def until(self, drive_id: str, pred: Any, limit: float = 5.0) -> DriveState:
        async with asyncio.timeout(limit):
            state: DriveState = await self.hub.wait_for(drive_id, pred)
            return state


async def until(cond: Callable[[], bool], limit: float = 5.0) -> None:
    """Wait for ``cond`` where no simulated slave takes telegrams (a port alone, a fake
    engine): polled, bounded. On a running line, :meth:`Line.heard_until`."""
    async with asyncio.timeout(limit):
        while not cond():  # noqa: ASYNC110
            await asyncio.sleep(0.002)


@contextlib.asynccontextmanager
async def running_line(config: Config) -> AsyncIterator[Line]:
    bus: BusConfig = config.buses[0]
    hub = build_hub(config)
    adapter = simulated.profibus(EchoProfibusAdapter, bus)
    hub.attach_params([d.id for d in bus.drives], adapter)
    task = asyncio.create_task(adapter.run(hub), name="profibus-test-line")
    try:
        for _ in range(100):  # the simulated line is made as the adapter starts
            if not bus.simulate or simulated.sim_line(adapter) is not None:
                break
            await asyncio.sleep(0)
        yield Line(adapter, hub, task)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
