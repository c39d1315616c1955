"""The device registry: every device model the gateway knows, declared once.

One :class:`DeviceSpec` per device is its whole registration: the model name (the config's
``device`` value and the published one), its Modbus device code, the bus adapter whose line
carries it, its package, its profile and simulator as ``"module:Class"`` (imported late:
the core never imports an adapter), its name on the simulators' command lines and its
docs entry. The :class:`Device` enum is the registry (a member per registration, so mypy
knows every model by name), and every map of the core and of the adapters derives from it:
the Modbus device codes, the key docs, ``PROFILES``, ``SIM_DEVICES``/``KINDS``, an adapter's
``devices``, the layering test's lists and the table in docs/architecture.md. Adding a
device on an existing bus is its own package plus one member here (docs/architecture.md).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from enum import Enum
from pathlib import Path


@dataclass(frozen=True, slots=True)
class DeviceSpec:
    """One device's registration (see the module docstring).

    ``bus``: the name of the adapter whose line carries it (``gateway.config.ADAPTERS``).
    ``package``: where its code lives (the layering test reads it). ``profile``: the class
    the bus adapter builds per drive ("" where the adapter still holds the device's logic:
    the CFW-08 until DeviceNet has a profile contract). ``simulator``: the class whose
    ``for_drive(drive)`` builds the simulated device of a configured drive, or a default
    one for ``None`` (the Profibus ``SimFactory``; "" where the bus adapter chooses its
    simulator itself). ``cli``: its name on ``drive-gateway sim <bus>``. ``doc``: its line
    in docs/architecture.md. ``gsd_names``: what a GSD file's Model_Name says for it
    (casefolded parts; ``drive-gateway profibus scan --gsd-dir`` matches them).
    ``firmware_param``: the parameter holding its firmware version, as its manual says (a
    parameter backup names the firmware with it; None: the gateway reads it elsewhere, or
    cannot). ``test``: a device of the tests, in no adapter's production set and in no
    published list. ``code_digits``: its fault and alarm codes are written in hex with this
    many digits, as its documents write them (CANopen EMCY codes: 4, ``0x8130``); 0: in
    decimal, as the WEG and Danfoss manuals number their faults (F021, trip 26).
    """

    model: str
    code: int
    bus: str
    package: str
    profile: str = ""
    simulator: str = ""
    cli: str = ""
    doc: str = ""
    gsd_names: tuple[str, ...] = ()
    firmware_param: int | None = None
    soft_starter: bool = False
    test: bool = False
    code_digits: int = 0


class Device(Enum):
    """The device models the gateway knows (the value is the model name)."""

    _value_: str
    spec: DeviceSpec

    CFW11 = DeviceSpec(
        "CFW-11",
        code=1,
        bus="profibus",
        package="adapters.profibus.weg",
        profile="adapters.profibus.weg.cfw11:Cfw11Profile",
        simulator="adapters.profibus.weg.sim.drive:Cfw11Sim",
        cli="cfw11",
        doc="WEG CFW-11 frequency inverter (docs/devices.md, WEG CFW-11 / CFW700 / CFW320)",
        gsd_names=("cfw-11", "cfw11"),
        # CFW-11 manual P0964: "versão de firmware do equipamento (P0023)"
        firmware_param=23,
    )
    CFW700 = DeviceSpec(
        "CFW700",
        code=2,
        bus="profibus",
        package="adapters.profibus.weg",
        profile="adapters.profibus.weg.cfw700:Cfw700Profile",
        simulator="adapters.profibus.weg.sim.drive:Cfw700Sim",
        cli="cfw700",
        doc="WEG CFW700 frequency inverter (docs/devices.md, WEG CFW-11 / CFW700 / CFW320)",
        gsd_names=("cfw700", "cfw-700"),
        # CFW700 manual P0964: "Sub-index 2: Version (software) = equipment firmware
        # version (P0023)"
        firmware_param=23,
    )
    CFW320 = DeviceSpec(
        "CFW320",
        code=3,
        bus="profibus",
        package="adapters.profibus.weg",
        profile="adapters.profibus.weg.cfw320:Cfw320Profile",
        simulator="adapters.profibus.weg.sim.drive:Cfw320Sim",
        cli="cfw320",
        doc="WEG CFW320 frequency inverter (docs/devices.md, WEG CFW-11 / CFW700 / CFW320)",
        gsd_names=("cfw320", "cfw-320"),
    )
    CFW08 = DeviceSpec(
        "CFW-08",
        code=4,
        bus="devicenet",
        package="adapters.devicenet.cfw08",
        profile="adapters.devicenet.cfw08.profile:Cfw08Profile",
        doc="WEG CFW-08 frequency inverter (docs/devices.md, WEG CFW-08 (DeviceNet))",
    )
    MCD600 = DeviceSpec(
        "MCD 600",
        code=5,
        bus="profibus",
        package="adapters.mcd600",
        profile="adapters.mcd600.profile:Mcd600Profile",
        simulator="adapters.mcd600.sim.starter:Mcd600Sim",
        cli="mcd600",
        doc="Danfoss VLT MCD 600 soft starter (docs/devices.md, Danfoss VLT MCD 600)",
        soft_starter=True,
        gsd_names=("mcd 600", "mcd600", "mcd6"),
    )
    CIA402 = DeviceSpec(
        "CiA 402",
        code=6,
        bus="canopen",
        package="adapters.canopen",
        doc="a drive of the CiA 402 profile on CANopen (docs/devices.md, CiA 402 drives (CANopen))",
        code_digits=4,  # EMCY error codes and 0x603F, CiA 301 §7.2.7.1
    )
    TEST = DeviceSpec(
        "test",
        code=255,
        bus="profibus",
        package="adapters.profibus.sim",
        simulator="adapters.profibus.sim.echo:EchoSim",
        cli="echo",
        doc="echo slave of the tests and the demo line tools",
        test=True,
    )

    def __new__(cls, spec: DeviceSpec | str) -> Device:
        # builds the members from their registrations; a str is the lookup by model name,
        # ``Device("CFW-11")``, which the Enum machinery answers without coming here
        if not isinstance(spec, DeviceSpec):
            raise TypeError(f"a device is registered with a DeviceSpec, not {spec!r}")
        member = object.__new__(cls)
        member._value_ = spec.model
        member.spec = spec
        return member

    @property
    def value(self) -> str:
        """The model name (the config's ``device`` and the published one)."""
        return self._value_

    @property
    def is_soft_starter(self) -> bool:
        return self.spec.soft_starter


def code_text(device: Device | str | None, code: int) -> str:
    """A fault or alarm code of ``device`` (a member, or its model name as the state JSON
    gives it) as its documents write it: ``0x8130`` for a CANopen drive, ``21`` for a WEG
    one; a model not known here: decimal."""
    if not isinstance(device, Device):
        try:
            device = Device(str(device))
        except ValueError:
            return str(code)
    digits = device.spec.code_digits
    return f"0x{code:0{digits}X}" if digits and code >= 0 else str(code)


def devices_of(bus: str) -> frozenset[Device]:
    """The production devices of a bus adapter (its ``devices``)."""
    return frozenset(d for d in Device if d.spec.bus == bus and not d.spec.test)


def published() -> tuple[Device, ...]:
    """The devices the northbound docs list, in registry order (no test device)."""
    return tuple(d for d in Device if not d.spec.test)


def registry_table() -> list[str]:
    """The registry as the Markdown table of docs/architecture.md (a test checks it)."""
    rows = [
        "| device | model | Modbus code | bus | package | profile | simulator | CLI | docs |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for d in Device:
        s = d.spec
        cells = (d.name, s.model, str(s.code), s.bus, s.package, s.profile, s.simulator, s.cli)
        code = [f"`{c}`" if c else "" for c in cells]
        rows.append("| " + " | ".join([*code, s.doc]) + " |")
    return rows


TABLE_START = (
    "<!-- registry table: generated by gateway.devices.registry_table(), checked by a test -->"
)
TABLE_END = "<!-- end of the registry table -->"


def with_registry_table(text: str) -> str:
    """``text`` (docs/architecture.md) with the table between its markers rewritten."""
    head, start, rest = text.partition(TABLE_START + "\n")
    _, end, tail = rest.partition(TABLE_END)
    if not start or not end:
        raise ValueError("the registry table's markers are missing")
    return head + start + "\n".join(registry_table()) + "\n" + end + tail


def main(argv: list[str] | None = None) -> int:
    """``python -m gateway.devices FILE``: rewrite the registry table of FILE
    (docs/architecture.md) in place."""
    parser = argparse.ArgumentParser(prog="python -m gateway.devices")
    parser.add_argument("file", type=Path, help="the notes to rewrite: docs/architecture.md")
    path: Path = parser.parse_args(argv).file  # a usage error exits 2 with the usage
    path.write_text(with_registry_table(path.read_text()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
