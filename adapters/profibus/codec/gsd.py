"""GSD files (the device data base of a DP slave): parse, render, and build a slave's setup.

Written from the GSD specification's facts (docs/devices.md, "GSD files"):

* the file is ISO-8859-1 text; ``;`` starts a comment (outside a quoted string); a line
  ending in ``\\`` goes on on the next line; keywords are case-insensitive;
* ``Key = value`` where a value is a number (decimal or ``0x`` hex), a quoted string or a
  comma-separated list of numbers;
* blocks: ``Module = "name" id, id ...`` (an optional line with the module reference
  number follows) ... ``EndModule``; ``PrmText = n`` with ``Text(value) = "text"`` lines ...
  ``EndPrmText``; ``ExtUserPrmData = n "name"`` with one data-type line (``Unsigned8 default
  min-max`` or ``Bit(b) default 0-1`` or ``BitArea(f-l) default min-max``, the range may be
  a list ``1,2,4``) and ``Prm_Text_Ref = n`` ... ``EndExtUserPrmData``;
* ``Ext_User_Prm_Data_Const(offset) = bytes`` and ``Ext_User_Prm_Data_Ref(offset) = n``
  place constant bytes and the defaults of ExtUserPrmData ``n`` into User_Prm_Data, at the
  station level or inside a module (offsets from the module's own block, of
  ``Ext_Module_Prm_Data_Len`` bytes, appended after the station's user data);
* DPV1_Slave = 1: the first three bytes of User_Prm_Data are DPV1_Status_1..3; the master
  sends its own DP-V1 status bytes (:class:`~adapters.profibus.codec.dp.SetPrm`) in their place.

Every problem is a :class:`GsdError` naming the file, the line and the key. The parser keeps
what a master needs and ignores the other keys (vendor texts, bitmaps, slot definitions).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from adapters.profibus.codec.chkcfg import decode_identifiers, total_input_bytes, total_output_bytes
from adapters.profibus.errors import ProfibusDecodeError
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

_BAUD_BY_SUFFIX: Final = {v.lower(): k for k, v in BAUD_KEYS.items()}

_INT_KEYS: Final[Mapping[str, str]] = {
    "ident_number": "Ident_Number",
    "station_type": "Station_Type",
    "min_slave_intervall": "Min_Slave_Intervall",
    "modular_station": "Modular_Station",
    "max_module": "Max_Module",
    "max_input_len": "Max_Input_Len",
    "max_output_len": "Max_Output_Len",
    "max_data_len": "Max_Data_Len",
    "user_prm_data_len": "User_Prm_Data_Len",
    "dpv1_slave": "DPV1_Slave",
    "c1_read_write_supp": "C1_Read_Write_supp",
    "c1_max_data_len": "C1_Max_Data_Len",
    "c1_response_timeout": "C1_Response_Timeout",
    "gsd_revision": "GSD_Revision",
}
"""The integer keys kept (lower-case -> the spelling rendered)."""

_STRING_KEYS: Final[Mapping[str, str]] = {
    "vendor_name": "Vendor_Name",
    "model_name": "Model_Name",
}

_SIGNED: Final[Mapping[str, tuple[int, bool]]] = {
    "unsigned8": (1, False),
    "unsigned16": (2, False),
    "unsigned32": (4, False),
    "signed8": (1, True),
    "signed16": (2, True),
    "signed32": (4, True),
}
"""ExtUserPrmData data types of whole bytes: size and sign."""


class GsdError(GatewayError, ValueError):
    """A GSD problem: the file, the line (0: the file as a whole), the key and the reason."""

    def __init__(self, file: str, line: int, key: str, reason: str) -> None:
        self.file = file
        self.line = line
        self.key = key
        self.reason = reason
        where = f"{file}:{line}" if line else file
        super().__init__(f"{where}: {key}: {reason}" if key else f"{where}: {reason}")


# ---------------------------------------------------------------------------- model


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

    def accepts(self, value: int) -> bool:
        if self.allowed:
            return value in self.allowed
        return self.minimum <= value <= self.maximum

    @property
    def size(self) -> int:
        """Bytes it covers in User_Prm_Data."""
        return _SIGNED[self.data_type.lower()][0] if self.data_type.lower() in _SIGNED else 1

    def put(self, data: bytearray, offset: int, value: int) -> None:
        """Write ``value`` at ``offset`` (big-endian; bits into the byte there)."""
        kind = self.data_type.lower()
        if kind in _SIGNED:
            size, signed = _SIGNED[kind]
            data[offset : offset + size] = value.to_bytes(size, "big", signed=signed)
            return
        width = self.last_bit - self.first_bit + 1 if kind == "bitarea" else 1
        mask = ((1 << width) - 1) << self.first_bit
        data[offset] = data[offset] & ~mask & 0xFF | (value << self.first_bit) & mask

    def get(self, data: bytes, offset: int) -> int:
        kind = self.data_type.lower()
        if kind in _SIGNED:
            size, signed = _SIGNED[kind]
            return int.from_bytes(data[offset : offset + size], "big", signed=signed)
        width = self.last_bit - self.first_bit + 1 if kind == "bitarea" else 1
        return data[offset] >> self.first_bit & ((1 << width) - 1)


@dataclass(frozen=True)
class PrmPlacement:
    """``Ext_User_Prm_Data_Const(offset) = bytes`` (``ref`` None) or ``_Ref(offset) = ref``."""

    offset: int
    ref: int | None = None
    const: bytes = b""
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class GsdModule:
    """``Module = "name" identifiers`` ... ``EndModule``."""

    name: str
    config: bytes  # the Chk_Cfg identifier bytes
    reference: int | None = None
    prm_len: int = 0  # Ext_Module_Prm_Data_Len
    placements: tuple[PrmPlacement, ...] = ()
    line: int = field(default=0, compare=False)

    @property
    def input_bytes(self) -> int:
        return total_input_bytes(decode_identifiers(self.config))

    @property
    def output_bytes(self) -> int:
        return total_output_bytes(decode_identifiers(self.config))


@dataclass(frozen=True)
class Gsd:
    """What a master needs of one GSD file (keys absent from the file are None)."""

    path: str = field(default="", compare=False)
    ints: tuple[tuple[str, int], ...] = ()  # lower-case key -> value, sorted by key
    strings: tuple[tuple[str, str], ...] = ()
    baud_rates: tuple[tuple[int, int | None], ...] = ()  # supported rate -> MaxTsdr (bit times)
    user_prm_data: bytes = b""
    placements: tuple[PrmPlacement, ...] = ()
    modules: tuple[GsdModule, ...] = ()
    prm_texts: tuple[PrmText, ...] = ()
    ext_user_prm: tuple[ExtUserPrmData, ...] = ()

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


# ---------------------------------------------------------------------------- lexing


@dataclass(frozen=True)
class _Line:
    number: int
    key: str  # as written
    value: str  # stripped, comments removed ("" without "=")


def _strip_comment(text: str) -> str:
    quoted = False
    for i, ch in enumerate(text):
        if ch == '"':
            quoted = not quoted
        elif ch == ";" and not quoted:
            return text[:i]
    return text


def _logical_lines(text: str) -> Iterator[_Line]:
    """Comments removed, continuations joined; a line's number is its first physical line."""
    pending = ""
    start = 0
    for number, raw in enumerate(_LINE_BREAK.split(text), 1):  # not splitlines: 0x85 is text
        body = _strip_comment(raw).rstrip()
        if not pending:
            start = number
        if body.endswith("\\"):
            pending += body[:-1] + " "
            continue
        body = (pending + body).strip()
        pending = ""
        if not body or body.startswith("#"):
            continue
        key, eq, value = body.partition("=")
        yield _Line(start, key.strip() if eq else body, value.strip() if eq else "")
    if pending.strip():
        yield _Line(start, pending.strip(), "")


