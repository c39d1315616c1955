"""Which simulated device stands for which device model, and how one is built.

:data:`SIM_DEVICES` maps a device to the "module:Class" of its simulator, from the device
registry (:mod:`gateway.devices`), imported lazily (the MCD 600 lives in its own package).
Every simulator class is a :class:`adapters.profibus.contract.SimFactory`: its
``for_drive(drive)`` builds the device a configured drive describes, or a default one for
``None``; :func:`make_device` calls it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from gateway.loader import load
from gateway.model import Device

if TYPE_CHECKING:
    from adapters.profibus.contract import SimDevice, SimFactory
    from gateway.config import DriveConfig

BUS: Final = "profibus"

SIM_DEVICES: Final[Mapping[Device, str]] = {
    d: d.spec.simulator for d in Device if d.spec.bus == BUS and d.spec.simulator
}
"""Device -> "module:Class" of its simulator (the registry's Profibus devices)."""

KINDS: Final[Mapping[str, Device]] = {d.spec.cli: d for d in SIM_DEVICES if d.spec.cli}
"""Names of the simulated devices on the command line."""


def with_setup(sim: SimDevice, device: Device, override: Any) -> SimDevice:
    """``sim`` behind the GSD file of a drive's config (``SetupOverride``), if it has one."""
    gsd = getattr(override, "gsd", None)
    if gsd is None:
        return sim
    from adapters.profibus.sim.gsdsim import GsdSim

    modules = tuple(getattr(override, "modules", ()))
    wrapped: SimDevice = GsdSim(sim, gsd, modules=modules)
    return wrapped


def sim_class(device: Device, table: Mapping[Device, str] = SIM_DEVICES) -> SimFactory:
    """The simulator class of ``device`` (ImportError / LookupError when there is none)."""
    try:
        target = table[device]
    except KeyError:
        raise LookupError(f"no simulated {device.value}") from None
    factory: SimFactory = load(target)
    return factory


def make_device(
    device: Device,
    drive: DriveConfig | None = None,
    table: Mapping[Device, str] = SIM_DEVICES,
) -> SimDevice:
    """A simulated ``device``, set up as ``drive`` describes when it is given."""
    return sim_class(device, table).for_drive(drive)
