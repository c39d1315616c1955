"""A simulated Profibus line: the link factory the composition root gives the Profibus
adapter for ``simulate = true`` (the production adapter never imports a simulator).

:meth:`SimulatedLine.start` builds a simulated device for each configured drive (its
simulator as :data:`~adapters.profibus.sim.devices.SIM_DEVICES` says, programmed as the
drive's config says, behind its GSD file where the config names one), puts them on one
:class:`~adapters.profibus.sim.line.SimLine` behind a pty pair
(:class:`~adapters.profibus.sim.port.SimPort`) and returns the master's end; the adapter
opens that like a real port. :meth:`settle` lets the slaves answer what was sent last
(the Clear on leaving), :meth:`close` ends them.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping

from adapters.profibus.link import SerialLink, SerialLinks, open_link
from adapters.profibus.options import BusOptions, profile_config
from adapters.profibus.sim.devices import SIM_DEVICES, make_device, with_setup
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.port import SimPort
from adapters.profibus.sim.slave import DpSlave
from gateway.config import BusConfig
from gateway.errors import AdapterError
from gateway.model import Device

log = logging.getLogger(__name__)


class SimulatedLine(SerialLinks):
    """The bus's drives simulated on a pty pair (see the module docstring)."""

    def __init__(self, bus: BusConfig, sim_devices: Mapping[Device, str] = SIM_DEVICES) -> None:
        options: BusOptions = bus.options
        self.name = bus.name
        self.options = options
        self.drives = [profile_config(d) for d in bus.drives]
        self.sim_devices = sim_devices
        self.port: SimPort | None = None
        self.line: SimLine | None = None
        """The simulated slaves once started (tests inject faults through it)."""
        self.path: str | None = None

    def far_end_apart(self) -> bool:
        return False  # the simulated slaves answer from this loop

    def start(self) -> str:
        line = SimLine(
            DpSlave(
                config.address,
                with_setup(
                    make_device(config.device, config, self.sim_devices), config.device, override
                ),
                self.options.baudrate,
            )
            for config, override in self.drives
        )
        port, path = SimPort.on_pty(line)
        port.start()
        self.port, self.line, self.path = port, line, path
        log.info("%s: simulated line on %s (%d slaves)", self.name, path, len(line.slaves))
        return path

    async def open(
        self,
        loop: asyncio.AbstractEventLoop,
        on_data: Callable[[bytes, float], None],
        on_error: Callable[[BaseException], None],
    ) -> SerialLink:
        if self.path is None:
            raise AdapterError(f"{self.name}: the simulated line is not started")
        return await open_link(
            self.path, self.options.baudrate, loop, on_data, on_error, rs485=self.options.rs485
        )

    async def settle(self) -> None:
        if self.port is not None:
            await self.port.settle()

    def close(self) -> None:
        port, self.port = self.port, None
        if port is not None:
            port.close()
