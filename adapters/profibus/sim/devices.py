"""Which simulated device stands for which device model, and how one is built.

:data:`SIM_DEVICES` maps a device to the "module:Class" of its
:class:`adapters.profibus.profile.SimDevice`, imported lazily (the MCD 600 lives in its own
package). :func:`make_device` builds one for a configured drive, programmed as the drive's config
says: with the class's ``for_drive(drive)`` when it has one, else its
``matching(options, address=...)``, else the constructor keywords whose names the drive's
profile options share (``mode``, ``ident_number``..., and ``address``), else no arguments.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from gateway.model import Device

if TYPE_CHECKING:
    from adapters.profibus.profile import SimDevice
    from gateway.config import DriveConfig

SIM_DEVICES: Final[Mapping[Device, str]] = {
    Device.CFW11: "adapters.profibus.weg.sim:Cfw11Sim",
    Device.CFW700: "adapters.profibus.weg.sim:Cfw700Sim",
    Device.CFW320: "adapters.profibus.weg.sim:Cfw320Sim",
    Device.MCD600: "adapters.mcd600.sim:Mcd600Sim",
    Device.TEST: "adapters.profibus.sim.echo:EchoSim",
}

KINDS: Final[Mapping[str, Device]] = {
    "cfw11": Device.CFW11,
    "cfw700": Device.CFW700,
    "cfw320": Device.CFW320,
    "mcd600": Device.MCD600,
    "echo": Device.TEST,
}
"""Names of the simulated devices on the command line."""


FORWARD_PRM: Final = frozenset({Device.MCD600})
"""Devices whose simulator reads the Set_Prm user data itself (the MCD 600's timeout byte)."""


def with_setup(sim: SimDevice, device: Device, override: Any) -> SimDevice:
    """``sim`` behind the GSD file of a drive's config (``SetupOverride``), if it has one."""
    gsd = getattr(override, "gsd", None)
    if gsd is None:
        return sim
    from .gsdsim import GsdSim

    modules = tuple(getattr(override, "modules", ()))
    wrapped: SimDevice = GsdSim(sim, gsd, forward_prm=device in FORWARD_PRM, modules=modules)
    return wrapped


def sim_class(device: Device, table: Mapping[Device, str] = SIM_DEVICES) -> Any:
    """The SimDevice class of ``device`` (ImportError / LookupError when there is none)."""
    try:
        target = table[device]
    except KeyError:
        raise LookupError(f"no simulated {device.value}") from None
    module_name, _, class_name = target.partition(":")
    module = importlib.import_module(module_name)
    try:
        return getattr(module, class_name)
    except AttributeError:
        raise LookupError(f"{module_name} has no {class_name}") from None


def make_device(
    device: Device,
    drive: DriveConfig | None = None,
    table: Mapping[Device, str] = SIM_DEVICES,
) -> SimDevice:
    """A simulated ``device``, set up as ``drive`` describes when it is given."""
    cls = sim_class(device, table)
    if drive is None:
        made: SimDevice = cls()
        return made
    for_drive = getattr(cls, "for_drive", None)
    if callable(for_drive):
        built: SimDevice = for_drive(drive)
        return built
    matching = getattr(cls, "matching", None)
    if callable(matching) and drive.options is not None:
        programmed: SimDevice = matching(drive.options, address=drive.address)
        return programmed
    matched: SimDevice = cls(**_shared_options(cls, drive))
    return matched


def _shared_options(cls: Any, drive: DriveConfig) -> dict[str, Any]:
    """Constructor keywords that the profile options (or the drive) carry by the same name."""
    try:
        params = inspect.signature(cls).parameters
    except (TypeError, ValueError):
        return {}
    out: dict[str, Any] = {}
    for name, param in params.items():
        if param.kind not in (param.KEYWORD_ONLY, param.POSITIONAL_OR_KEYWORD):
            continue
        value = getattr(drive.options, name, None)
        if value is None and name == "address":
            value = drive.address
        if isinstance(param.default, int) and isinstance(value, float) and value.is_integer():
            value = int(value)  # 52.0 A configured, an int wanted
        if value is not None:
            out[name] = value
    return out
