"""What a master keeps of a GSD file (a DP slave's device data base), and where its user
parameter bytes come from.

The model is what :mod:`adapters.profibus.codec.gsdparse` reads and
:func:`adapters.profibus.codec.gsd.render` writes. Two ways of describing the user
parameter data (Set_Prm after the 7 standard bytes) exist in the GSD specification:

* the legacy keywords ``User_Prm_Data_Len`` and ``User_Prm_Data`` (every revision);
* the Ext keywords (revision 1 on): ``ExtUserPrmData`` definitions placed by
  ``Ext_User_Prm_Data_Ref(offset)``, constant bytes by ``Ext_User_Prm_Data_Const(offset)``,
  at the station level and inside modules (``Ext_Module_Prm_Data_Len``), the whole bounded
  by ``Max_User_Prm_Data_Len``.

The specification says the Ext keywords exclude the evaluation of User_Prm_Data: a file
with any of them (:attr:`Gsd.ext_prm`) builds its user data from them alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from adapters.profibus.codec.chkcfg import decode_identifiers, total_input_bytes, total_output_bytes
from gateway.errors import GatewayError

ENCODING: Final = "iso-8859-1"
MAX_USER_PRM: Final = 237  # 1.6: 244 bytes of Set_Prm data minus the 7 standard bytes
DPV1_STATUS_BYTES: Final = 3

BAUD_KEYS: Final[Mapping[int, str]] = {
    9600: "9.6",
    19200: "19.2",
    45450: "45.45",
    93750: "93.75",
    187500: "187.5",
    500000: "500",
    1500000: "1.5M",
    3000000: "3M",
    6000000: "6M",
    12000000: "12M",
}
"""Baud rate -> the suffix of ``<suffix>_supp`` and ``MaxTsdr_<suffix>``."""

INT_KEYS: Final[Mapping[str, str]] = {
    "gsd_revision": "GSD_Revision",
    "ident_number": "Ident_Number",
    "station_type": "Station_Type",
    "min_slave_intervall": "Min_Slave_Intervall",
    "modular_station": "Modular_Station",
    "max_module": "Max_Module",
    "max_input_len": "Max_Input_Len",
    "max_output_len": "Max_Output_Len",
    "max_data_len": "Max_Data_Len",
    "max_diag_data_len": "Max_Diag_Data_Len",
    "user_prm_data_len": "User_Prm_Data_Len",
    "max_user_prm_data_len": "Max_User_Prm_Data_Len",
    "dpv1_slave": "DPV1_Slave",
    "c1_read_write_supp": "C1_Read_Write_supp",
    "c1_max_data_len": "C1_Max_Data_Len",
    "c1_response_timeout": "C1_Response_Timeout",
    "c2_read_write_supp": "C2_Read_Write_supp",
    "c2_max_data_len": "C2_Max_Data_Len",
    "c2_response_timeout": "C2_Response_Timeout",
    "c2_max_count_channels": "C2_Max_Count_Channels",
    "wd_base_1ms_supp": "WD_Base_1ms_supp",
    "diagnostic_alarm_supp": "Diagnostic_Alarm_supp",
    "process_alarm_supp": "Process_Alarm_supp",
}
"""The integer keys kept (lower-case -> the spelling rendered)."""

STRING_KEYS: Final[Mapping[str, str]] = {
    "vendor_name": "Vendor_Name",
    "model_name": "Model_Name",
}

WHOLE_BYTE_TYPES: Final[Mapping[str, tuple[int, bool]]] = {
    "unsigned8": (1, False),
    "unsigned16": (2, False),
    "unsigned32": (4, False),
    "signed8": (1, True),
    "signed16": (2, True),
    "signed32": (4, True),
}
"""ExtUserPrmData data types of whole bytes: size and sign (big-endian in the data)."""

BIT_TYPES: Final = ("bit", "bitarea")
TYPE_NAMES: Final[Mapping[str, str]] = {
    **{k: k.capitalize() for k in WHOLE_BYTE_TYPES},
    "bit": "Bit",
    "bitarea": "BitArea",
}
"""Lower-case data type -> the spelling rendered."""


class GsdError(GatewayError, ValueError):
    """A GSD problem: the file, the line (0: the file as a whole), the key and the reason."""

    def __init__(self, file: str, line: int, key: str, reason: str) -> None:
        self.file = file
        self.line = line
        self.key = key
        self.reason = reason
        where = f"{file}:{line}" if line else file
        super().__init__(f"{where}: {key}: {reason}" if key else f"{where}: {reason}")


class GsdSetupError(GatewayError, ValueError):
    """A module or parameter setting that the GSD does not allow; ``key`` names the setting."""

    def __init__(self, key: str, reason: str) -> None:
        self.key = key
        self.reason = reason
        super().__init__(f"{key}: {reason}")


# ---------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class PrmText:
    """``PrmText = ref``: value -> text of a parameter's choices."""

    ref: int
    texts: tuple[tuple[int, str], ...]

    def value_of(self, text: str) -> int | None:
        for value, name in self.texts:
            if name.casefold() == text.casefold():
                return value
        return None


