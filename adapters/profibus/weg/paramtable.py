"""The WEG parameter tables: number, name, unit, decimal places and range, as data.

Each model's table is what its Profibus DP manual (the seed) gives: the parameters of its
"Parameters" section with their ranges (CFW-11 section 3, CFW700 section 4, CFW320 section
4), and the parameters the manual names elsewhere (status bits, examples, notes) with the
unit and decimal places its examples show ("P0003 = 4.7 A is sent as 47", "P0100 = 5.0 s as
50"). The seeds are not the programming manuals: a parameter the project uses that no seed
names, or a range no seed gives, is marked below in :data:`NOT_IN_SEEDS` and listed in
docs/devices.md. Names are the CFW700 and CFW320 manuals' English ones; the CFW-11 manual is
in Portuguese and its names are those of the CFW700 twin where it has one, else translated.

Ranges are in the parameter's unit; None where the seed gives none. A raw value reaches the
front ends as :class:`gateway.adapter.ParamInfo` of the drive's capabilities
(``WegProfile.capabilities``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Final

from adapters.profibus.weg.spec import DECIMALS, SPECS
from gateway.adapter import ParamInfo, ParamTable, param_table
from gateway.model import Device

WORD: Final = (0, 0xFFFF)  # "0000h a FFFFh" / "0 to FFFF (hexa)"
SIGNED_WORD: Final = (-32768, 32767)
MAPPING: Final = (0, 1199)  # P0742-P0757 (P742-P749): "0 to 1199"

Row = tuple[int, str, str, tuple[float, float] | None]
"""(number, name, unit, range): decimals come from :data:`adapters.profibus.weg.spec.DECIMALS`."""

# Named in the seeds' examples, status bits and notes (one list for the three models: a
# number a model's seed does not name is in NOT_IN_SEEDS).
_NAMED: Final[tuple[Row, ...]] = (
    (2, "Motor speed", "rpm", None),  # 4.2.5 / 5.2.5 example: P0002 = 100 rpm
    (3, "Motor current", "A", None),  # P0742 description: P0003 = 4.7 A is 47
    (48, "Present alarm", "", None),  # P0680 bit 7 note
    (49, "Present fault", "", None),  # P0680 bit 15 note
    (100, "Acceleration time", "s", None),  # P0750 / P746 description: 5.0 s is 50
    (101, "Deceleration time", "s", None),  # P0680 bit 5: P0100 and P0101
    (102, "Acceleration time 2nd ramp", "s", None),  # P0680 bit 5: P0102 and P0103
    (103, "Deceleration time 2nd ramp", "s", None),
    (105, "1st/2nd ramp selection", "", None),  # section 3 / 4 list of command sources
    (134, "Maximum speed", "rpm", None),  # P0685 / P0741: 4000h = P0134
    (220, "Local/remote selection source", "", None),
    (221, "Speed reference selection - local", "", None),
    (222, "Speed reference selection - remote", "", None),
    (223, "Forward/reverse selection - local", "", None),
    (224, "Run/stop selection - local", "", None),
    (225, "JOG selection - local", "", None),
    (226, "Forward/reverse selection - remote", "", None),
    (227, "Run/stop selection - remote", "", None),
    (228, "JOG selection - remote", "", None),
    (402, "Motor rated speed", "rpm", None),  # CFW320 P681: 13-bit base (P402 or P403)
    (403, "Motor rated frequency", "Hz", None),  # CFW320 P685: 2000h = P403
)
# Named by the CFW-11 and CFW700 seeds only.
_CFW11_LIKE_NAMED: Final[tuple[Row, ...]] = (
    (10, "Output power", "kW", None),  # CFW-11 P0761 formula
    (23, "Software version", "", None),  # P0964 subindex 2
    (202, "Type of control", "", (0, 7)),  # P0684 bit 6 note; codes: docs/devices.md
    (401, "Motor rated current", "A", None),  # CFW-11 P0760 description
    (404, "Motor rated power", "kW", None),  # CFW-11 P0761 formula
)
# CFW-11 section 3 and CFW700 section 4, with their ranges.
_CFW11_LIKE_PROFIBUS: Final[tuple[Row, ...]] = (
    (313, "Communication error action", "", (0, 5)),
    (680, "Status word", "", WORD),
    (681, "Motor speed in 13 bits", "", SIGNED_WORD),
    (684, "Profibus control word", "", WORD),
    (685, "Profibus speed reference", "", SIGNED_WORD),
    (696, "Value 1 for analog outputs", "", SIGNED_WORD),
    (697, "Value 2 for analog outputs", "", SIGNED_WORD),
    (740, "Profibus DP communication status", "", (0, 6)),
    (741, "Profibus data profile", "", (0, 1)),
    *((742 + i, f"Profibus reading #{i + 3}", "", MAPPING) for i in range(8)),
    *((750 + i, f"Profibus writing #{i + 3}", "", MAPPING) for i in range(8)),
    (922, "Selection of the configuration telegram", "", (1, 9)),
    (944, "Inverter fault counter", "", (0, 1)),
    (947, "Fault number", "", (0, 999)),
    (963, "Profibus baud rate detection", "", (0, 11)),
    (964, "Drive identification", "", WORD),
    (965, "PROFIdrive profile identification", "", WORD),
    (967, "PROFIdrive control word", "", WORD),
    (968, "PROFIdrive status word", "", WORD),
)
_CFW11_ONLY: Final[tuple[Row, ...]] = (
    (695, "Value for the digital outputs", "", WORD),  # "0000h a FFFFh"
    (698, "Value 3 for analog outputs", "", SIGNED_WORD),
    (699, "Value 4 for analog outputs", "", SIGNED_WORD),
    (760, "PROFIdrive output current", "", (0, 16384)),
    (761, "PROFIdrive output power", "", (0, 16384)),
    (762, "PROFIdrive output torque", "", (0, 16384)),
    (763, "PROFIdrive NAMUR status word", "", (0, 16384)),
    (799, "I/O update delay", "s", (0.0, 999.0)),
    (918, "Profibus address", "", (1, 125)),
)
_CFW700_ONLY: Final[tuple[Row, ...]] = (
    (695, "Digital output setting", "", (0, 0x1F)),  # "0000h to 001Fh"
    (918, "Profibus address", "", (1, 126)),
)
# CFW320 section 4 (its own names), and the parameters it names elsewhere.
_CFW320: Final[tuple[Row, ...]] = (
    (28, "Accessory identification", "", None),  # 6.1 step 2 (range not in the seed)
    (313, "Action for communic. error", "", (0, 5)),
    (680, "Logical status", "", WORD),
    # P681, P685, P696, P697: "0 to FFFF (hexa)"; the values are signed 13-bit speeds and
    # analog values (P681 text: "-32768 to 32767"), read as signed like the CFW-11's (SIGNED)
    (681, "13-bit speed", "", SIGNED_WORD),
    (684, "CO/DN/DP/ETH control", "", WORD),
    (685, "CO/DN/DP/ETH speed ref", "", SIGNED_WORD),
    (695, "DOx value", "", (0, 0xF)),
    (696, "AOx value 1", "", SIGNED_WORD),
    (697, "AOx value 2", "", SIGNED_WORD),
    (740, "Profibus comm. status", "", (0, 6)),
    (741, "Profibus data profile", "", (0, 1)),  # Table 4.6 note; range: docs/devices.md
    *((742 + i, f"Profibus read word #{i + 3}", "", MAPPING) for i in range(4)),
    *((746 + i, f"Profibus write word #{i + 3}", "", MAPPING) for i in range(4)),
    (750, "Profibus address", "", (1, 126)),
    (751, "Profibus teleg. sel.", "", (1, 5)),
    (754, "Profibus baud rate", "", (0, 11)),
)


def _infos(device: Device, rows: Iterable[Row]) -> ParamTable:
    spec = SPECS[device]
    infos = []
    for number, name, unit, limits in rows:
        low, high = limits if limits is not None else (None, None)
        infos.append(
            ParamInfo(
                number=number,
                name=name,
                unit=unit,
                decimals=DECIMALS.get(number, 0),
                minimum=low,
                maximum=high,
                code=spec.pname(number),
            )
        )
    return param_table(sorted(infos, key=lambda info: info.number))


PARAM_TABLES: Final[Mapping[Device, ParamTable]] = MappingProxyType(
    {
        Device.CFW11: _infos(
            Device.CFW11, (*_NAMED, *_CFW11_LIKE_NAMED, *_CFW11_LIKE_PROFIBUS, *_CFW11_ONLY)
        ),
        Device.CFW700: _infos(
            Device.CFW700, (*_NAMED, *_CFW11_LIKE_NAMED, *_CFW11_LIKE_PROFIBUS, *_CFW700_ONLY)
        ),
        Device.CFW320: _infos(Device.CFW320, (*_NAMED, *_CFW320)),
    }
)
"""Device -> its parameter table (number -> :class:`gateway.adapter.ParamInfo`)."""

NOT_IN_SEEDS: Final[Mapping[Device, frozenset[int]]] = MappingProxyType(
    {
        Device.CFW11: frozenset({402, 403}),
        Device.CFW700: frozenset({2, 10, 401, 402, 403, 404}),
        Device.CFW320: frozenset({105}),
    }
)
"""Parameters of the tables that the model's seed does not name (docs/devices.md)."""
