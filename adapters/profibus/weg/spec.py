"""What differs between the CFW-11, the CFW700 and the CFW320 on Profibus DP, as data.

Each model follows its own manual: the CFW-11 manual (Portuguese seed, sections 3-5), the
CFW700 manual (sections 4-6) and the CFW320 manual (sections 4-7). Texts are the manuals'
own (the CFW-11's translated from Portuguese where the CFW700 manual has no English twin).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Final

from adapters.profibus.weg import words
from adapters.profibus.weg.words import BitTable
from gateway.model import Device


class DataProfile(Enum):
    """P0741 "Perfil de Dados Profibus" (CFW-11 Table 3.6, CFW700 Table 4.6).

    The CFW320 manual names P741 (Table 4.6 note, 6.2 step 3) without its values: the same
    coding is taken (docs/devices.md).
    """

    PROFIDRIVE = "profidrive"  # P0741 = 0
    MANUFACTURER = "manufacturer"  # P0741 = 1 (factory setting)

    @property
    def p0741(self) -> int:
        return 0 if self is DataProfile.PROFIDRIVE else 1


class CommAction(Enum):
    """P0313 "Action for communication error" (CFW-11 Table 3.3.1, CFW700 Table 4.1,
    CFW320 Table 4.1)."""

    INACTIVE = 0  # no action, the drive stays as it is
    RAMP_STOP = 1  # stop command on the deceleration ramp
    GENERAL_DISABLE = 2  # general enable removed: the motor coasts
    GO_TO_LOCAL = 3  # commands go to local
    LOCAL_KEEP = 4  # local, keeping the network's enable and reference
    FAULT = 5  # a fault (F238/F239...) instead of the alarm: needs a reset


COMM_ACTION_TEXTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        0: "inactive",
        1: "ramp stop",
        2: "general disable",
        3: "go to local",
        4: "go to local keeping commands and reference",
        5: "cause a fault",
    }
)

# The drive's own reaction to a lost master by P0313 (issue 32 item 5): True when the
# motor stops (1 ramp stop, 2 general disable: coasts, 5 a fault: needs a reset), False when
# it may keep turning (0 "remains in the existing status"; 3 local: the local sources take
# over, no stop; 4 local keeping the network's enable and reference). CFW-11 Table 3.3.1,
# CFW700 Table 4.1, CFW320 Table 4.1.
COMM_ACTION_FAILSAFE: Final[Mapping[int, bool]] = MappingProxyType(
    {0: False, 1: True, 2: True, 3: False, 4: False, 5: True}
)

# The control word sent until the drive's data profile (P0741) is verified at connect
# (issue 32 item 2): a stop in both profiles, with no JOG in either. Manufacturer P0684
# (CFW-11 Table 3.3, CFW700 Table 4.3, CFW320 Table 4.3): bit 0 = 0 ramp stop, bit 1 general
# enable, bit 2 forward, bit 3 = 0 no JOG, bit 4 remote, bit 6 = 0 no quick stop, bits 8-15
# reserved. PROFIdrive STW1 (CFW-11 Table 3.8, CFW700 Table 4.7): bit 0 = 0 OFF1, bit 1 no
# coast stop, bit 2 no quick stop, bit 3 = 0 operation disabled, bit 4 ramp generator,
# bit 6 = 0 setpoint zeroed, bit 8 = 0 no JOG, bit 10 control by PLC (remote). The reference
# word is 0 (no speed in either scale).
NEUTRAL_STOP_WORD: Final = 0x0416


# P0740 Profibus DP communication status: CFW-11 Table 3.5 / CFW700 Table 4.5.
CFW11_COMM_STATUS: Final[Mapping[int, str]] = MappingProxyType(
    {
        0: "inactive",
        1: "Profibus interface initialization error",
        2: "offline",
        3: "configuration data error",
        4: "parameterization data error",
        5: "clear mode",
        6: "online",
    }
)
# CFW320 P740, Table 4.5.
CFW320_COMM_STATUS: Final[Mapping[int, str]] = MappingProxyType(
    {
        0: "disabled",
        1: "access error",
        2: "offline",
        3: "config. error",
        4: "param. error",
        5: "clear mode",
        6: "online",
    }
)
COMM_ONLINE: Final = 6
COMM_OFFLINE: Final = 2
COMM_CFG_ERROR: Final = 3
COMM_PRM_ERROR: Final = 4
COMM_CLEAR: Final = 5

# CFW700 section 6 (English twin of CFW-11 section 5): A138/F238, A139/F239, A140/F240.
_PROFIBUS_ALARMS: Final = {
    138: "Profibus DP interface in clear mode",
    139: "Profibus DP interface offline",
    140: "Profibus DP module access error",
}
_PROFIBUS_FAULTS: Final = {code + 100: text for code, text in _PROFIBUS_ALARMS.items()}

CFW11_FAULTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        # CFW-11 P0763, Table 3.7 (VIK-NAMUR), the faults each bit names.
        22: "DC link overvoltage",
        51: "inverter overtemperature",
        54: "inverter overtemperature",
        57: "inverter overtemperature",
        65: "speed sensor fault",
        66: "speed sensor fault",
        71: "motor overload",
        72: "motor overload",
        74: "ground fault",
        80: "control electronics/software fault",
        229: "internal communication fault",
        230: "internal communication fault",
        **_PROFIBUS_FAULTS,  # section 5
    }
)
CFW700_FAULTS: Final[Mapping[int, str]] = MappingProxyType(dict(_PROFIBUS_FAULTS))  # section 6
CFW11_ALARMS: Final[Mapping[int, str]] = MappingProxyType(dict(_PROFIBUS_ALARMS))
CFW700_ALARMS: Final = CFW11_ALARMS

# CFW320 section 7 "Quick reference of alarms and faults" (no A140/F240; F032 instead).
CFW320_FAULTS: Final[Mapping[int, str]] = MappingProxyType(
    {
        32: "Comm. plug-in module communication lost",
        238: "Profibus DP interface in clear mode",
        239: "Offline Profibus DP interface",
    }
)
CFW320_ALARMS: Final[Mapping[int, str]] = MappingProxyType(
    {
        138: "Profibus DP interface in clear mode",
        139: "Offline Profibus DP interface",
    }
)


# P0202 "Type of control". The seeds name P0202 and its V/f and VVW types (CFW700 P0684
# bit 6 note, CFW-11 P0684 bit 6 "Obs.", P0967 bit 2 notes) but not its value table: the
# codes are those of the WEG programming manuals of the CFW-11 and CFW700 (docs/devices.md).
_CONTROL_TYPES: Final = {
    0: "V/f 60 Hz",
    1: "V/f 50 Hz",
    2: "V/f adjustable",
    3: "sensorless vector",
    4: "vector with encoder",
    5: "VVW",
}
CFW11_CONTROL_TYPES: Final[Mapping[int, str]] = MappingProxyType(
    {**_CONTROL_TYPES, 6: "PM vector with encoder", 7: "PM sensorless vector"}
)
CFW700_CONTROL_TYPES: Final[Mapping[int, str]] = MappingProxyType(dict(_CONTROL_TYPES))
VECTOR_CONTROL_TYPES: Final[frozenset[int]] = frozenset({3, 4, 6, 7})
DEFAULT_CONTROL_TYPE: Final = 3  # the simulators' P0202: sensorless vector


@dataclass(frozen=True)
class ModelSpec:
    """One model's Profibus DP facts."""

    device: Device
    pnu_digits: int  # how the manual writes numbers: P0680 (4) or P680 (3)
    address_param: int  # CFW-11/CFW700 P0918; CFW320 P750
    address_range: tuple[int, int]  # CFW-11 P0918 1-125; CFW700 P0918 1-126; CFW320 P750 1-126
    address_source: str  # where the manual gives the range
    address_needs_power_cycle: bool  # CFW-11 P0918 note; the others: when not exchanging
    telegram_param: int  # CFW-11/CFW700 P0922; CFW320 P751
    max_words: int  # CFW-11/CFW700 10 (P0922 1-9); CFW320 6 (P751 1-5)
    read_map_first: int  # P0742 (input words 3..)
    write_map_first: int  # CFW-11/CFW700 P0750; CFW320 P746 (output words 3..)
    profiles: frozenset[DataProfile]  # CFW320: its manual documents only the manufacturer's
    frame20: bool  # PROFIdrive frame type 20 with P0760-P0763 (CFW-11 Table 3.6 only)
    quick_stop: bool  # P0684 bit 6 (reserved on the CFW320)
    control_bits: BitTable
    status_bits: BitTable
    zsw1_bits: BitTable
    faults: Mapping[int, str]
    alarms: Mapping[int, str]
    comm_status: Mapping[int, str]
    fault_counter: bool  # P0944/P0947 (CFW-11, CFW700)
    comm_action_default: int  # P0313 factory setting: 0 (CFW-11, CFW700), 1 (CFW320)
    interface_fault: int | None  # CFW-11/CFW700 A140/F240; CFW320 F032 (always a fault)
    default_ident: int  # placeholder: the GSD file's Ident_Number is not in the seeds
    control_types: Mapping[int, str] = field(default_factory=dict)  # P0202 (none: not read)
    quick_stop_ignored_ramp_only: bool = False  # the drive ignores bit 6 in V/f or VVW
    # read P0741/P741 at connect whatever verify_mapping says: the words depend on it
    # (CFW-11 Table 3.6, CFW700 Table 4.6, CFW320 Table 4.6 note) and a word of the other
    # profile can be a motion command (issue 32 item 2); all three models set it
    reads_data_profile: bool = False
    baud_param: int = 963  # the detected baud rate: P0963 (CFW-11, CFW700); CFW320 P754
    # parameters the manual says must keep their factory settings, with the values taken
    # as factory (CFW320 2.4 WARNING: P308, P310, P311, P312; the values are the
    # programming manual's, not in the seed: a drive's ``factory_settings`` key says
    # otherwise); read at every connect, a difference is a config event
    factory_settings: Mapping[int, int] = field(default_factory=dict)

    @property
    def reads_control_type(self) -> bool:
        """True for the models whose quick stop depends on P0202 (CFW-11, CFW700)."""
        return bool(self.control_types)

    def quick_stop_as_ramp(self, control_type: int) -> bool:
        """True when P0202 = ``control_type`` is not a vector mode (V/f, VVW or unknown).

        CFW700 P0684 bit 6: "not allowed with control types (P0202) V/f or VVW"; CFW-11
        P0684 bit 6 and both P0967 bit 2: not recommended there. A value outside the table
        is taken as not vector (the ramp stop is the stop every control type allows).
        """
        return control_type not in VECTOR_CONTROL_TYPES or control_type not in self.control_types

    def control_type_text(self, control_type: int) -> str:
        text = self.control_types.get(control_type, "unknown control type")
        return f"{self.pname(202)} = {control_type} ({text})"

    def pname(self, number: int) -> str:
        """A parameter's name as the manual writes it (P0003, or P003 on the CFW320)."""
        return f"P{number:0{self.pnu_digits}d}"

    def telegram_code(self, n_words: int) -> int:
        """P0922/P751 value for ``n_words`` I/O words: 1 = 2 words ... (P0922 / Table 4.7)."""
        return n_words - 1

    def words_of(self, telegram_code: int) -> int:
        return telegram_code + 1

    @property
    def telegram_codes(self) -> range:
        return range(1, self.max_words)

    def read_map_param(self, word: int) -> int:
        """The parameter that programs input word ``word`` (3..N): P0742 + word - 3."""
        return self.read_map_first + word - 3

    def write_map_param(self, word: int) -> int:
        """The parameter that programs output word ``word`` (3..N)."""
        return self.write_map_first + word - 3

    def fault_text(self, code: int) -> str:
        """The manual's text, or the code as the drive shows it (never an invented text)."""
        return self.faults.get(code, f"F{code:03d}")

    def alarm_text(self, code: int) -> str:
        return self.alarms.get(code, f"A{code:03d}")

    def comm_status_text(self, value: int) -> str:
        return self.comm_status.get(value, f"{self.pname(740)} = {value}")