@dataclass(frozen=True)
class ExtUserPrmData:
    """``ExtUserPrmData = ref "name"``: one user parameter's type, default and range."""

    ref: int
    name: str
    data_type: str  # "Unsigned8".."Signed32", "Bit", "BitArea" (as rendered)
    default: int
    minimum: int
    maximum: int
    allowed: tuple[int, ...] = ()  # an enumerated range (empty: minimum..maximum)
    first_bit: int = 0  # Bit(b): b; BitArea(f-l): f
    last_bit: int = 0  # BitArea(f-l): l
    prm_text_ref: int | None = None
    changeable: bool = True  # Changeable = 0: the default is the only value
    visible: bool = True  # Visible = 0: a configuration tool does not show it

    def accepts(self, value: int) -> bool:
        if self.allowed:
            return value in self.allowed
        return self.minimum <= value <= self.maximum

    @property
    def kind(self) -> str:
        return self.data_type.lower()

    @property
    def size(self) -> int:
        """Bytes it covers in the user parameter data."""
        whole = WHOLE_BYTE_TYPES.get(self.kind)
        return 1 if whole is None else whole[0]

    @property
    def width(self) -> int:
        """Bits of a Bit or BitArea parameter (8 x size for the others)."""
        if self.kind == "bitarea":
            return self.last_bit - self.first_bit + 1
        return 1 if self.kind == "bit" else 8 * self.size

    def limits(self) -> tuple[int, int]:
        """The smallest and largest value its data type holds."""
        whole = WHOLE_BYTE_TYPES.get(self.kind)
        if whole is not None and whole[1]:
            return -(1 << (self.width - 1)), (1 << (self.width - 1)) - 1
        return 0, (1 << self.width) - 1

    def put(self, data: bytearray, offset: int, value: int) -> None:
        """Write ``value`` at ``offset`` (big-endian; bits into the byte there)."""
        whole = WHOLE_BYTE_TYPES.get(self.kind)
        if whole is not None:
            data[offset : offset + self.size] = value.to_bytes(self.size, "big", signed=whole[1])
            return
        mask = ((1 << self.width) - 1) << self.first_bit
        data[offset] = data[offset] & ~mask & 0xFF | (value << self.first_bit) & mask

    def get(self, data: bytes, offset: int) -> int:
        whole = WHOLE_BYTE_TYPES.get(self.kind)
        if whole is not None:
            return int.from_bytes(data[offset : offset + self.size], "big", signed=whole[1])
        return data[offset] >> self.first_bit & ((1 << self.width) - 1)


@dataclass(frozen=True)
class PrmPlacement:
    """``Ext_User_Prm_Data_Const(offset) = bytes`` (``ref`` None) or ``_Ref(offset) = ref``."""

    offset: int
    ref: int | None = None
    const: bytes = b""
    line: int = field(default=0, compare=False)

    @property
    def keyword(self) -> str:
        return "Ext_User_Prm_Data_Const" if self.ref is None else "Ext_User_Prm_Data_Ref"


# ---------------------------------------------------------------------------- modules, slots


@dataclass(frozen=True)
class GsdModule:
    """``Module = "name" identifiers`` ... ``EndModule``."""

    name: str
    config: bytes  # the Chk_Cfg identifier bytes
    reference: int | None = None  # the module reference number (the line after Module =)
    prm_len: int = 0  # its block of user parameter data (Ext_Module_Prm_Data_Len, else its extent)
    placements: tuple[PrmPlacement, ...] = ()
    f_parameters: bool = False  # PROFIsafe F_ parameter keys, which the gateway does not build
    line: int = field(default=0, compare=False)

    @property
    def input_bytes(self) -> int:
        return total_input_bytes(decode_identifiers(self.config))

    @property
    def output_bytes(self) -> int:
        return total_output_bytes(decode_identifiers(self.config))


