"""Reading a GSD file into :class:`~adapters.profibus.codec.gsdmodel.Gsd`, by the GSD
specification's file format (revisions 0 to 5):

* ISO-8859-1 text; the DP slave's keys follow a ``#Profibus_DP`` line (text before it is
  not part of the file's description; another ``#`` line ends it);
* ``;`` starts a comment (outside a quoted string); a line ending in ``\\`` goes on on the
  next line; keywords are case-insensitive;
* ``Key = value`` where a value is a number (decimal or ``0x`` hex), a quoted string or a
  comma-separated list of numbers; ``Key(index) = value`` for the indexed keys;
* blocks, each with its own end keyword: ``Module`` ... ``EndModule`` (the module reference
  number may follow on its own line), ``PrmText`` ... ``EndPrmText``, ``ExtUserPrmData`` ...
  ``EndExtUserPrmData``, ``SlotDefinition`` ... ``EndSlotDefinition``, ``Unit_Diag_Area``
  ... ``Unit_Diag_Area_End``.

Keys a master does not need (vendor texts, bitmaps, alarms, isochronous mode, ``X_``
keys of the extended parameterization) are read over. Every problem is a
:class:`~adapters.profibus.codec.gsdmodel.GsdError` naming the file, the line and the key.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Final

from adapters.profibus.codec.chkcfg import decode_identifiers
from adapters.profibus.codec.gsdmodel import (
    BAUD_KEYS,
    DPV1_STATUS_BYTES,
    ENCODING,
    INT_KEYS,
    MAX_USER_PRM,
    STRING_KEYS,
    TYPE_NAMES,
    ExtUserPrmData,
    Gsd,
    GsdError,
    GsdModule,
    PrmPlacement,
    PrmText,
    SlotDef,
    UnitDiagArea,
    UnitDiagBit,
    extent,
    placement_size,
    station_prm_len,
    user_prm_bound,
)
from adapters.profibus.errors import ProfibusDecodeError

HEADER: Final = "#Profibus_DP"
_HEADER: Final = HEADER.lower()

# ---------------------------------------------------------------------------- lexing


@dataclass(frozen=True)
class _Line:
    number: int  # the first physical line of a continued line
    key: str  # as written
    value: str  # stripped, comments removed ("" without "=")
    eq: bool = True  # the line has a "="

    @property
    def name(self) -> str:
        return self.key.lower()


_LINE_BREAK: Final = re.compile(r"\r\n|\r|\n")
_NUMBER: Final = re.compile(r"^(0x[0-9a-f]+|-?\d+)$", re.IGNORECASE)
_INDEXED: Final = re.compile(r"^([a-z_0-9.]+)\s*\(\s*(-?\w+)\s*\)$", re.IGNORECASE)
_STRING: Final = re.compile(r'^"([^"]*)"\s*(.*)$', re.DOTALL)
_SPAN: Final = re.compile(r"^(-?\w+)\s*-\s*(-?\w+)$")
_TYPE_LINE: Final = re.compile(
    r"^(unsigned8|unsigned16|unsigned32|signed8|signed16|signed32|bit|bitarea)"
    r"\s*(?:\(\s*(\d+)\s*(?:-\s*(\d+)\s*)?\))?\s+(-?\w+)\s+(.+)$",
    re.IGNORECASE,
)


def _strip_comment(text: str) -> str:
    quoted = False
    for i, ch in enumerate(text):
        if ch == '"':
            quoted = not quoted
        elif ch == ";" and not quoted:
            return text[:i]
    return text


def _joined(physical: Sequence[str], start: int) -> Iterator[tuple[int, str]]:
    """(line number, text) of each non-empty line from ``physical[start]`` on: comments
    removed, continuations joined; a line's number is that of its first physical line."""
    pending = ""
    first = start + 1
    for number, raw in enumerate(physical[start:], start + 1):
        body = _strip_comment(raw).rstrip()
        if not pending:
            first = number
        if body.endswith("\\"):
            pending += body[:-1] + " "
            continue
        body = (pending + body).strip()
        pending = ""
        if body:
            yield first, body
    if pending.strip():
        yield first, pending.strip()


def _split(number: int, body: str) -> _Line:
    key, eq, value = body.partition("=")
    if not eq:
        return _Line(number, body, "", eq=False)
    return _Line(number, key.strip(), value.strip())


def _indexed(line: _Line) -> tuple[str, str] | None:
    """``Key(index)``: the lower-case key and the index as written."""
    m = _INDEXED.match(line.key)
    return None if m is None else (m.group(1).lower(), m.group(2))