CFW11: Final = ModelSpec(
    device=Device.CFW11,
    pnu_digits=4,
    address_param=918,
    address_range=(1, 125),
    address_source="CFW-11 manual 2.3.2 and P0918 (section 3): 1 a 125",
    address_needs_power_cycle=True,
    telegram_param=922,
    max_words=10,
    read_map_first=742,
    write_map_first=750,
    profiles=frozenset(DataProfile),
    frame20=True,
    quick_stop=True,
    control_bits=words.MANUFACTURER_CONTROL_BITS,
    status_bits=words.CFW11_STATUS_BITS,
    zsw1_bits=words.CFW11_ZSW1_BITS,
    faults=CFW11_FAULTS,
    alarms=CFW11_ALARMS,
    comm_status=CFW11_COMM_STATUS,
    fault_counter=True,
    comm_action_default=0,
    interface_fault=240,
    default_ident=0x0C11,
    control_types=CFW11_CONTROL_TYPES,
    reads_data_profile=True,  # issue 32 item 2: P0741 checked at every connect
)

CFW700: Final = ModelSpec(
    device=Device.CFW700,
    pnu_digits=4,
    address_param=918,
    address_range=(1, 126),
    address_source="CFW700 manual P0918 (section 4): 1 to 126",
    address_needs_power_cycle=False,
    telegram_param=922,
    max_words=10,
    read_map_first=742,
    write_map_first=750,
    profiles=frozenset(DataProfile),
    frame20=False,
    quick_stop=True,
    control_bits=words.MANUFACTURER_CONTROL_BITS,
    status_bits=words.CFW700_STATUS_BITS,
    zsw1_bits=words.CFW700_ZSW1_BITS,
    faults=CFW700_FAULTS,
    alarms=CFW700_ALARMS,
    comm_status=CFW11_COMM_STATUS,
    fault_counter=True,
    comm_action_default=0,
    interface_fault=240,
    default_ident=0x0C70,
    control_types=CFW700_CONTROL_TYPES,
    quick_stop_ignored_ramp_only=True,  # P0684 bit 6: "not allowed" (CFW-11: "not recommended")
    reads_data_profile=True,  # issue 32 item 2: P0741 checked at every connect
)