_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_NUMBER = re.compile(r"^(0x[0-9a-f]+|-?\d+)$", re.IGNORECASE)
_INDEXED = re.compile(r"^([a-z_0-9.]+)\s*\(\s*(-?\w+)\s*\)$", re.IGNORECASE)
_STRING = re.compile(r'^"([^"]*)"\s*(.*)$', re.DOTALL)
_TYPE_LINE = re.compile(
    r"^(unsigned8|unsigned16|unsigned32|signed8|signed16|signed32|bit|bitarea)"
    r"\s*(?:\(\s*(\d+)\s*(?:-\s*(\d+)\s*)?\))?\s+(-?\w+)\s+(.+)$",
    re.IGNORECASE,
)


class _Reader:
    """The parse of one file (its name for the errors)."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(self, line: _Line | int, key: str, reason: str) -> GsdError:
        number = line.number if isinstance(line, _Line) else line
        return GsdError(self.file, number, key, reason)

    def number(self, line: _Line, text: str, key: str | None = None) -> int:
        text = text.strip()
        if not _NUMBER.match(text):
            raise self.error(line, key or line.key, f"{text!r} is not a number")
        return int(text, 0) if text.lower().startswith("0x") else int(text)

    def numbers(self, line: _Line, text: str) -> tuple[int, ...]:
        parts = [p for p in text.split(",")]
        if not text.strip() or any(not p.strip() for p in parts):
            raise self.error(line, line.key, f"{text!r} is not a list of numbers")
        return tuple(self.number(line, p) for p in parts)

    def byte_list(self, line: _Line, text: str) -> bytes:
        values = self.numbers(line, text)
        for v in values:
            if not 0 <= v <= 255:
                raise self.error(line, line.key, f"{v} is not a byte (0-255)")
        return bytes(values)

    def string(self, line: _Line, text: str) -> tuple[str, str]:
        m = _STRING.match(text.strip())
        if m is None:
            raise self.error(line, line.key, f"{text!r} does not start with a quoted string")
        return m.group(1), m.group(2).strip()


# ---------------------------------------------------------------------------- parsing


def load(path: str | Path) -> Gsd:
    """Read and parse a GSD file (ISO-8859-1); :class:`GsdError` on any problem."""
    file = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise GsdError(file, 0, "", f"cannot read it: {exc.strerror or exc}") from None
    return parse(raw.decode(ENCODING), file)


def parse(text: str, file: str = "<gsd>") -> Gsd:
    """Parse GSD text (already decoded); ``file`` names it in errors."""
    r = _Reader(file)
    lines = list(_logical_lines(text))
    state = _State()
    i = 0
    while i < len(lines):
        i = _statement(r, lines, i, state)
    gsd = Gsd(
        path=file,
        ints=tuple(sorted(state.ints.items())),
        strings=tuple(sorted(state.strings.items())),
        baud_rates=_baud_rates(state),
        user_prm_data=state.user_prm,
        placements=tuple(state.placements),
        modules=tuple(state.modules),
        prm_texts=tuple(state.prm_texts),
        ext_user_prm=tuple(state.ext),
    )
    _validate(r, gsd, state)
    return gsd


@dataclass
class _State:
    ints: dict[str, int] = field(default_factory=dict)
    strings: dict[str, str] = field(default_factory=dict)
    supp: dict[int, int] = field(default_factory=dict)
    tsdr: dict[int, int] = field(default_factory=dict)
    user_prm: bytes = b""
    placements: list[PrmPlacement] = field(default_factory=list)
    modules: list[GsdModule] = field(default_factory=list)
    prm_texts: list[PrmText] = field(default_factory=list)
    ext: list[ExtUserPrmData] = field(default_factory=list)
    lines: dict[str, int] = field(default_factory=dict)  # key -> line, for later errors
    ref_lines: dict[int, int] = field(default_factory=dict)  # Ext ref -> line of its use


def _baud_rates(state: _State) -> tuple[tuple[int, int | None], ...]:
    return tuple((baud, state.tsdr.get(baud)) for baud in BAUD_KEYS if state.supp.get(baud, 0) == 1)


def _statement(r: _Reader, lines: list[_Line], i: int, state: _State) -> int:
    line = lines[i]
    key = line.key.lower()
    block = _BLOCKS.get(key)
    if block is not None:
        return block(r, lines, i, state)
    if key in ("endmodule", "endprmtext", "endextuserprmdata"):
        raise r.error(line, line.key, "closes a block that was never opened")
    _simple(r, line, state, state.placements)
    return i + 1


def _simple(r: _Reader, line: _Line, state: _State, placements: list[PrmPlacement]) -> None:
    key = line.key.lower()
    if not line.value and "=" not in line.key:
        if key in _INT_KEYS or key in _STRING_KEYS:
            raise r.error(line, line.key, "has no value (Key = value)")
        return  # a line the master does not need (e.g. a module reference number)
    if key in _INT_KEYS:
        state.ints[key] = r.number(line, line.value)
        state.lines[key] = line.number
    elif key in _STRING_KEYS:
        state.strings[key] = r.string(line, line.value)[0]
    elif key == "user_prm_data":
        state.user_prm = r.byte_list(line, line.value)
        state.lines[key] = line.number
    elif key.endswith("_supp") and key[: -len("_supp")] in _BAUD_BY_SUFFIX:
        state.supp[_BAUD_BY_SUFFIX[key[: -len("_supp")]]] = r.number(line, line.value)
    elif key.startswith("maxtsdr_") and key[len("maxtsdr_") :] in _BAUD_BY_SUFFIX:
        state.tsdr[_BAUD_BY_SUFFIX[key[len("maxtsdr_") :]]] = r.number(line, line.value)
    else:
        placement = _placement(r, line, state)
        if placement is not None:
            placements.append(placement)


def _placement(r: _Reader, line: _Line, state: _State) -> PrmPlacement | None:
    m = _INDEXED.match(line.key)
    if m is None:
        return None
    name = m.group(1).lower()
    if name not in ("ext_user_prm_data_const", "ext_user_prm_data_ref"):
        return None
    offset = r.number(line, m.group(2))
    if not 0 <= offset < MAX_USER_PRM:
        raise r.error(line, line.key, f"offset {offset} is outside 0-{MAX_USER_PRM - 1}")
    if name == "ext_user_prm_data_const":
        return PrmPlacement(offset, const=r.byte_list(line, line.value), line=line.number)
    ref = r.number(line, line.value)
    state.ref_lines.setdefault(ref, line.number)
    return PrmPlacement(offset, ref=ref, line=line.number)


def _block_end(r: _Reader, lines: list[_Line], i: int, end: str) -> int:
    """Index of the line closing the block opened at ``i``."""
    for j in range(i + 1, len(lines)):
        key = lines[j].key.lower()
        if key == end.lower():
            return j
        if key in _BLOCKS:
            break
    raise r.error(lines[i], lines[i].key, f"has no {end}")


def _module(r: _Reader, lines: list[_Line], i: int, state: _State) -> int:
    line = lines[i]
    end = _block_end(r, lines, i, "EndModule")
    name, rest = r.string(line, line.value)
    if not rest:
        raise r.error(line, line.key, f"module {name!r} has no identifier bytes")
    config = r.byte_list(line, rest)
    try:
        decode_identifiers(config)
    except ProfibusDecodeError as exc:
        raise r.error(line, line.key, f"module {name!r}: {exc.message}") from None
    if any(m.name.casefold() == name.casefold() for m in state.modules):
        raise r.error(line, line.key, f"module {name!r} is defined twice")
    reference: int | None = None
    prm_len = 0
    placements: list[PrmPlacement] = []
    for inner in lines[i + 1 : end]:
        key = inner.key.lower()
        if not inner.value and _NUMBER.match(inner.key) and reference is None:
            reference = r.number(inner, inner.key, "Module")
        elif key == "ext_module_prm_data_len":
            prm_len = r.number(inner, inner.value)
        else:
            placement = _placement(r, inner, state)
            if placement is not None:
                placements.append(placement)
    for p in placements:
        if p.offset + _placement_size(state, p) > prm_len:
            raise r.error(
                line,
                line.key,
                f"module {name!r}: a parameter at offset {p.offset} is beyond "
                f"Ext_Module_Prm_Data_Len = {prm_len}",
            )
    state.modules.append(
        GsdModule(name, config, reference, prm_len, tuple(placements), line.number)
    )
    return end + 1


def _placement_size(state: _State, p: PrmPlacement) -> int:
    if p.ref is None:
        return len(p.const)
    ext = next((e for e in state.ext if e.ref == p.ref), None)
    return 1 if ext is None else ext.size


def _prm_text(r: _Reader, lines: list[_Line], i: int, state: _State) -> int:
    line = lines[i]
    end = _block_end(r, lines, i, "EndPrmText")
    ref = r.number(line, line.value)
    texts: list[tuple[int, str]] = []
    for inner in lines[i + 1 : end]:
        m = _INDEXED.match(inner.key)
        if m is None or m.group(1).lower() != "text":
            raise r.error(inner, inner.key, 'only Text(value) = "text" lines go in a PrmText')
        texts.append((r.number(inner, m.group(2)), r.string(inner, inner.value)[0]))
    if any(p.ref == ref for p in state.prm_texts):
        raise r.error(line, line.key, f"PrmText {ref} is defined twice")
    state.prm_texts.append(PrmText(ref, tuple(texts)))
    return end + 1


def _ext_user_prm(r: _Reader, lines: list[_Line], i: int, state: _State) -> int:
    line = lines[i]
    end = _block_end(r, lines, i, "EndExtUserPrmData")
    m = re.match(r"^(\S+)\s+(.*)$", line.value)
    if m is None:
        raise r.error(line, line.key, 'is not ExtUserPrmData = ref "name"')
    ref = r.number(line, m.group(1))
    name = r.string(line, m.group(2))[0]
    typed: ExtUserPrmData | None = None
    text_ref: int | None = None
    for inner in lines[i + 1 : end]:
        if inner.key.lower() == "prm_text_ref":
            text_ref = r.number(inner, inner.value)
            continue
        typed = _data_type(r, inner, ref, name)
    if typed is None:
        raise r.error(line, line.key, f"ExtUserPrmData {ref} {name!r} has no data type line")
    if any(e.ref == ref for e in state.ext):
        raise r.error(line, line.key, f"ExtUserPrmData {ref} is defined twice")
    state.ext.append(_with_text_ref(typed, text_ref))
    state.lines[f"ext{ref}"] = line.number
    return end + 1


def _with_text_ref(e: ExtUserPrmData, ref: int | None) -> ExtUserPrmData:
    return ExtUserPrmData(
        e.ref, e.name, e.data_type, e.default, e.minimum, e.maximum, e.allowed,
        e.first_bit, e.last_bit, ref,
    )  # fmt: skip


_TYPE_NAMES: Final = {k: k.capitalize() for k in _SIGNED}
_TYPE_NAMES.update({"bit": "Bit", "bitarea": "BitArea"})


def _data_type(r: _Reader, line: _Line, ref: int, name: str) -> ExtUserPrmData:
    text = f"{line.key} {line.value}" if line.value else line.key
    m = _TYPE_LINE.match(text)
    if m is None:
        raise r.error(line, line.key, f"{text!r} is not a data type line (Unsigned8 0 0-255)")
    kind = m.group(1).lower()
    first = int(m.group(2)) if m.group(2) else 0
    last = int(m.group(3)) if m.group(3) else first
    if kind in ("bit", "bitarea") and (m.group(2) is None or not 0 <= first <= last <= 7):
        raise r.error(line, line.key, f"{text!r}: bit numbers must be 0-7")
    default = r.number(line, m.group(4), line.key)
    low, high, allowed = _range(r, line, m.group(5).strip())
    e = ExtUserPrmData(ref, name, _TYPE_NAMES[kind], default, low, high, allowed, first, last)
    lo, hi = _type_limits(e)
    if not (lo <= low and high <= hi):
        raise r.error(line, line.key, f"range {low}-{high} does not fit a {e.data_type}")
    if not e.accepts(default):
        raise r.error(line, line.key, f"default {default} is outside its own range")
    return e


def _range(r: _Reader, line: _Line, text: str) -> tuple[int, int, tuple[int, ...]]:
    m = re.match(r"^(-?\w+)\s*-\s*(-?\w+)$", text)
    if m is not None:
        low, high = r.number(line, m.group(1), line.key), r.number(line, m.group(2), line.key)
        if low > high:
            raise r.error(line, line.key, f"range {text!r} runs backwards")
        return low, high, ()
    values = r.numbers(line, text)
    return min(values), max(values), values


def _type_limits(e: ExtUserPrmData) -> tuple[int, int]:
    kind = e.data_type.lower()
    if kind in _SIGNED:
        size, signed = _SIGNED[kind]
        bits = 8 * size
        return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    width = e.last_bit - e.first_bit + 1 if kind == "bitarea" else 1
    return 0, (1 << width) - 1


_BLOCKS: Final = {
    "module": _module,
    "prmtext": _prm_text,
    "extuserprmdata": _ext_user_prm,
}


def _validate(r: _Reader, gsd: Gsd, state: _State) -> None:
    """Cross-checks once the whole file is read (a key can refer to one further down)."""
    if gsd.get("ident_number") is None:
        raise r.error(0, "Ident_Number", "is missing")
    if not 0 <= gsd.ident_number <= 0xFFFF:
        raise r.error(state.lines["ident_number"], "Ident_Number", "must be 0-0xFFFF")
    if not gsd.modules:
        raise r.error(0, "Module", "the file defines no module")
    length = gsd.get("user_prm_data_len")
    if length is not None and not 0 <= length <= MAX_USER_PRM:
        raise r.error(
            state.lines["user_prm_data_len"], "User_Prm_Data_Len", f"must be 0-{MAX_USER_PRM}"
        )
    if length is not None and len(gsd.user_prm_data) > length:
        raise r.error(
            state.lines.get("user_prm_data", 0),
            "User_Prm_Data",
            f"{len(gsd.user_prm_data)} bytes for User_Prm_Data_Len = {length}",
        )
    for ref, number in state.ref_lines.items():
        if gsd.ext(ref) is None:
            raise r.error(number, "Ext_User_Prm_Data_Ref", f"no ExtUserPrmData {ref} in the file")
    for e in gsd.ext_user_prm:
        if e.prm_text_ref is not None and gsd.prm_text(e.prm_text_ref) is None:
            raise r.error(
                state.lines[f"ext{e.ref}"], "Prm_Text_Ref", f"no PrmText {e.prm_text_ref}"
            )
    total = station_prm_len(gsd)
    for p in gsd.placements:
        size = len(p.const) if p.ref is None else _ext_size(gsd, p.ref)
        if p.offset + size > total:
            raise r.error(
                p.line,
                "Ext_User_Prm_Data_Ref" if p.ref is not None else "Ext_User_Prm_Data_Const",
                f"offset {p.offset} + {size} bytes is beyond User_Prm_Data_Len = {total}",
            )  # fmt: skip


def _ext_size(gsd: Gsd, ref: int) -> int:
    e = gsd.ext(ref)
    return 1 if e is None else e.size


def station_prm_len(gsd: Gsd) -> int:
    """Bytes of the station's own user parameter data (User_Prm_Data_Len, else its data)."""
    length = gsd.get("user_prm_data_len")
    return len(gsd.user_prm_data) if length is None else length