class _Reader:
    """The parse of one file (its name for the errors)."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(self, line: _Line | int, key: str, reason: str) -> GsdError:
        number = line.number if isinstance(line, _Line) else line
        return GsdError(self.file, number, key, reason)

    def lines(self, text: str) -> list[_Line]:
        """The logical lines after the ``#Profibus_DP`` line, up to the next ``#`` line."""
        physical = _LINE_BREAK.split(text)  # not splitlines: 0x85 is text in ISO-8859-1
        headers = (
            i for i, raw in enumerate(physical) if _strip_comment(raw).strip().lower() == _HEADER
        )
        index = next(headers, None)
        if index is None:
            raise self.error(0, HEADER, f"the file has no {HEADER} line: not a DP slave's GSD")
        found: list[_Line] = []
        for number, body in _joined(physical, index + 1):
            if body.startswith("#"):
                break  # another section of the file: not the DP slave's
            found.append(_split(number, body))
        return found

    def number(self, line: _Line, text: str, key: str | None = None) -> int:
        text = text.strip()
        if not _NUMBER.match(text):
            raise self.error(line, key or line.key, f"{text!r} is not a number")
        return int(text, 0) if text.lower().startswith("0x") else int(text)

    def numbers(self, line: _Line, text: str) -> tuple[int, ...]:
        parts = text.split(",")
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

    def flag(self, line: _Line) -> bool:
        value = self.number(line, line.value)
        if value not in (0, 1):
            raise self.error(line, line.key, f"{value} is not 0 or 1")
        return bool(value)

    def span(self, line: _Line, text: str) -> tuple[int, int]:
        """``first-last``, first <= last."""
        m = _SPAN.match(text.strip())
        if m is None:
            raise self.error(line, line.key, f"{text!r} is not a range first-last")
        low, high = self.number(line, m.group(1)), self.number(line, m.group(2))
        if low > high:
            raise self.error(line, line.key, f"range {text.strip()!r} runs backwards")
        return low, high


# ---------------------------------------------------------------------------- the parse state


@dataclass
class _Module:
    """A module as read, before its block length is known (definitions may follow it)."""

    name: str
    config: bytes
    line: int
    reference: int | None = None
    declared_len: int | None = None  # Ext_Module_Prm_Data_Len
    placements: list[PrmPlacement] = field(default_factory=list)
    f_parameters: bool = False


@dataclass
class _State:
    ints: dict[str, int] = field(default_factory=dict)
    strings: dict[str, str] = field(default_factory=dict)
    supp: dict[int, int] = field(default_factory=dict)
    tsdr: dict[int, int] = field(default_factory=dict)
    user_prm: bytes = b""
    placements: list[PrmPlacement] = field(default_factory=list)
    modules: list[_Module] = field(default_factory=list)
    prm_texts: list[PrmText] = field(default_factory=list)
    ext: list[ExtUserPrmData] = field(default_factory=list)
    slots: list[SlotDef] = field(default_factory=list)
    diag_bits: list[UnitDiagBit] = field(default_factory=list)
    diag_areas: list[UnitDiagArea] = field(default_factory=list)
    lines: dict[str, int] = field(default_factory=dict)  # key -> line, for later errors


# ---------------------------------------------------------------------------- parsing


def decode(raw: bytes, file: str = "<gsd>") -> Gsd:
    """Parse a GSD file's bytes (ISO-8859-1, as the specification says); ``file`` names it
    in errors. Reading the file is the caller's (``adapters.profibus.options.load_gsd``)."""
    return parse(raw.decode(ENCODING), file)


def parse(text: str, file: str = "<gsd>") -> Gsd:
    """Parse GSD text (already decoded); ``file`` names it in errors."""
    r = _Reader(file)
    lines = r.lines(text)
    state = _State()
    i = 0
    while i < len(lines):
        i = _statement(r, lines, i, state)
    gsd = Gsd(
        path=file,
        ints=tuple(sorted(state.ints.items())),
        strings=tuple(sorted(state.strings.items())),
        baud_rates=tuple(
            (baud, state.tsdr.get(baud)) for baud in BAUD_KEYS if state.supp.get(baud, 0) == 1
        ),
        user_prm_data=state.user_prm,
        placements=tuple(state.placements),
        modules=tuple(_finished(m, state) for m in state.modules),
        prm_texts=tuple(state.prm_texts),
        ext_user_prm=tuple(state.ext),
        slots=tuple(state.slots),
        unit_diag_bits=tuple(state.diag_bits),
        unit_diag_areas=tuple(state.diag_areas),
    )
    for check in _CHECKS:
        check(r, gsd, state)
    return gsd


