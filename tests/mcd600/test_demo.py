"""The demo's MCD 600: extended mode, Modbus unit 4, on the Profibus line of the WEG drives."""

from __future__ import annotations

from dataclasses import replace

from adapters.mcd600.layout import Mode
from adapters.mcd600.options import Mcd600Options
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.options import DriveOptions
from adapters.profibus.sim.devices import make_device
from gateway.config import DEFAULT_CONFIG, load
from gateway.model import Device


def test_the_demo_has_an_extended_mode_starter_on_the_weg_line() -> None:
    config = load(DEFAULT_CONFIG)
    (starter,) = [d for d in config.drives if d.device is Device.MCD600]
    assert (starter.id, starter.modbus_unit) == ("mcd600", 4)
    bus = next(b for b in config.buses if starter in b.drives)
    assert bus.adapter == "profibus" and bus.options.simulate
    others = {d.device for d in bus.drives} - {Device.MCD600}
    assert {Device.CFW11, Device.CFW700, Device.CFW320} <= others  # one mixed line
    assert isinstance(starter.options, DriveOptions)
    options = starter.options.profile
    assert isinstance(options, Mcd600Options) and options.mode is Mode.EXTENDED
    # the simulated starter the demo line builds is the one the table describes
    sim = make_device(Device.MCD600, replace(starter, options=options))
    assert isinstance(sim, Mcd600Sim) and sim.mode is Mode.EXTENDED