# ---------------------------------------------------------------------------- rendering


def render(gsd: Gsd) -> str:
    """GSD text that parses back to ``gsd`` (keys in a fixed order, names as the spec spells)."""
    out = ["#Profibus_DP", "; rendered by drive-gateway"]
    strings = dict(gsd.strings)
    for key, spelled in _STRING_KEYS.items():
        if key in strings:
            out.append(f'{spelled} = "{strings[key]}"')
    ints = dict(gsd.ints)
    for key, spelled in _INT_KEYS.items():
        if key in ints:
            value = ints[key]
            out.append(
                f"{spelled} = 0x{value:04X}" if key == "ident_number" else f"{spelled} = {value}"
            )
    for baud, tsdr in gsd.baud_rates:
        out.append(f"{BAUD_KEYS[baud]}_supp = 1")
        if tsdr is not None:
            out.append(f"MaxTsdr_{BAUD_KEYS[baud]} = {tsdr}")
    if gsd.user_prm_data:
        out.append("User_Prm_Data = " + _hex_list(gsd.user_prm_data))
    for p in gsd.prm_texts:
        out.append(f"PrmText = {p.ref}")
        out.extend(f'Text({value}) = "{text}"' for value, text in p.texts)
        out.append("EndPrmText")
    for e in gsd.ext_user_prm:
        out.append(f'ExtUserPrmData = {e.ref} "{e.name}"')
        out.append(_type_line(e))
        if e.prm_text_ref is not None:
            out.append(f"Prm_Text_Ref = {e.prm_text_ref}")
        out.append("EndExtUserPrmData")
    out.extend(_placement_line(p) for p in gsd.placements)
    for m in gsd.modules:
        out.append(f'Module = "{m.name}" {_hex_list(m.config)}')
        if m.reference is not None:
            out.append(str(m.reference))
        if m.prm_len:
            out.append(f"Ext_Module_Prm_Data_Len = {m.prm_len}")
        out.extend(_placement_line(p) for p in m.placements)
        out.append("EndModule")
    return "\n".join(out) + "\n"


