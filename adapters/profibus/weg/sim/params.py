"""The simulated drives' parameter tables: every parameter the three manuals name.

Each entry: default, range, read-only (RO), change only with the motor stopped (CFG),
signed, written only through the cyclic words ("network only": P0684, P0685, P0967 behave
as read-only for every other source, and we count DP-V1 records as another source).
Live parameters (speeds, currents, status words...) are computed by the simulator.

Ranges and defaults are the manuals' where they give them (cited); the rest are the
simulator's choices, listed in docs/devices.md. Values are raw words: P0100 = 200 is 20.0 s.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from adapters.profibus.weg.spec import (
    CFW11_CONTROL_TYPES,
    CFW700_CONTROL_TYPES,
    DEFAULT_CONTROL_TYPE,
)
from gateway.model import Device


@dataclass(frozen=True)
class ParamSpec:
    number: int
    default: int = 0
    low: int = 0
    high: int = 0xFFFF
    read_only: bool = False
    cfg: bool = False
    signed: bool = False
    network_only: bool = False
    live: bool = False  # the simulator computes the value
    array: int = 0  # number of subindices (P0964: 5)


def rw(number: int, default: int, low: int, high: int, *, cfg: bool = False) -> ParamSpec:
    return ParamSpec(number, default, low, high, cfg=cfg)


def ro(number: int, default: int = 0, *, live: bool = True) -> ParamSpec:
    return ParamSpec(number, default, read_only=True, live=live)


def signed_rw(number: int) -> ParamSpec:
    return ParamSpec(number, 0, -32768, 32767, signed=True)


def net(number: int, *, signed: bool = False) -> ParamSpec:
    low, high = (-32768, 32767) if signed else (0, 0xFFFF)
    return ParamSpec(number, 0, low, high, signed=signed, network_only=True, live=True)


def _table(specs: Iterable[ParamSpec]) -> Mapping[int, ParamSpec]:
    return MappingProxyType({p.number: p for p in specs})


# Command-source option numbers (P0105, P0220-P0228). The manuals name the sources
# ("CANopen/DeviceNet/Profibus DP" options) but not their numbers: the simulator numbers
# them as below for the three models (docs/devices.md). NETWORK_SOURCES gives the network
# the remote situation (run/stop, reference, direction, JOG, 2nd ramp) with LOC/REM
# chosen by P0684 bit 4 / STW1 bit 10, and leaves local to the HMI.
SRC_LOCREM_ALWAYS_LOCAL: Final = 0
SRC_LOCREM_ALWAYS_REMOTE: Final = 1
SRC_LOCREM_NET_LOC: Final = 9  # CO/DN/DP, local at power-up
SRC_LOCREM_NET_REM: Final = 10  # CO/DN/DP, remote at power-up
SRC_REF_NET: Final = 11  # P0221/P0222
SRC_DIR_FORWARD: Final = 0  # P0223/P0226 "always forward"
SRC_DIR_REVERSE: Final = 1
SRC_DIR_NET: Final = (9, 10)  # CO/DN/DP (forward / reverse at power-up)
SRC_RUN_NET: Final = 4  # P0224/P0227
SRC_JOG_NET: Final = 5  # P0225/P0228
SRC_RAMP_SECOND: Final = 1  # P0105 "2nd ramp"
SRC_RAMP_NET: Final = 5  # P0105 CO/DN/DP

NETWORK_SOURCES: Final[Mapping[int, int]] = MappingProxyType(
    {
        105: SRC_RAMP_NET,
        220: SRC_LOCREM_NET_REM,
        222: SRC_REF_NET,
        226: SRC_DIR_NET[0],
        227: SRC_RUN_NET,
        228: SRC_JOG_NET,
    }
)

JOG_RPM: Final = 150.0  # JOG speed of the simulator (the JOG reference is not in the seeds)


def _sources() -> list[ParamSpec]:
    """P0105 and P0220-P0228 (CFW-11/CFW700 section 3/4 "P0105, P0220 ... P0228")."""
    return [
        rw(105, 0, 0, 6),
        rw(220, 2, 0, 12, cfg=True),
        rw(221, 0, 0, 12, cfg=True),
        rw(222, 1, 0, 12, cfg=True),
        rw(223, 2, 0, 12, cfg=True),
        rw(224, 0, 0, 5, cfg=True),
        rw(225, 1, 0, 6, cfg=True),
        rw(226, 4, 0, 12, cfg=True),
        rw(227, 1, 0, 5, cfg=True),
        rw(228, 2, 0, 6, cfg=True),
    ]


def _motor_and_ramps() -> list[ParamSpec]:
    return [
        rw(100, 200, 0, 9990),  # acceleration time, 0.0-999.0 s (P0750 example: 5.0 s = 50)
        rw(101, 200, 0, 9990),  # deceleration time
        rw(102, 200, 0, 9990),  # 2nd ramp (P0680 bit 5)
        rw(103, 200, 0, 9990),
        rw(134, 1800, 0, 18000),  # maximum speed, rpm (P0741: 4000h = P0134 = 1800 rpm)
        rw(401, 100, 0, 60000, cfg=True),  # motor rated current, 10.0 A
        rw(402, 1750, 0, 18000, cfg=True),  # motor rated speed, rpm
        rw(403, 60, 0, 300, cfg=True),  # motor rated frequency, Hz
        # auto-reset time, s, 0 = off: the programming manuals' P0206 / P206 (not among the
        # seeds; range 0-255 s as there, the simulator resets any fault: docs/devices.md)
        rw(206, 0, 0, 255),
    ]


def _cfw11_like(device: Device) -> list[ParamSpec]:
    cfw11 = device is Device.CFW11
    control_types = CFW11_CONTROL_TYPES if cfw11 else CFW700_CONTROL_TYPES
    specs = [
        ro(2),  # motor speed (4.2.5 example)
        ro(3),  # motor current (P0742 description)
        ro(10),  # output power (P0761)
        ro(23, 500, live=False),  # firmware version 5.00 (P0964 subindex 2)
        ro(48),  # present alarm (Table 3.2 bit 7)
        ro(49),  # present fault (Table 3.2 bit 15)
        *_motor_and_ramps(),
        # control type (P0684 bit 6 note), the WEG programming manuals' codes (spec.py):
        # the simulator starts in sensorless vector (docs/devices.md)
        rw(202, DEFAULT_CONTROL_TYPE, 0, max(control_types), cfg=True),
        *_sources(),
        rw(313, 0, 0, 5, cfg=True),  # Table 3.3.1 / 4.1: default 0, CFG
        rw(404, 55, 0, 9999, cfg=True),  # motor rated power, 5.5 kW (our reading)
        ro(680),
        ro(681),
        net(684),
        net(685, signed=True),
        ro(692),  # special operation mode (Table 3.2 bit 6 note)
        rw(695, 0, 0, 0xFFFF if cfw11 else 0x1F),  # CFW-11 0000h-FFFFh, CFW700 0-1Fh
        signed_rw(696),
        signed_rw(697),
        ro(740),
        rw(741, 1, 0, 1),  # data profile, default 1 = manufacturer
        *(rw(n, 0, 0, 1199) for n in range(742, 758)),  # P0742-P0757, 0 to 1199
        rw(918, 1, 1, 125 if cfw11 else 126),  # CFW-11 1-125, CFW700 1-126
        rw(922, 1, 1, 9),  # telegram, default 1 (2 words)
        ro(944),
        ro(947),
        ro(963, 1, live=False),  # detected baud rate (CFW-11 "Padrão: 1")
        ParamSpec(964, 367, read_only=True, live=True, array=5),
        ro(965, 809, live=False),  # 3 << 8 | 41 = PROFIdrive 4.1
        net(967),
        ro(968),
    ]
    if cfw11:
        specs += [
            rw(251, 0, 0, 255),  # analog output functions (P0696 description)
            rw(254, 0, 0, 255),
            rw(257, 0, 0, 255),
            rw(260, 0, 0, 255),
            *(rw(n, 0, 0, 255) for n in range(275, 281)),  # P0275-P0280 DO functions
            signed_rw(698),
            signed_rw(699),
            *(ro(n) for n in (760, 761, 762, 763)),  # PROFIdrive current, power, torque, NAMUR
            rw(799, 0, 0, 9990),  # I/O update delay 0.0-999.0 s
        ]
    else:
        specs += [
            rw(251, 0, 0, 255),
            rw(254, 0, 0, 255),
            *(rw(n, 0, 0, 255) for n in range(275, 280)),  # P0275-P0279
        ]
    return specs


def _cfw320() -> list[ParamSpec]:
    return [
        ro(2),
        ro(3),
        ro(6),  # inverter status (section 7 "Fault and alarm operation")
        ro(28, 1, live=False),  # accessory identification (6.1 step 2)
        ro(48),
        ro(49),
        *_motor_and_ramps(),
        *_sources(),
        rw(251, 0, 0, 255),
        rw(254, 0, 0, 255),
        rw(308, 1, 1, 247),  # serial settings: keep factory settings (2.4 warning)
        rw(310, 0, 0, 255),
        rw(311, 0, 0, 255),
        rw(312, 0, 0, 255),
        rw(313, 1, 0, 5, cfg=True),  # Table 4.1, factory setting 1
        ro(680),
        ro(681),
        net(684),
        net(685, signed=True),
        rw(695, 0, 0, 0xF),  # DO1-DO4
        signed_rw(696),
        signed_rw(697),
        ro(740),
        # data profile: the CFW320 manual names P741 (Table 4.6 note, 6.2 step 3) without its
        # table; the CFW-11/CFW700 coding (0 = PROFIdrive, 1 = manufacturer, factory 1) is
        # taken (docs/devices.md). The simulator's words stay the manufacturer's either way.
        rw(741, 1, 0, 1),
        *(rw(n, 0, 0, 1199) for n in range(742, 750)),  # P742-P749, 0 to 1199
        rw(750, 1, 1, 126),  # address, 1 to 126, factory setting 1
        rw(751, 1, 1, 5),  # telegram, Table 4.7: 1-5, factory setting 1
        ro(754, 0, live=False),  # detected baud rate, Table 4.8
    ]


PARAMETERS: Final[Mapping[Device, Mapping[int, ParamSpec]]] = MappingProxyType(
    {
        Device.CFW11: _table(_cfw11_like(Device.CFW11)),
        Device.CFW700: _table(_cfw11_like(Device.CFW700)),
        Device.CFW320: _table(_cfw320()),
    }
)