def _finished(m: _Module, state: _State) -> GsdModule:
    placements = tuple(m.placements)
    length = m.declared_len if m.declared_len is not None else extent(state.ext, placements)
    return GsdModule(m.name, m.config, m.reference, length, placements, m.f_parameters, line=m.line)


def _statement(r: _Reader, lines: list[_Line], i: int, state: _State) -> int:
    """Read the statement at ``lines[i]``; the index of the next one."""
    line = lines[i]
    block = _BLOCKS.get(line.name)
    if block is not None:
        end = _block_end(r, lines, i, block.ends)
        block.read(r, line, lines[i + 1 : end], state)
        return end + 1
    if line.name in _BLOCK_ENDS:
        raise r.error(line, line.key, "closes a block that was never opened")
    _station_line(r, line, state)
    return i + 1


def _block_end(r: _Reader, lines: list[_Line], i: int, ends: tuple[str, ...]) -> int:
    """Index of the line closing the block opened at ``i``."""
    wanted = {e.lower() for e in ends}
    for j in range(i + 1, len(lines)):
        if lines[j].name in wanted:
            return j
        if lines[j].name in _BLOCKS:
            break
    raise r.error(lines[i], lines[i].key, f"has no {ends[0]}")


# ---------------------------------------------------------------------------- station keys


def _station_line(r: _Reader, line: _Line, state: _State) -> None:
    handler = _STATION_KEYS.get(line.name)
    if handler is not None:
        if not line.eq:
            raise r.error(line, line.key, "has no value (Key = value)")
        handler(r, line, state)
        return
    indexed = _indexed(line)
    if indexed is None:
        return  # a key the master does not need
    indexed_handler = _STATION_INDEXED.get(indexed[0])
    if indexed_handler is not None:
        indexed_handler(r, line, indexed[1], state)


def _int_key(r: _Reader, line: _Line, state: _State) -> None:
    state.ints[line.name] = r.number(line, line.value)
    state.lines[line.name] = line.number


def _string_key(r: _Reader, line: _Line, state: _State) -> None:
    state.strings[line.name] = r.string(line, line.value)[0]


def _user_prm_data(r: _Reader, line: _Line, state: _State) -> None:
    state.user_prm = r.byte_list(line, line.value)
    state.lines[line.name] = line.number


def _supp(baud: int, r: _Reader, line: _Line, state: _State) -> None:
    state.supp[baud] = r.number(line, line.value)


def _tsdr(baud: int, r: _Reader, line: _Line, state: _State) -> None:
    state.tsdr[baud] = r.number(line, line.value)


_Handler = Callable[[_Reader, _Line, _State], None]

_STATION_KEYS: Final[Mapping[str, _Handler]] = {
    **dict.fromkeys(INT_KEYS, _int_key),
    **dict.fromkeys(STRING_KEYS, _string_key),
    "user_prm_data": _user_prm_data,
    **{f"{s.lower()}_supp": partial(_supp, baud) for baud, s in BAUD_KEYS.items()},
    **{f"maxtsdr_{s.lower()}": partial(_tsdr, baud) for baud, s in BAUD_KEYS.items()},
}


def _placement(r: _Reader, line: _Line, index: str, *, ref: bool) -> PrmPlacement:
    offset = r.number(line, index)
    if not 0 <= offset < MAX_USER_PRM:
        raise r.error(line, line.key, f"offset {offset} is outside 0-{MAX_USER_PRM - 1}")
    if ref:
        return PrmPlacement(offset, ref=r.number(line, line.value), line=line.number)
    return PrmPlacement(offset, const=r.byte_list(line, line.value), line=line.number)


def _station_placement(ref: bool, r: _Reader, line: _Line, index: str, state: _State) -> None:
    state.placements.append(_placement(r, line, index, ref=ref))


def _diag_bit(inverted: bool, r: _Reader, line: _Line, index: str, state: _State) -> None:
    bit = r.number(line, index)
    if bit < 0:
        raise r.error(line, line.key, f"bit {bit} is negative")
    state.diag_bits.append(UnitDiagBit(bit, r.string(line, line.value)[0], inverted))


_IndexedHandler = Callable[[_Reader, _Line, str, _State], None]

