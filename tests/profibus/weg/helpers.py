"""Shared pieces of the WEG profile tests: a bus-free loop and an in-memory RecordChannel."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from adapters.profibus.weg.cfw11 import Cfw11Profile
from adapters.profibus.weg.cfw320 import Cfw320Profile
from adapters.profibus.weg.cfw700 import Cfw700Profile
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim, WegSim
from gateway.config import DriveConfig
from gateway.model import DesiredCommand, Device

PROFILES: dict[Device, type[WegProfile]] = {
    Device.CFW11: Cfw11Profile,
    Device.CFW700: Cfw700Profile,
    Device.CFW320: Cfw320Profile,
}
SIMS: dict[Device, type[WegSim]] = {
    Device.CFW11: Cfw11Sim,
    Device.CFW700: Cfw700Sim,
    Device.CFW320: Cfw320Sim,
}
FAST_RAMPS = {100: 20, 101: 20}  # 2.0 s from 0 to P0134 = 1800 rpm


def drive(device: Device, options: WegOptions | None = None, address: int = 5) -> DriveConfig:
    return DriveConfig(id="d1", bus="pb", device=device, address=address, options=options)


def profile(device: Device, options: WegOptions | None = None) -> WegProfile:
    return PROFILES[device](drive(device, options))


class SimChannel:
    """RecordChannel forwarding to a simulated drive's DP-V1 records (fake clock)."""

    def __init__(self, sim: WegSim, clock: Callable[[], float] = lambda: 0.0) -> None:
        self.sim = sim
        self.clock = clock
        self.writes: list[tuple[int, int, bytes]] = []
        self.reads: list[tuple[int, int, int]] = []

    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        self.reads.append((slot, index, length))
        return self.sim.read_record(slot, index, length, self.clock())

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        self.writes.append((slot, index, bytes(data)))
        self.sim.write_record(slot, index, data, self.clock())


@dataclass
class Events:
    got: list[tuple[str, str, dict[str, Any]]] = field(default_factory=list)

    def __call__(self, text: str, kind: str = "info", **data: Any) -> None:
        self.got.append((text, kind, data))


class Loop:
    """profile.outputs() -> sim.exchange() -> profile.inputs(), stepped with a fake clock."""

    def __init__(
        self,
        device: Device,
        options: WegOptions | None = None,
        params: Mapping[int, int] | None = None,
        dt: float = 0.05,
    ) -> None:
        self.options = options or WegOptions()
        self.profile = profile(device, self.options)
        merged = {**sp.NETWORK_SOURCES, **FAST_RAMPS, **(params or {})}
        self.sim = SIMS[device].matching(self.options, address=5, params=merged)
        self.now = 0.0
        self.dt = dt
        self.desired = DesiredCommand()
        self.state: dict[str, Any] = {}
        self.channel = SimChannel(self.sim, lambda: self.now)
        self.events = Events()
        self.last_out = b""
        self.last_in = b""

    async def connect(self) -> Mapping[str, Any]:
        changes = await self.profile.on_connect(self.channel, self.events)
        self.state.update(changes)
        return changes

    def command(self, **changes: Any) -> None:
        self.desired = replace(self.desired, **changes)

    def reset(self) -> None:
        self.desired = replace(
            self.desired, run=False, fault_reset_seq=self.desired.fault_reset_seq + 1
        )

    def step(self, n: int = 1) -> dict[str, Any]:
        for _ in range(n):
            self.now += self.dt
            self.last_out = self.profile.outputs(self.desired, self.now)
            self.last_in = self.sim.exchange(self.last_out, self.now)
            self.state.update(self.profile.inputs(self.last_in, self.now))
        return self.state

    def until(self, predicate: Callable[[dict[str, Any]], bool], seconds: float) -> dict[str, Any]:
        for _ in range(round(seconds / self.dt)):
            if predicate(self.step()):
                return self.state
        raise AssertionError(f"not reached in {seconds} s: {self.state}")