@dataclass(frozen=True)
class SlotDef:
    """``Slot(number) = "name" default allowed`` of a ``SlotDefinition`` block (modules by
    their reference numbers)."""

    number: int
    name: str
    default: int
    allowed: tuple[int, ...]
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class UnitDiagBit:
    """``Unit_Diag_Bit(bit) = "text"`` (``inverted``: ``Unit_Diag_Not_Bit``, text when 0)."""

    bit: int
    text: str
    inverted: bool = False


@dataclass(frozen=True)
class UnitDiagArea:
    """``Unit_Diag_Area = first-last`` with ``Value(n) = "text"`` lines ...
    ``Unit_Diag_Area_End``."""

    first: int
    last: int
    values: tuple[tuple[int, str], ...]


# ---------------------------------------------------------------------------- the file


@dataclass(frozen=True)
class Gsd:
    """What a master needs of one GSD file (keys absent from the file are None)."""

    path: str = field(default="", compare=False)
    ints: tuple[tuple[str, int], ...] = ()  # lower-case key -> value, sorted by key
    strings: tuple[tuple[str, str], ...] = ()
    baud_rates: tuple[tuple[int, int | None], ...] = ()  # supported rate -> MaxTsdr (bit times)
    user_prm_data: bytes = b""  # the legacy User_Prm_Data, as written
    placements: tuple[PrmPlacement, ...] = ()  # the station's Ext_User_Prm_Data_Const/_Ref
    modules: tuple[GsdModule, ...] = ()
    prm_texts: tuple[PrmText, ...] = ()
    ext_user_prm: tuple[ExtUserPrmData, ...] = ()
    slots: tuple[SlotDef, ...] = ()
    unit_diag_bits: tuple[UnitDiagBit, ...] = ()
    unit_diag_areas: tuple[UnitDiagArea, ...] = ()

    def get(self, key: str) -> int | None:
        return dict(self.ints).get(key.lower())

    @property
    def ident_number(self) -> int:
        value = self.get("ident_number")
        return 0 if value is None else value

    @property
    def name(self) -> str:
        return dict(self.strings).get("model_name", Path(self.path).stem)

    @property
    def dpv1(self) -> bool:
        return bool(self.get("dpv1_slave"))

    @property
    def modular(self) -> bool:
        return bool(self.get("modular_station"))

    @property
    def ext_prm(self) -> bool:
        """The user parameter data comes from the Ext keywords, not User_Prm_Data(_Len)."""
        return bool(
            self.ext_user_prm
            or self.placements
            or any(m.placements for m in self.modules)
            or self.get("max_user_prm_data_len") is not None
        )

    def max_tsdr(self, baudrate: int) -> int | None:
        return dict(self.baud_rates).get(baudrate)

    def supports(self, baudrate: int) -> bool:
        return baudrate in dict(self.baud_rates)

    def module(self, name: str) -> GsdModule | None:
        for m in self.modules:
            if m.name.casefold() == name.casefold():
                return m
        return None

    def ext(self, ref: int) -> ExtUserPrmData | None:
        for e in self.ext_user_prm:
            if e.ref == ref:
                return e
        return None

    def prm_text(self, ref: int | None) -> PrmText | None:
        for p in self.prm_texts:
            if p.ref == ref:
                return p
        return None


def placement_size(exts: Sequence[ExtUserPrmData], p: PrmPlacement) -> int:
    """Bytes a placement covers (a reference to no definition: 1)."""
    if p.ref is None:
        return len(p.const)
    ext = next((e for e in exts if e.ref == p.ref), None)
    return 1 if ext is None else ext.size


def extent(exts: Sequence[ExtUserPrmData], placements: Sequence[PrmPlacement]) -> int:
    """The bytes up to the end of the last byte ``placements`` cover."""
    return max((p.offset + placement_size(exts, p) for p in placements), default=0)


def user_prm_bound(gsd: Gsd) -> tuple[int, str]:
    """The most user parameter bytes the file allows, and the key that says so."""
    most = gsd.get("max_user_prm_data_len")
    if most is None:
        return MAX_USER_PRM, f"the {MAX_USER_PRM} bytes a Set_Prm carries"
    return most, f"Max_User_Prm_Data_Len = {most}"


def station_prm_len(gsd: Gsd) -> int:
    """Bytes of the station's own user parameter data (before the modules' blocks): the
    extent of its Ext placements, else User_Prm_Data_Len, else the length of User_Prm_Data."""
    if gsd.ext_prm:
        return extent(gsd.ext_user_prm, gsd.placements)
    length = gsd.get("user_prm_data_len")
    return len(gsd.user_prm_data) if length is None else length