CFW320: Final = ModelSpec(
    device=Device.CFW320,
    pnu_digits=3,
    address_param=750,
    address_range=(1, 126),
    address_source="CFW320 manual 3.2 and P750 (section 4.2): 1 to 126",
    address_needs_power_cycle=False,
    telegram_param=751,
    max_words=6,
    read_map_first=742,
    write_map_first=746,
    profiles=frozenset({DataProfile.MANUFACTURER}),
    frame20=False,
    quick_stop=False,
    control_bits=words.CFW320_CONTROL_BITS,
    status_bits=words.CFW320_STATUS_BITS,
    zsw1_bits=(),
    faults=CFW320_FAULTS,
    alarms=CFW320_ALARMS,
    comm_status=CFW320_COMM_STATUS,
    fault_counter=False,
    comm_action_default=1,
    interface_fault=32,
    default_ident=0x0C32,
    reads_data_profile=True,
    baud_param=754,
    factory_settings=MappingProxyType({308: 1, 310: 0, 311: 0, 312: 0}),
)

SPECS: Final[Mapping[Device, ModelSpec]] = MappingProxyType(
    {s.device: s for s in (CFW11, CFW700, CFW320)}
)

# Frame type 20 (CFW-11 Table 3.6): P0922 = 5 (6 words), P0742-P0745 = P0760-P0763 and
# P0750-P0753 = 0.
FRAME20_WORDS: Final = 6
FRAME20_INPUTS: Final = (760, 761, 762, 763)
FRAME20_OUTPUTS: Final = (0, 0, 0, 0)

