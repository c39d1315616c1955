"""A simulated DeviceNet line: the link factory the composition root gives the DeviceNet
adapter for ``simulate = true`` (the production adapter never imports a simulator).

The adapter opens its link on the configured in-process channel (``interface =
"virtual"``); once it is open, :meth:`SimulatedBus.start` runs the bus's drives as
simulated CFW-08 nodes (:class:`~adapters.devicenet.sim.runner.SimRunner`) on the same
channel, and :meth:`SimulatedBus.stop` ends them after the adapter has left the line.
"""

from __future__ import annotations

from typing import Final

from adapters.can.simulated import SimulatedLine
from adapters.devicenet.cfw08.options import DriveOptions
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.link import CanLink, LinkConfig
from adapters.devicenet.options import BusOptions
from adapters.devicenet.sim.node import SimNodeConfig
from adapters.devicenet.sim.objects import identity_from_eds
from adapters.devicenet.sim.runner import SimRunner
from gateway.config import BusConfig

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


class SimulatedBus(SimulatedLine[CanFrame, SimRunner]):
    """The bus's drives simulated on its in-process channel (see the module docstring)."""

    def __init__(self, bus: BusConfig) -> None:
        options: BusOptions = bus.options
        config = LinkConfig(options.interface, options.channel, options.bitrate)
        super().__init__("devicenet", bus.name, config)
        self.nodes = sim_configs(bus)

    def link(self) -> CanLink:
        return CanLink(self.config)

    def new_runner(self) -> SimRunner:
        return SimRunner(LinkConfig("virtual", self.config.channel), self.nodes)
