"""The DeviceNet profile contract: the adapter and the scanner name no device, and a
drive gets whatever profile its device registers (issue 21)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pytest

from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.cfw08.options import DriveOptions, parse_drive
from adapters.devicenet.cfw08.profile import Cfw08Profile
from adapters.devicenet.contract import PROFILES, DnProfile, DrivePort, load_profile
from adapters.devicenet.link import LinkConfig
from gateway.adapter import Capabilities, EventKind, ParamValue
from gateway.config import DriveConfig
from gateway.errors import ParameterError
from gateway.model import CommState, DesiredCommand, Device, Readings, SpeedScale
from gateway.schema import Table
from tests.devicenet.integration.conftest import drive, rig
from tests.test_layering import MODULES, under

DEVICE_PACKAGES = ("adapters.devicenet.cfw08",)


def test_the_adapter_and_the_scanner_import_no_device_package() -> None:
    bad = [
        f"{mod} imports {imp}"
        for mod, imports in MODULES.items()
        if under(mod, "adapters.devicenet.adapter", "adapters.devicenet.scanner")
        for imp in imports
        if under(imp, *DEVICE_PACKAGES)
    ]
    assert bad == []


def test_every_registered_profile_loads_and_is_a_dn_profile() -> None:
    assert DeviceNetAdapter.devices == frozenset(PROFILES)
    for device in PROFILES:
        factory = load_profile(device)
        assert factory.device is device and DnProfile in getattr(factory, "__mro__", ())
    assert load_profile(Device.CFW08) is Cfw08Profile


@dataclass
class PlainProfile(DnProfile):
    """A device with nothing but the required parts: no connect steps, fixed I/O."""

    device: ClassVar[Device] = Device.CFW08

    drive_id: str
    opts: DriveOptions

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> DriveOptions:
        return parse_drive(table, drive)

    @property
    def ready(self) -> bool:
        return True

    def capabilities(self) -> Capabilities | None:
        return Capabilities(speed_scale=SpeedScale(1500.0, 100.0, label="plain"))

    def outputs(self, desired: DesiredCommand, fault_reset: bool) -> bytes:
        return bytes(4)

    def inputs(self, data: bytes, desired: DesiredCommand) -> Readings:
        return {"running": False}

    async def read_param(self, port: DrivePort, number: int, subindex: int) -> ParamValue:
        raise ParameterError("plain: no parameters")

    async def write_param(
        self, port: DrivePort, number: int, subindex: int, value: ParamValue
    ) -> None:
        raise ParameterError("plain: no parameters")


async def test_a_drive_runs_the_profile_its_device_registers(
    can_line: LinkConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(PROFILES, Device.CFW08, f"{__name__}:PlainProfile")
    async with rig(can_line, [drive(6)]) as r:
        state = await r.wait("d6", lambda s: s.comm is CommState.ONLINE)
        assert isinstance(r.adapter.drives[6].profile, PlainProfile)
        # the defaults: no connect steps (no CFW-08 parameter was read), "configured"
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG)
        assert ev.text == "configured" and "P313" not in state.values
        scale = r.hub.capabilities("d6").speed_scale
        assert scale is not None and scale.label == "plain"
        with pytest.raises(ParameterError, match="no table of standard objects"):
            await r.adapter.read_object("d6", 0x01, 1, 1)