def _hex_list(data: bytes) -> str:
    return ",".join(f"0x{b:02X}" for b in data)


def _type_line(e: ExtUserPrmData) -> str:
    kind = e.data_type.lower()
    head = e.data_type
    if kind == "bit":
        head = f"Bit({e.first_bit})"
    elif kind == "bitarea":
        head = f"BitArea({e.first_bit}-{e.last_bit})"
    span = ",".join(map(str, e.allowed)) if e.allowed else f"{e.minimum}-{e.maximum}"
    return f"{head} {e.default} {span}"


def _placement_line(p: PrmPlacement) -> str:
    if p.ref is None:
        return f"Ext_User_Prm_Data_Const({p.offset}) = {_hex_list(p.const)}"
    return f"Ext_User_Prm_Data_Ref({p.offset}) = {p.ref}"


# ---------------------------------------------------------------------------- a slave's setup


@dataclass(frozen=True)
class GsdSetup:
    """What a master sends a slave configured from a GSD (see :func:`build_setup`)."""

    ident_number: int
    cfg: bytes
    user_prm: bytes  # the whole User_Prm_Data (with DPV1_Status_1..3 first if dpv1)
    input_len: int
    output_len: int
    dpv1: bool
    origin: str  # "GSD <file>, module 'x'" for events

    @property
    def user_prm_after_dpv1(self) -> bytes:
        """The user data after the DP-V1 status bytes (what :class:`SlaveParams` carries)."""
        return self.user_prm[DPV1_STATUS_BYTES:] if self.dpv1 else self.user_prm