# Parameters are 16-bit words without decimal point on the wire (P0742 description: P0003
# = 4.7 A is sent as 47; P0750: P0100 = 5.0 s as 50). Decimal places of the parameters the
# profile converts; see docs/devices.md for the ones the seeds do not state.
DECIMALS: Final[Mapping[int, int]] = MappingProxyType(
    {
        2: 0,  # motor speed, rpm (4.2.5 example: 100 rpm = 100)
        3: 1,  # motor current, A (P0742: 4.7 A = 47; 4.2.5: 5.0 A = 50)
        10: 1,  # output power, kW (P0761 formula)
        23: 2,  # firmware version (P0964 subindex 2)
        100: 1,  # acceleration time, s (P0750: 5.0 s = 50; 4.2.5: 8.5 s = 85)
        101: 1,  # deceleration time, s
        102: 1,  # 2nd acceleration time, s
        103: 1,  # 2nd deceleration time, s
        134: 0,  # maximum speed, rpm (P0741 example: 1800 rpm; CFW320 5.2.5: 1000 rpm)
        401: 1,  # motor rated current, A
        402: 0,  # motor rated speed, rpm
        403: 0,  # motor rated frequency, Hz
        404: 1,  # motor rated power, kW (our reading, see docs/devices.md)
        799: 1,  # I/O update delay, s (P0799 range 0.0 to 999.0)
    }
)