_STATION_INDEXED: Final[Mapping[str, _IndexedHandler]] = {
    "ext_user_prm_data_const": partial(_station_placement, False),
    "ext_user_prm_data_ref": partial(_station_placement, True),
    "unit_diag_bit": partial(_diag_bit, False),
    "unit_diag_not_bit": partial(_diag_bit, True),
}


# ---------------------------------------------------------------------------- Module


def _module(r: _Reader, head: _Line, inner: list[_Line], state: _State) -> None:
    name, rest = r.string(head, head.value)
    if not rest:
        raise r.error(head, head.key, f"module {name!r} has no identifier bytes")
    config = r.byte_list(head, rest)
    try:
        decode_identifiers(config)
    except ProfibusDecodeError as exc:
        raise r.error(head, head.key, f"module {name!r}: {exc.message}") from None
    if any(m.name.casefold() == name.casefold() for m in state.modules):
        raise r.error(head, head.key, f"module {name!r} is defined twice")
    module = _Module(name, config, head.number)
    for line in inner:
        _module_line(r, line, module)
    state.modules.append(module)


def _module_line(r: _Reader, line: _Line, module: _Module) -> None:
    if not line.eq and _NUMBER.match(line.key) and module.reference is None:
        module.reference = r.number(line, line.key, "Module")
        return
    indexed = _indexed(line)
    name = line.name if indexed is None else indexed[0]
    if name.startswith("f_"):
        module.f_parameters = True  # PROFIsafe: F_Ext_Module_Prm_Data_Len, F_Ext_User_Prm_...
    elif name == "ext_module_prm_data_len" and indexed is None:
        module.declared_len = _module_len(r, line)
    elif indexed is not None and name in _PLACEMENT_KEYS:
        ref = _PLACEMENT_KEYS[name]
        module.placements.append(_placement(r, line, indexed[1], ref=ref))


_PLACEMENT_KEYS: Final = {"ext_user_prm_data_const": False, "ext_user_prm_data_ref": True}


def _module_len(r: _Reader, line: _Line) -> int:
    length = r.number(line, line.value)
    if not 0 <= length <= MAX_USER_PRM:
        raise r.error(line, line.key, f"must be 0-{MAX_USER_PRM}")
    return length


# ---------------------------------------------------------------------------- PrmText


def _prm_text(r: _Reader, head: _Line, inner: list[_Line], state: _State) -> None:
    ref = r.number(head, head.value)
    texts: list[tuple[int, str]] = []
    for line in inner:
        indexed = _indexed(line)
        if indexed is None or indexed[0] != "text":
            raise r.error(line, line.key, 'only Text(value) = "text" lines go in a PrmText')
        texts.append((r.number(line, indexed[1]), r.string(line, line.value)[0]))
    if any(p.ref == ref for p in state.prm_texts):
        raise r.error(head, head.key, f"PrmText {ref} is defined twice")
    state.prm_texts.append(PrmText(ref, tuple(texts)))


# ---------------------------------------------------------------------------- ExtUserPrmData


@dataclass
class _ExtBody:
    typed: ExtUserPrmData | None = None
    text_ref: int | None = None
    changeable: bool = True
    visible: bool = True


def _ext_user_prm(r: _Reader, head: _Line, inner: list[_Line], state: _State) -> None:
    m = re.match(r"^(\S+)\s+(.*)$", head.value)
    if m is None:
        raise r.error(head, head.key, 'is not ExtUserPrmData = ref "name"')
    ref = r.number(head, m.group(1))
    name = r.string(head, m.group(2))[0]
    body = _ExtBody()
    for line in inner:
        _ext_line(r, line, ref, name, body)
    if body.typed is None:
        raise r.error(head, head.key, f"ExtUserPrmData {ref} {name!r} has no data type line")
    if any(e.ref == ref for e in state.ext):
        raise r.error(head, head.key, f"ExtUserPrmData {ref} is defined twice")
    state.ext.append(
        replace(
            body.typed,
            prm_text_ref=body.text_ref,
            changeable=body.changeable,
            visible=body.visible,
        )
    )
    state.lines[f"ext{ref}"] = head.number


def _ext_line(r: _Reader, line: _Line, ref: int, name: str, body: _ExtBody) -> None:
    if not line.eq:
        if body.typed is not None:
            raise r.error(line, line.key, f"ExtUserPrmData {ref} has a second data type line")
        body.typed = _data_type(r, line, ref, name)
        return
    setter = _EXT_KEYS.get(line.name)
    if setter is not None:
        setter(r, line, body)  # other keys of later revisions are read over


def _set_text_ref(r: _Reader, line: _Line, body: _ExtBody) -> None:
    body.text_ref = r.number(line, line.value)