class GsdSetupError(GatewayError, ValueError):
    """A module or parameter setting that the GSD does not allow; ``key`` names the setting."""

    def __init__(self, key: str, reason: str) -> None:
        self.key = key
        self.reason = reason
        super().__init__(f"{key}: {reason}")


def build_setup(
    gsd: Gsd, modules: Sequence[str], prm: Mapping[str, int | str] | None = None
) -> GsdSetup:
    """The Ident_Number, Chk_Cfg bytes and User_Prm_Data of ``modules`` (by name) of ``gsd``.

    User_Prm_Data starts from the GSD's defaults (User_Prm_Data, then the constants and
    the ExtUserPrmData defaults placed into it; each module's block after it); ``prm``
    sets single ExtUserPrmData values by name (a PrmText text or a number).
    """
    chosen = [_find_module(gsd, name) for name in modules]
    _check_modules(gsd, chosen)
    cfg = b"".join(m.config for m in chosen)
    ids = decode_identifiers(cfg)
    data, slots = default_user_prm(gsd, chosen)
    for name, value in (prm or {}).items():
        _set_prm(gsd, data, slots, name, value)
    if len(data) > MAX_USER_PRM:
        raise GsdSetupError("modules", f"{len(data)} bytes of user parameters (max {MAX_USER_PRM})")
    names = ", ".join(repr(m.name) for m in chosen)
    label = "module" if len(chosen) == 1 else "modules"
    return GsdSetup(
        ident_number=gsd.ident_number,
        cfg=cfg,
        user_prm=bytes(data),
        input_len=total_input_bytes(ids),
        output_len=total_output_bytes(ids),
        dpv1=gsd.dpv1,
        origin=f"GSD {gsd.path}, {label} {names}",
    )