# Parameters whose word is signed (ranges -32768..32767 in the manuals).
SIGNED: Final[frozenset[int]] = frozenset({681, 685, 696, 697, 698, 699})


def scaled(number: int, raw: int) -> float | int:
    """A raw parameter word in its unit (decimal places from :data:`DECIMALS`)."""
    value = words.signed(raw) if number in SIGNED else raw & 0xFFFF
    places = DECIMALS.get(number, 0)
    return value / 10**places if places else value


def failsafe_of(spec: ModelSpec, p0313: int, p0206: int = 0) -> tuple[bool | None, str]:
    """(``failsafe``, ``failsafe_text``) for the drive's P0313 value (read at connect).

    P0313 = 5 faults the drive (F238/F239), but an auto-reset (P0206 > 0, the programming
    manuals' auto-reset time, docs/devices.md) clears that fault by itself while the
    master is still away, and the control word it holds (bit 0 run is a level) applies
    again: not fail-safe."""
    name = spec.pname(313)
    text = COMM_ACTION_TEXTS.get(p0313)
    if text is None:
        return None, f"{name} = {p0313}: unknown communication error action"
    failsafe = COMM_ACTION_FAILSAFE[p0313]
    if failsafe and p0313 == CommAction.FAULT.value and p0206 > 0:
        return False, (
            f"{name} = {p0313}: {text}, but {spec.pname(206)} = {p0206} s auto-resets it and "
            "the drive runs again on the last command it holds while the master is away"
        )
    if failsafe:
        return True, f"{name} = {p0313}: {text} when the master is lost"
    return False, f"{name} = {p0313}: {text}, the drive keeps running when the master is lost"


WATCHDOG_OFF_TEXT: Final = (
    "watchdog = 0: the DP watchdog is off, the drive never sees the master go "
    "(A139/F239 and P0313 never act)"
)


def failsafe_warning(spec: ModelSpec, p0313: int | None, watchdog: float | None) -> str | None:
    """What ``check-config`` says of a WEG drive's reaction to a lost master, from the
    config alone: the DP watchdog (``None`` or 0: off) and P0313 as ``startup_params``
    writes it (``None``: not written, the factory setting is assumed). None: fail-safe."""
    if not watchdog:
        return WATCHDOG_OFF_TEXT
    value = spec.comm_action_default if p0313 is None else p0313
    failsafe, text = failsafe_of(spec, value)
    if failsafe:
        return None
    if p0313 is None:
        return (
            f"{text} (factory setting; startup_params does not write {spec.pname(313)}): "
            f"set {spec.pname(313)} = 1 (ramp stop), 2 or 5"
        )
    return f"{text}: set {spec.pname(313)} = 1 (ramp stop), 2 or 5"
