"""A closed loop without a bus: profile.outputs() -> sim.exchange() -> profile.inputs().

Stepped with a fake clock; the drive state is kept as a real DriveState so every change the
profile returns must be a DriveState field.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import replace
from typing import Any

from adapters.mcd600.layout import Mode
from adapters.mcd600.options import Mcd600Options
from adapters.mcd600.profile import Mcd600Profile
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.mcd600.words import ControlWord
from gateway.config import DriveConfig
from gateway.model import DesiredCommand, Device, DriveState, DriveStatus

DT = 0.05


def drive_config(drive_id: str = "ss1", **options: Any) -> DriveConfig:
    return DriveConfig(
        id=drive_id, bus="pb", device=Device.MCD600, address=5, options=Mcd600Options(**options)
    )


class Loop:
    def __init__(
        self,
        mode: Mode = Mode.BASIC,
        *,
        sim: Mcd600Sim | None = None,
        sim_params: dict[int, int] | None = None,
        drive_id: str = "ss1",
        **options: Any,
    ) -> None:
        self.profile = Mcd600Profile(drive_config(drive_id, mode=mode, **options))
        self.sim = sim or Mcd600Sim(mode, params=sim_params)
        if not self.sim.set_prm(self.profile.setup().user_prm):
            raise AssertionError("the simulator refused the profile's Set_Prm user data")
        self.now = 0.0
        self.desired = DesiredCommand()
        self.state = DriveState(id=drive_id, device=Device.MCD600, bus="pb", address=5)
        self.statuses: list[DriveStatus] = []
        self.controls: list[ControlWord] = []
        self.sent: list[bytes] = []  # every output telegram
        self.last: dict[str, Any] = {}

    def command(self, **changes: Any) -> None:
        self.desired = replace(self.desired, **changes)

    def fault_reset(self) -> None:
        self.command(fault_reset_seq=self.desired.fault_reset_seq + 1)

    def step(self, n: int = 1, dt: float = DT) -> DriveState:
        for _ in range(n):
            self.now += dt
            out = self.profile.outputs(self.desired, self.now)
            self.sent.append(out)
            self.controls.append(ControlWord.decode(out[:2]))
            inputs = self.sim.exchange(out, self.now)
            self.last = dict(self.profile.inputs(inputs, self.now))
            self.state = self.state.changed(**self.last)
            if not self.statuses or self.statuses[-1] is not self.state.status:
                self.statuses.append(self.state.status)
        return self.state

    def run_until(
        self, predicate: Callable[[DriveState], bool], limit: float = 60.0, dt: float = DT
    ) -> DriveState:
        end = self.now + limit
        while self.now < end:
            if predicate(self.step(dt=dt)):
                return self.state
        raise AssertionError(f"condition not reached in {limit} s; state {self.state}")

    def diag(self) -> list[Any]:
        """What the master does on a diagnosis: hand the device bytes to the profile."""
        data = self.sim.ext_diag()
        return self.profile.on_ext_diag(data) if data else []

    def reset_edges(self) -> int:
        bits = [c.reset for c in self.controls]
        return sum(1 for a, b in zip([False, *bits], bits, strict=False) if b and not a)


@contextlib.asynccontextmanager
async def running_bus(loop: Loop) -> AsyncIterator[None]:
    """Cycle the loop in the background while a parameter request awaits its answer."""

    async def pump() -> None:
        while True:
            loop.step()
            await asyncio.sleep(0)

    task = asyncio.create_task(pump(), name="mcd600-bus")
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