def _find_module(gsd: Gsd, name: str) -> GsdModule:
    module = gsd.module(name)
    if module is None:
        known = ", ".join(repr(m.name) for m in gsd.modules)
        raise GsdSetupError("module", f"{name!r} is not a module of {gsd.path} (it has {known})")
    return module


def _check_modules(gsd: Gsd, chosen: Sequence[GsdModule]) -> None:
    if not chosen:
        raise GsdSetupError("module", "no module chosen")
    if not gsd.modular and len(chosen) != 1:
        raise GsdSetupError(
            "modules", f"{gsd.path} is not a modular station (Modular_Station = 0): one module"
        )
    most = gsd.get("max_module")
    if gsd.modular and most is not None and len(chosen) > most:
        raise GsdSetupError("modules", f"{len(chosen)} modules, the GSD allows Max_Module = {most}")
    ins = sum(m.input_bytes for m in chosen)
    outs = sum(m.output_bytes for m in chosen)
    for key, have, label in (
        ("max_input_len", ins, "input"),
        ("max_output_len", outs, "output"),
        ("max_data_len", ins + outs, "input and output"),
    ):
        limit = gsd.get(key)
        if limit is not None and have > limit:
            raise GsdSetupError(
                "modules",
                f"{have} bytes of {label} data, the GSD allows {_INT_KEYS[key]} = {limit}",
            )