def _set_changeable(r: _Reader, line: _Line, body: _ExtBody) -> None:
    body.changeable = r.flag(line)


def _set_visible(r: _Reader, line: _Line, body: _ExtBody) -> None:
    body.visible = r.flag(line)


_EXT_KEYS: Final[Mapping[str, Callable[[_Reader, _Line, _ExtBody], None]]] = {
    "prm_text_ref": _set_text_ref,
    "changeable": _set_changeable,
    "visible": _set_visible,
}


def _data_type(r: _Reader, line: _Line, ref: int, name: str) -> ExtUserPrmData:
    text = line.key
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
    e = ExtUserPrmData(ref, name, TYPE_NAMES[kind], default, low, high, allowed, first, last)
    lo, hi = e.limits()
    if not (lo <= low and high <= hi):
        raise r.error(line, line.key, f"range {low}-{high} does not fit a {e.data_type}")
    if not e.accepts(default):
        raise r.error(line, line.key, f"default {default} is outside its own range")
    return e


def _range(r: _Reader, line: _Line, text: str) -> tuple[int, int, tuple[int, ...]]:
    if _SPAN.match(text) is not None:
        low, high = r.span(line, text)
        return low, high, ()
    values = r.numbers(line, text)
    return min(values), max(values), values


# ---------------------------------------------------------------------------- SlotDefinition


def _slot_definition(r: _Reader, head: _Line, inner: list[_Line], state: _State) -> None:
    for line in inner:
        indexed = _indexed(line)
        if indexed is None or indexed[0] != "slot":
            raise r.error(
                line, line.key, 'only Slot(n) = "name" default allowed lines go in a SlotDefinition'
            )
        number = r.number(line, indexed[1])
        name, rest = r.string(line, line.value)
        parts = rest.split(None, 1)
        if len(parts) != 2:
            raise r.error(line, line.key, f"{rest!r} is not a default module and allowed modules")
        default = r.number(line, parts[0])
        allowed = _module_refs(r, line, parts[1])
        if default not in allowed:
            raise r.error(line, line.key, f"default module {default} is not an allowed one")
        if any(s.number == number for s in state.slots):
            raise r.error(line, line.key, f"slot {number} is defined twice")
        state.slots.append(SlotDef(number, name, default, allowed, line.number))


def _module_refs(r: _Reader, line: _Line, text: str) -> tuple[int, ...]:
    """``1,2,5`` or ``1-4`` (or both, ``1-3,5``): module reference numbers."""
    refs: list[int] = []
    for part in text.split(","):
        if _SPAN.match(part.strip()) is not None:
            low, high = r.span(line, part)
            refs.extend(range(low, high + 1))
        else:
            refs.append(r.number(line, part))
    return tuple(refs)


# ---------------------------------------------------------------------------- Unit_Diag_Area


def _unit_diag_area(r: _Reader, head: _Line, inner: list[_Line], state: _State) -> None:
    first, last = r.span(head, head.value)
    values: list[tuple[int, str]] = []
    for line in inner:
        indexed = _indexed(line)
        name = None if indexed is None else indexed[0]
        if name == "value_help":
            continue  # revision 4 on: help texts
        if indexed is None or name != "value":
            raise r.error(line, line.key, 'only Value(n) = "text" lines go in a Unit_Diag_Area')
        values.append((r.number(line, indexed[1]), r.string(line, line.value)[0]))
    state.diag_areas.append(UnitDiagArea(first, last, tuple(values)))


@dataclass(frozen=True)
class _Block:
    ends: tuple[str, ...]  # the end keywords (the first is named in errors)
    read: Callable[[_Reader, _Line, list[_Line], _State], None]


_BLOCKS: Final[Mapping[str, _Block]] = {
    "module": _Block(("EndModule",), _module),
    "prmtext": _Block(("EndPrmText",), _prm_text),
    "extuserprmdata": _Block(("EndExtUserPrmData",), _ext_user_prm),
    "slotdefinition": _Block(("EndSlotDefinition", "EndSlot_Definition"), _slot_definition),
    "slot_definition": _Block(("EndSlot_Definition", "EndSlotDefinition"), _slot_definition),
    "unit_diag_area": _Block(("Unit_Diag_Area_End",), _unit_diag_area),
}
_BLOCK_ENDS: Final = frozenset(end.lower() for b in _BLOCKS.values() for end in b.ends)


# ---------------------------------------------------------------------------- checks


