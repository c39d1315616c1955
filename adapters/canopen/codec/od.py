"""A node's object dictionary, read from its EDS or DCF with the canopen library.

The library parses the file's text (CiA 306: ``canopen.import_od`` on a text stream: the
bytes are read by the caller, as a vendor file, ``adapters.canopen.options.read_eds``) and
knows each object's data type, size, access and PDO mapping flag, and encodes and decodes
values (``ODVariable.encode_raw``/``decode_raw``); this module wraps it in the project's
errors: a file that does not parse, a value out of its range (:func:`value_problems`), or
an object the file lacks, is an :class:`EdsError` naming the file and the object. Only the
configuration side uses it: the engine gets bytes.
"""

from __future__ import annotations

import configparser
import hashlib
import io
import logging
import re
import sys
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import canopen
from canopen.objectdictionary import (
    ObjectDictionary,
    ObjectDictionaryError,
    ODArray,
    ODRecord,
    ODVariable,
)
from canopen.objectdictionary import datatypes as dt

from adapters.canopen.errors import EdsError

log = logging.getLogger(__name__)

_INTEGER_TYPES = frozenset(dt.INTEGER_TYPES)
_SIGNED_TYPES = frozenset(dt.SIGNED_TYPES)
_TYPE_NAMES: Final = {
    value: name for name, value in vars(dt).items() if name.isupper() and isinstance(value, int)
}
_REAL32_MAX: Final = 3.4028234663852886e38  # the largest finite IEEE 754 single


def obj_name(index: int, subindex: int | None = None) -> str:
    """``0x6042`` or ``0x2000:1``: how config keys and errors name an object."""
    return f"0x{index:04X}" if subindex is None else f"0x{index:04X}:{subindex}"


def parse_object(text: str) -> tuple[int, int | None]:
    """``"0x6083"`` -> (0x6083, None); ``"0x2000:1"`` -> (0x2000, 1). ValueError otherwise."""
    head, sep, tail = text.strip().partition(":")
    if not head.lower().startswith("0x"):
        raise ValueError(f"{text!r} is not an object index such as '0x6083' or '0x2000:1'")
    index = int(head, 16)
    if not 0 <= index <= 0xFFFF:
        raise ValueError(f"{text!r}: index beyond 0xFFFF")
    if not sep:
        return index, None
    subindex = int(tail, 0)
    if not 0 <= subindex <= 0xFF:
        raise ValueError(f"{text!r}: subindex beyond 255")
    return index, subindex


@dataclass(frozen=True, slots=True)
class Variable:
    """One object of the dictionary as the gateway uses it."""

    index: int
    subindex: int
    name: str
    data_type: int
    bits: int
    signed: bool
    integer: bool
    readable: bool
    writable: bool
    mappable: bool
    minimum: int | float | None
    maximum: int | float | None
    default: object
    unit: str
    od: ODVariable

    def encode(self, value: int | float) -> bytes:
        """The raw bytes of ``value`` (ValueError or struct.error when it does not fit)."""
        if self.integer:
            return bytes(self.od.encode_raw(int(value)))
        return bytes(self.od.encode_raw(value))

    def decode(self, data: bytes) -> int | float:
        value = self.od.decode_raw(data)
        if isinstance(value, bool):
            return int(value)
        if isinstance(value, int | float):
            return value
        raise ValueError(f"{obj_name(self.index, self.subindex)} is not a number")


class Dictionary:
    """A node's object dictionary from one file."""

    def __init__(self, path: Path, node_id: int, raw: bytes) -> None:
        """The dictionary of ``raw``, the bytes read from ``path``, for ``node_id``."""
        self.path = path
        self.file = str(path)
        self.node_id = node_id
        self.od = load(self.file, raw, node_id)

    def has(self, index: int, subindex: int = 0) -> bool:
        try:
            self._get(index, subindex)
        except KeyError:
            return False
        return True

    def _get(self, index: int, subindex: int) -> ODVariable:
        entry = self.od[index]
        if isinstance(entry, ODRecord | ODArray):
            var = entry[subindex]
        elif subindex == 0:
            var = entry
        else:
            raise KeyError(subindex)
        if not isinstance(var, ODVariable):
            raise KeyError(subindex)
        return var

    def variable(self, index: int, subindex: int = 0, *, why: str = "") -> Variable:
        """The object, or an :class:`EdsError` naming the file and the object."""
        try:
            var = self._get(index, subindex)
        except KeyError:
            for_ = f" ({why})" if why else ""
            raise EdsError(
                self.file,
                obj_name(index, subindex or None),
                f"the EDS has no object {obj_name(index, subindex or None)}{for_}",
            ) from None
        data_type = int(var.data_type or 0)
        return Variable(
            index=index,
            subindex=subindex,
            name=str(var.name),
            data_type=data_type,
            bits=len(var),
            signed=data_type in _SIGNED_TYPES,
            integer=data_type in _INTEGER_TYPES or data_type == dt.BOOLEAN,
            readable=bool(var.readable),
            writable=bool(var.writable),
            mappable=bool(var.pdo_mappable),
            minimum=var.min,
            maximum=var.max,
            default=var.default,
            unit=str(var.unit or ""),
            od=var,
        )

    def subindexes(self, index: int) -> tuple[int, ...]:
        entry = self.od.get(index)
        if isinstance(entry, ODRecord | ODArray):
            return tuple(sorted(entry.subindices))
        return (0,) if entry is not None else ()

    def indexes(self) -> tuple[int, ...]:
        return tuple(sorted(self.od.indices))