@dataclass(frozen=True)
class _Slot:
    offset: int
    ext: ExtUserPrmData
    where: str


def default_user_prm(gsd: Gsd, chosen: Sequence[GsdModule]) -> tuple[bytearray, list[_Slot]]:
    """User_Prm_Data with every default in place, and where each named parameter sits."""
    size = station_prm_len(gsd)
    data = bytearray(size)
    data[: len(gsd.user_prm_data)] = gsd.user_prm_data
    slots: list[_Slot] = []
    _apply(gsd, data, 0, gsd.placements, slots=slots, where="station")
    for m in chosen:
        base = len(data)
        data.extend(bytes(m.prm_len))
        _apply(gsd, data, base, m.placements, slots=slots, where=f"module {m.name!r}")
    return data, slots


def _apply(
    gsd: Gsd,
    data: bytearray,
    base: int,
    placements: Iterable[PrmPlacement],
    *,
    slots: list[_Slot],
    where: str,
) -> None:
    for p in placements:
        if p.ref is None:
            data[base + p.offset : base + p.offset + len(p.const)] = p.const
            continue
        ext = gsd.ext(p.ref)
        if ext is None:  # checked at parse time
            continue
        ext.put(data, base + p.offset, ext.default)
        slots.append(_Slot(base + p.offset, ext, where))