def _check_ident(r: _Reader, gsd: Gsd, state: _State) -> None:
    if gsd.get("ident_number") is None:
        raise r.error(0, "Ident_Number", "is missing")
    if not 0 <= gsd.ident_number <= 0xFFFF:
        raise r.error(state.lines["ident_number"], "Ident_Number", "must be 0-0xFFFF")


def _check_modules(r: _Reader, gsd: Gsd, state: _State) -> None:
    if not gsd.modules:
        raise r.error(0, "Module", "the file defines no module")


def _check_length(r: _Reader, key: str, value: int | None, state: _State) -> None:
    if value is not None and not 0 <= value <= MAX_USER_PRM:
        raise r.error(state.lines[key], INT_KEYS[key], f"must be 0-{MAX_USER_PRM}")


def _check_max_len(r: _Reader, gsd: Gsd, state: _State) -> None:
    _check_length(r, "max_user_prm_data_len", gsd.get("max_user_prm_data_len"), state)


def _check_legacy(r: _Reader, gsd: Gsd, state: _State) -> None:
    """User_Prm_Data_Len, and User_Prm_Data within it (only where the Ext keywords are
    absent: with them, the specification leaves both unevaluated)."""
    if gsd.ext_prm:
        return
    length = gsd.get("user_prm_data_len")
    _check_length(r, "user_prm_data_len", length, state)
    if length is None or len(gsd.user_prm_data) <= length:
        return
    raise r.error(
        state.lines.get("user_prm_data", 0),
        "User_Prm_Data",
        f"{len(gsd.user_prm_data)} bytes for User_Prm_Data_Len = {length}",
    )


def _check_refs(r: _Reader, gsd: Gsd, state: _State) -> None:
    for p in (*gsd.placements, *(p for m in gsd.modules for p in m.placements)):
        if p.ref is not None and gsd.ext(p.ref) is None:
            raise r.error(p.line, p.keyword, f"no ExtUserPrmData {p.ref} in the file")
    for e in gsd.ext_user_prm:
        if e.prm_text_ref is not None and gsd.prm_text(e.prm_text_ref) is None:
            raise r.error(
                state.lines[f"ext{e.ref}"], "Prm_Text_Ref", f"no PrmText {e.prm_text_ref}"
            )


def _check_station_extent(r: _Reader, gsd: Gsd, state: _State) -> None:
    most, label = user_prm_bound(gsd)
    for p in gsd.placements:
        size = placement_size(gsd.ext_user_prm, p)
        if p.offset + size > most:
            raise r.error(p.line, p.keyword, f"offset {p.offset} + {size} bytes is beyond {label}")


def _check_module_blocks(r: _Reader, gsd: Gsd, state: _State) -> None:
    for raw in state.modules:
        most = MAX_USER_PRM if raw.declared_len is None else raw.declared_len
        label = (
            f"the {MAX_USER_PRM} bytes a Set_Prm carries"
            if raw.declared_len is None
            else f"Ext_Module_Prm_Data_Len = {raw.declared_len}"
        )
        for p in raw.placements:
            size = placement_size(gsd.ext_user_prm, p)
            if p.offset + size > most:
                raise r.error(
                    p.line,
                    p.keyword,
                    f"module {raw.name!r}: offset {p.offset} + {size} bytes is beyond {label}",
                )


def _check_dpv1_status(r: _Reader, gsd: Gsd, state: _State) -> None:
    have = station_prm_len(gsd)
    if gsd.dpv1 and have < DPV1_STATUS_BYTES:
        raise r.error(
            state.lines["dpv1_slave"],
            "DPV1_Slave",
            f"a DP-V1 slave's user parameter data starts with DPV1_Status_1..3; the file "
            f"gives the station {have} byte(s) of it",
        )


def _check_slots(r: _Reader, gsd: Gsd, state: _State) -> None:
    known = {m.reference for m in gsd.modules if m.reference is not None}
    for slot in gsd.slots:
        missing = sorted(set(slot.allowed) - known)
        if missing:
            refs = ", ".join(map(str, missing))
            raise r.error(
                slot.line, f"Slot({slot.number})", f"no module has the reference number {refs}"
            )


_CHECKS: Final[tuple[Callable[[_Reader, Gsd, _State], None], ...]] = (
    _check_ident,
    _check_modules,
    _check_max_len,
    _check_legacy,
    _check_refs,
    _check_station_extent,
    _check_module_blocks,
    _check_dpv1_status,
    _check_slots,
)
"""Cross-checks once the whole file is read (a key can refer to one further down)."""
