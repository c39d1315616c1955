"""A test adapter: drives simulated in-process on the shared motor physics.

Used by the daemon tests (``adapter = "fake"``, registered by tests/support/plugins.py)
and by the northbound tests. It behaves like a real adapter towards the hub:
comm goes connecting -> online, commands are followed with ramps, fault reset
is taken as an edge, parameters are served from a table.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, ClassVar

from gateway.adapter import (
    Capabilities,
    EventKind,
    HubPort,
    ParamInfo,
    ParamValue,
    param_table,
)
from gateway.config import BusConfig, DriveConfig
from gateway.errors import ParameterError
from gateway.model import CommState, Device, Direction, DriveStatus, Source, SpeedScale
from gateway.schema import Table
from gateway.sim import Motor, MotorParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FakeBusOptions:
    cycle: float = 0.02
    crash_after: int = 0  # cycles before the adapter raises (0 = never)
    state_file: str | None = None  # where to record what the adapter did (daemon tests)


@dataclass(frozen=True)
class FakeDriveOptions:
    rated_rpm: float = 1800.0
    ramp_time: float = 0.5
    start_running: bool = False  # the drive is already turning (local control) at start
    stuck: bool = False  # the drive ignores every command (a drive that will not stop)


PARAM_LIMITS: dict[int, tuple[int, int]] = {100: (0, 9999), 101: (0, 9999), 134: (0, 3600)}
# the fake drives' parameter table (ParamInfo): P100 named, P101 and P134 left unnamed
PARAM_INFO = param_table([ParamInfo(100, "Acceleration time", "s", 1, 0.0, 999.9, code="P0100")])


class FakeAdapter:
    devices: ClassVar[frozenset[Device]] = frozenset({Device.TEST, Device.MCD600})
    address_range: ClassVar[tuple[int, int]] = (1, 125)
    instances: ClassVar[list[FakeAdapter]] = []

    @classmethod
    def parse_bus_options(cls, table: Table) -> FakeBusOptions:
        return FakeBusOptions(
            cycle=table.number("cycle", 0.02, minimum=0.001, maximum=1.0),
            crash_after=table.integer("crash_after", 0, minimum=0),
            state_file=table.string("state_file", None),
        )

    @classmethod
    def parse_drive_options(cls, table: Table, drive: DriveConfig) -> FakeDriveOptions:
        return FakeDriveOptions(
            rated_rpm=table.number("rated_rpm", 1800.0, minimum=1.0, maximum=100000.0),
            ramp_time=table.number("ramp_time", 0.5, minimum=0.0, maximum=100.0),
            start_running=table.boolean("start_running", False),
            stuck=table.boolean("stuck", False),
        )

    def __init__(self, bus: BusConfig) -> None:
        self.bus = bus
        self.name = bus.name
        self.options: FakeBusOptions = bus.options
        self.motors: dict[str, Motor] = {}
        self.params: dict[str, dict[int, int]] = {}
        self.reset_seen: dict[str, int] = {}
        self.faults: dict[str, int] = {}
        self.cycles = 0
        self.online = True
        for d in bus.drives:
            opts: FakeDriveOptions = d.options
            motor = Motor(
                MotorParams(
                    rated_rpm=opts.rated_rpm, accel_time=opts.ramp_time, decel_time=opts.ramp_time
                )
            )
            if opts.start_running:
                motor.command(True, opts.rated_rpm / 2)
                motor.speed = opts.rated_rpm / 2
            self.motors[d.id] = motor
            self.params[d.id] = {100: 50, 101: 50, 134: 1800, 2: 0, 3: 0}
        FakeAdapter.instances.append(self)

    def _record(self, text: str) -> None:
        if self.options.state_file:
            with open(self.options.state_file, "a", encoding="utf-8") as f:
                f.write(text + "\n")

    def inject_fault(self, drive_id: str, code: int) -> None:
        self.faults[drive_id] = code

    async def run(self, hub: HubPort) -> None:
        for d in self.bus.drives:
            opts: FakeDriveOptions = d.options
            scale = None if d.device is Device.MCD600 else SpeedScale(opts.rated_rpm, 100.0)
            unsupported = {}
            if d.device is Device.MCD600:
                unsupported = {"direction": "a soft starter has no direction", "jog": "no jog"}
            caps = Capabilities(speed_scale=scale, unsupported=unsupported, params=PARAM_INFO)
            hub.set_capabilities(d.id, caps)
            hub.update(d.id, comm=CommState.CONNECTING)
            self.reset_seen[d.id] = hub.desired(d.id).fault_reset_seq
        self._record("started")
        loop = asyncio.get_running_loop()
        last = loop.time()
        try:
            while True:
                now = loop.time()
                self._cycle(hub, now - last)
                last = now
                self.cycles += 1
                if self.options.crash_after and self.cycles >= self.options.crash_after:
                    raise RuntimeError("fake adapter crash (test)")
                await asyncio.sleep(self.options.cycle)
        finally:
            self._record("left the bus")

    def _cycle(self, hub: HubPort, dt: float) -> None:
        for d in self.bus.drives:
            if not self.online:
                hub.update(d.id, comm=CommState.OFFLINE, running=False)
                continue
            self._drive_cycle(hub, d, dt)

    def _drive_cycle(self, hub: HubPort, d: DriveConfig, dt: float) -> None:
        motor = self.motors[d.id]
        want = hub.desired(d.id)
        if want.fault_reset_seq != self.reset_seen[d.id]:
            self.reset_seen[d.id] = want.fault_reset_seq
            if self.faults.pop(d.id, None) is not None:
                hub.event(d.id, EventKind.FAULT, "fault reset sent")
        fault = self.faults.get(d.id)
        was_running = motor.running
        if d.options.stuck:
            pass  # deaf to the network: keeps doing what it does
        elif fault is not None or want.coast_stop:
            motor.coast()
        elif want.run:
            opts: FakeDriveOptions = d.options
            rpm = want.speed_rpm
            if rpm is None:
                rpm = (want.speed_pct or 0.0) * opts.rated_rpm / 100.0
            sign = -1.0 if want.direction is Direction.REVERSE else 1.0
            motor.command(True, sign * abs(rpm))
        elif want.source is Source.NONE and d.options.start_running:
            pass  # turning under local control until the gateway commands it
        else:
            motor.command(motor.speed != 0.0, 0.0)
        motor.advance(dt)
        if motor.enabled and motor.reference == 0.0 and motor.speed == 0.0:
            motor.command(False, 0.0)
        if was_running and not motor.running:
            self._record(f"{d.id} stopped")
        self._publish(hub, d, motor, fault)

    def _publish(self, hub: HubPort, d: DriveConfig, motor: Motor, fault: int | None) -> None:
        opts: FakeDriveOptions = d.options
        status = DriveStatus.READY
        if fault is not None:
            status = DriveStatus.FAULTED
        elif motor.running:
            status = DriveStatus.RUNNING if motor.speed == motor.reference else DriveStatus.STARTING
        is_starter = d.device is Device.MCD600
        hub.update(
            d.id,
            comm=CommState.ONLINE,
            status=status,
            running=motor.running,
            direction=Direction.REVERSE if motor.speed < 0 else Direction.FORWARD,
            at_reference=motor.running and motor.speed == motor.reference,
            remote=True,
            speed_rpm=None if is_starter else round(motor.speed, 1),
            speed_pct=None if is_starter else round(100 * motor.speed / opts.rated_rpm, 2),
            current_a=round(motor.current(), 2),
            fault_code=fault,
            fault_text=None if fault is None else f"test fault {fault}",
        )

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        await asyncio.sleep(0)
        table = self.params[drive_id]
        if number not in table:
            raise ParameterError("impermissible parameter number", code=0x0000)
        return table[number]

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        await asyncio.sleep(0)
        if number not in self.params[drive_id]:
            raise ParameterError("impermissible parameter number", code=0x0000)
        lo, hi = PARAM_LIMITS.get(number, (0, 0))
        if not isinstance(value, int) or not lo <= value <= hi:
            raise ParameterError("parameter value out of limits", code=0x0002)
        self.params[drive_id][number] = value

    def diagnostics(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles,
            "drives": {d.id: {"cycles": self.cycles} for d in self.bus.drives},
        }
