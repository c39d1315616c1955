"""A simulated DeviceNet line: the link factory the composition root gives the DeviceNet
adapter for ``simulate = true`` (the production adapter never imports a simulator).

The adapter opens its link on the configured in-process channel (``interface =
"virtual"``); once it is open, :meth:`SimulatedBus.start` runs the bus's drives as
simulated CFW-08 nodes (:class:`~adapters.devicenet.sim.runner.SimRunner`) on the same
channel, and :meth:`SimulatedBus.stop` ends them after the adapter has left the line.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Final

from adapters.devicenet.frame import CanFrame
from adapters.devicenet.link import CanLink, LinkConfig
from adapters.devicenet.options import BusOptions, DriveOptions
from adapters.devicenet.sim.node import SimNodeConfig
from adapters.devicenet.sim.objects import identity_from_eds
from adapters.devicenet.sim.runner import SimRunner
from adapters.link.can import CanLinks
from gateway.config import BusConfig

SIM_START_BOUND: Final = 2.0  # s
SIM_DEFAULT_MAX_RPM: Final = 1800.0


def sim_configs(bus: BusConfig) -> list[SimNodeConfig]:
    """The simulated node of each configured drive (its ``sim_*`` keys, else what the
    drive's config says it is)."""
    options: BusOptions = bus.options
    out = []
    for d in bus.drives:
        o: DriveOptions = d.options
        s = o.sim
        out.append(
            SimNodeConfig(
                mac=d.address,
                p710=s.p710 if s.p710 is not None else o.assembly.p710,
                p710_stored=s.p710_stored,
                p313=s.p313,
                max_rpm=s.max_rpm or o.max_rpm or SIM_DEFAULT_MAX_RPM,
                ramp_time=s.ramp_time,
                weg_speed_scale=o.weg_speed_scale,
                product_code=o.product_code if o.product_code is not None else 8,
                dupmac_timeout=options.dupmac_timeout,
                identity=None if o.eds is None else identity_from_eds(o.eds),
                io_sizes=o.io_sizes,
            )
        )
    return out


class SimulatedBus(CanLinks[CanFrame]):
    """The bus's drives simulated on its in-process channel (see the module docstring)."""

    def __init__(self, bus: BusConfig) -> None:
        options: BusOptions = bus.options
        self.name = bus.name
        self.config = LinkConfig(options.interface, options.channel, options.bitrate)
        self.nodes = sim_configs(bus)
        self.runner: SimRunner | None = None
        """The simulated nodes while the line runs (tests inject faults through it)."""
        self._task: asyncio.Task[None] | None = None

    def link(self) -> CanLink:
        return CanLink(self.config)

    async def start(self) -> None:
        runner = SimRunner(LinkConfig("virtual", self.config.channel), self.nodes)
        self.runner = runner
        task = self._task = asyncio.create_task(runner.run(), name=f"devicenet-sim-{self.name}")
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(SIM_START_BOUND):
                await runner.started.wait()
        if task.done():
            task.result()  # raises what broke the simulator

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
