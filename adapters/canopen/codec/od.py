"""A node's object dictionary, read from its EDS or DCF with the canopen library.

The library reads the file (CiA 306: ``canopen.import_od``) and knows each object's data
type, size, access and PDO mapping flag, and encodes and decodes values
(``ODVariable.encode_raw``/``decode_raw``); this module wraps it in the project's errors:
a file that does not parse, or an object the file lacks, is an :class:`EdsError` naming
the file and the object. Only the configuration side uses it: the engine gets bytes.
"""

from __future__ import annotations

import configparser
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen.objectdictionary import ObjectDictionary, ODArray, ODRecord, ODVariable
from canopen.objectdictionary import datatypes as dt

from adapters.canopen.errors import EdsError

log = logging.getLogger(__name__)

_INTEGER_TYPES = frozenset(dt.INTEGER_TYPES)
_SIGNED_TYPES = frozenset(dt.SIGNED_TYPES)


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

    def __init__(self, path: Path, node_id: int) -> None:
        self.path = path
        self.file = str(path)
        self.node_id = node_id
        self.od = load(path, node_id)

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


_CACHE: dict[tuple[Path, float, int], ObjectDictionary] = {}


def load(path: Path, node_id: int) -> ObjectDictionary:
    """The file's dictionary for ``node_id`` ($NODEID resolved); EdsError for a file that
    is missing or does not parse. Read once per file version and node."""
    try:
        stamp = path.stat().st_mtime
    except OSError as exc:
        raise EdsError(str(path), "", f"cannot read the EDS: {exc.strerror or exc}") from None
    key = (path.resolve(), stamp, node_id)
    cached = _CACHE.get(key)
    if cached is not None:
        return cached
    try:
        with warnings.catch_warnings():  # the library's own logger.warn deprecation
            warnings.simplefilter("ignore", DeprecationWarning)
            od = canopen.import_od(str(path), node_id)
    except (configparser.Error, ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise EdsError(str(path), "", f"does not parse as an EDS/DCF: {reason}") from None
    except OSError as exc:
        raise EdsError(str(path), "", f"cannot read the EDS: {exc.strerror or exc}") from None
    if not isinstance(od, ObjectDictionary) or len(od.indices) == 0:
        raise EdsError(str(path), "", "does not parse as an EDS/DCF: no objects")
    _CACHE[key] = od
    return od