_CACHE: dict[tuple[str, bytes, int], ObjectDictionary] = {}


def load(file: str, raw: bytes, node_id: int) -> ObjectDictionary:
    """The dictionary of the EDS/DCF bytes ``raw`` (``file`` names it) for ``node_id``
    ($NODEID resolved), its values checked; EdsError for a file that does not parse or
    whose values are out of range. Parsed once per content and node."""
    key = (file, hashlib.sha256(raw).digest(), node_id)
    cached = _CACHE.get(key)
    if cached is None:
        cached = _CACHE[key] = parse(file, raw, node_id)
    return cached


def parse(file: str, raw: bytes, node_id: int | None) -> ObjectDictionary:
    """A dictionary of its own (never shared: the simulator's LocalNode gets one) of the
    EDS/DCF bytes ``raw``: text (:func:`decode_text`) put in the form the library reads
    (:func:`canonical_text`), parsed by the library, then every value checked against its
    range (:func:`value_problems`); EdsError naming the file otherwise."""
    stream = io.StringIO(canonical_text(decode_text(file, raw)), newline=None)
    stream.name = file  # the library tells an EDS from a DCF by the name's suffix
    try:
        with warnings.catch_warnings():  # the library's own logger.warn deprecation
            warnings.simplefilter("ignore", DeprecationWarning)
            od = canopen.import_od(stream, node_id)
    except (configparser.Error, ObjectDictionaryError, ValueError, KeyError, TypeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise EdsError(file, "", f"does not parse as an EDS/DCF: {reason}") from None
    if not isinstance(od, ObjectDictionary) or len(od.indices) == 0:
        raise EdsError(file, "", "does not parse as an EDS/DCF: no objects")
    check_values(file, od)
    return od


# ---------------------------------------------------------------- the text the library reads

_BOM: Final = "\ufeff"
_SECTIONS: Final = {
    name.lower(): name
    for name in (
        "FileInfo",
        "DeviceInfo",
        "DummyUsage",
        "Comments",
        "MandatoryObjects",
        "OptionalObjects",
        "ManufacturerObjects",
        "DeviceComissioning",
    )
}
_KEYS: Final = {
    name.lower(): name
    for name in (
        *("ParameterName", "ObjectType", "DataType", "AccessType", "DefaultValue"),
        *("PDOMapping", "LowLimit", "HighLimit", "SubNumber", "CompactSubObj"),
        *("StorageLocation", "ParameterValue", "ObjectFlags", "Denotation", "NrOfEntries"),
        *("Lines", "SupportedObjects", "VendorName", "VendorNumber", "ProductName"),
        *("ProductNumber", "RevisionNumber", "OrderCode", "SimpleBootUpMaster"),
        *("SimpleBootUpSlave", "Granularity", "DynamicChannelsSupported", "GroupMessaging"),
        *("NrOfRXPDO", "NrOfTXPDO", "LSS_Supported", "NodeID", "Baudrate", "NetNumber"),
        *("NetworkName", "CANopenManager", "LSS_SerialNumber", "Factor", "Description"),
        *("Unit", "FileName", "FileVersion", "FileRevision", "EDSVersion", "CreationTime"),
        *("CreationDate", "CreatedBy", "ModificationTime", "ModificationDate", "ModifiedBy"),
    )
}
_NUMBERED_KEY: Final = re.compile(r"(?i)(baudrate_|dummy|line)(\d+)$")
_NUMBERED_NAMES: Final = {"baudrate_": "BaudRate_", "dummy": "Dummy", "line": "Line"}
_SUB_SECTION: Final = re.compile(r"(?i)([0-9a-f]{4})(sub)([0-9a-f]+)$")
_NAME_SECTION: Final = re.compile(r"(?i)([0-9a-f]{4})(name)$")
_HEADER: Final = re.compile(r"\s*\[([^\]]*)\]\s*$")


def decode_text(file: str, raw: bytes) -> str:
    """The text of an EDS/DCF: UTF-8 when its bytes are UTF-8 (a byte order mark dropped),
    ISO-8859-1 otherwise (the format is ASCII; vendors' tools write a unit's degree sign
    or a name in their language in either); a NUL byte is no text: EdsError."""
    nul = raw.find(b"\0")
    if nul >= 0:
        line = raw[:nul].count(b"\n") + 1
        raise EdsError(file, "", f"does not parse as an EDS/DCF: line {line}: byte 0x00")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("iso-8859-1")
    return text[1:] if text.startswith(_BOM) else text


def canonical_text(text: str) -> str:
    """``text`` as the library reads it, meaning unchanged: CiA 306 puts no order on the
    sections and the field's tools write keywords and section names in any case, but
    the library looks its keywords up as spelled and wants an object's section before
    its sub-index sections. So the known keywords and section names are spelled as CiA
    306 spells them and each object's ``sub``/``Name`` sections are moved after every
    other section (their own order kept); lines and values are left as written."""
    blocks: list[list[str]] = [[]]
    for line in text.splitlines():
        header = _HEADER.match(line)
        if header is not None:
            blocks.append([f"[{_section_name(header.group(1).strip())}]"])
        else:
            blocks[-1].append(_key_line(line))
    head, body = blocks[0], blocks[1:]
    ordered = sorted(body, key=lambda block: _is_part(block[0][1:-1]))
    return "\n".join(line for block in (head, *ordered) for line in block) + "\n"


def _section_name(name: str) -> str:
    sub = _SUB_SECTION.match(name)
    if sub is not None:
        return f"{sub.group(1).upper()}sub{sub.group(3).upper()}"
    named = _NAME_SECTION.match(name)
    if named is not None:
        return f"{named.group(1).upper()}Name"
    if re.fullmatch(r"[0-9A-Fa-f]{4}", name):
        return name.upper()
    return _SECTIONS.get(name.lower(), name)


def _key_line(line: str) -> str:
    key, sep, value = line.partition("=")
    stripped = key.strip()
    if not sep or not stripped or stripped[0] in ";#":
        return line
    known = _KEYS.get(stripped.lower())
    if known is None:
        numbered = _NUMBERED_KEY.match(stripped)
        if numbered is None:
            return line
        known = _NUMBERED_NAMES[numbered.group(1).lower()] + numbered.group(2)
    return f"{known}={value}"


def _is_part(name: str) -> bool:
    return bool(_SUB_SECTION.match(name) or _NAME_SECTION.match(name))


# ---------------------------------------------------------------- values against their ranges


def check_values(file: str, od: ObjectDictionary) -> None:
    """EdsError naming the file, the first object whose value is out of its range and how
    many more there are (:func:`value_problems`); nothing when every value is in range."""
    problems = value_problems(od)
    if problems:
        where, reason = problems[0]
        more = f" (and {len(problems) - 1} more value(s) out of range)" if len(problems) > 1 else ""
        raise EdsError(file, where, f"{reason}{more}")


def value_problems(od: ObjectDictionary) -> list[tuple[str, str]]:
    """(object, reason) for each DefaultValue, and a DCF's ParameterValue, beyond its
    DataType's range (``encode_raw`` could not put it in its bytes) or outside the
    object's LowLimit..HighLimit: what a node answers for an object nobody wrote is its
    DefaultValue, and the gateway reads defaults (0x6046:2, 0x6075, 0x6007)."""
    problems: list[tuple[str, str]] = []
    for var in _variables(od):
        for key in ("DefaultValue", "ParameterValue"):
            value = var.default if key == "DefaultValue" else getattr(var, "value", None)
            why = _out_of_range(var, value)
            if why is not None:
                sub = var.subindex if isinstance(var.parent, ODRecord | ODArray) else None
                problems.append((obj_name(var.index, sub), f"{key} {value} {why} ({var.name})"))
    return problems


def type_range(var: ODVariable) -> tuple[int | float, int | float] | None:
    """The values ``var``'s DataType holds (None for strings and domains)."""
    data_type = var.data_type
    if data_type == dt.BOOLEAN:
        return 0, 1
    if data_type in _SIGNED_TYPES:
        half = 1 << (len(var) - 1)
        return -half, half - 1
    if data_type in _INTEGER_TYPES:
        return 0, (1 << len(var)) - 1
    if data_type == dt.REAL32:
        return -_REAL32_MAX, _REAL32_MAX
    if data_type == dt.REAL64:
        return -sys.float_info.max, sys.float_info.max
    return None


def _out_of_range(var: ODVariable, value: object) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    bounds = type_range(var)
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        name = _TYPE_NAMES.get(var.data_type or 0, f"data type 0x{var.data_type:04X}")
        low, high = (f"{b:g}" if isinstance(b, float) else str(b) for b in bounds)
        return f"is beyond its DataType {name} ({low}..{high})"
    if var.min is not None and value < var.min:
        return f"is below its LowLimit {var.min}"
    if var.max is not None and value > var.max:
        return f"is above its HighLimit {var.max}"
    return None


def _variables(od: ObjectDictionary) -> Iterator[ODVariable]:
    for entry in od.values():
        if isinstance(entry, ODRecord | ODArray):
            yield from (var for var in entry.values() if isinstance(var, ODVariable))
        elif isinstance(entry, ODVariable):
            yield entry