def _set_prm(gsd: Gsd, data: bytearray, slots: list[_Slot], name: str, value: int | str) -> None:
    matching = [s for s in slots if s.ext.name.casefold() == name.casefold()]
    if not matching:
        known = ", ".join(sorted({repr(s.ext.name) for s in slots})) or "none"
        raise GsdSetupError(
            f"prm.{name}", f"not a user parameter of the chosen module(s) (known: {known})"
        )
    for slot in matching:
        number = _prm_value(gsd, slot.ext, name, value)
        slot.ext.put(data, slot.offset, number)


def _prm_value(gsd: Gsd, ext: ExtUserPrmData, name: str, value: int | str) -> int:
    texts = gsd.prm_text(ext.prm_text_ref)
    if isinstance(value, str):
        found = texts.value_of(value) if texts is not None else None
        if found is None:
            choices = ", ".join(repr(t) for _, t in texts.texts) if texts else "numbers only"
            raise GsdSetupError(f"prm.{name}", f"{value!r} is not one of its texts ({choices})")
        value = found
    if isinstance(value, bool) or not ext.accepts(value):
        span = ",".join(map(str, ext.allowed)) if ext.allowed else f"{ext.minimum}-{ext.maximum}"
        raise GsdSetupError(f"prm.{name}", f"{value!r} is outside its range {span}")
    return value


def check_user_prm(gsd: Gsd, chosen: Sequence[GsdModule], data: bytes) -> str | None:
    """Why ``data`` (the whole User_Prm_Data) is not valid for ``chosen``; None if it is."""
    expected, slots = default_user_prm(gsd, chosen)
    if len(data) != len(expected):
        return f"{len(data)} bytes of user parameters, the GSD gives {len(expected)}"
    for slot in slots:
        value = slot.ext.get(data, slot.offset)
        if not slot.ext.accepts(value):
            return f"{slot.ext.name!r} = {value} is outside its range"
    return None


def match_modules(gsd: Gsd, cfg: bytes) -> tuple[GsdModule, ...] | None:
    """The modules whose identifier bytes, one after another, are ``cfg`` (None: no match)."""
    if not cfg:
        return None
    for m in sorted(gsd.modules, key=lambda m: -len(m.config)):
        if cfg.startswith(m.config):
            if len(m.config) == len(cfg):
                return (m,)
            rest = match_modules(gsd, cfg[len(m.config) :])
            if rest is not None:
                return (m, *rest)
    return None


def find_in_dir(directory: str | Path, ident_number: int) -> list[Gsd]:
    """The GSD files of ``directory`` (``*.gsd``, ``*.gs?``) whose Ident_Number matches."""
    found: list[Gsd] = []
    for path in sorted(Path(directory).iterdir()):
        if not path.is_file() or not path.suffix.lower().startswith(".gs"):
            continue
        try:
            gsd = load(path)
        except GsdError:
            continue
        if gsd.ident_number == ident_number:
            found.append(gsd)
    return found
