"""EDS (Electronic Data Sheet) files: the INI-like text a DeviceNet vendor ships per device.

Sans-IO: :func:`parse_eds` takes the text (and the file name for errors). The format, as
the EDS files of the DeviceNet/CIP specification family write it:

- ``[Section]`` headers; ``Key = field, field, ...;`` entries that may span lines and end
  at ``;``; fields separated by commas, any of them empty; quoted strings ``"..."`` (two
  adjacent quoted strings are one string); ``$`` starts a comment to the end of the line
  (outside quotes). Keywords are compared case-insensitively.
- ``[File]``: DescText, CreateDate, CreateTime, ModDate, ModTime, Revision.
- ``[Device]``: VendCode, VendName, ProdType, ProdTypeStr, ProdCode, MajRev, MinRev,
  ProdName, Catalog (the Identity object attributes 1-4 and 7).
- ``[IO_Info]``: Default (connection bit mask), PollInfo / StrobeInfo / COSInfo /
  CyclicInfo = ``types mask, default input N, default output N``; InputN / OutputN =
  ``size (bytes), bits used, types mask, name, path size, path, help``. Connection type
  bits: 0 poll, 1 strobe, 2 COS, 3 cyclic.
- ``[Params]``: ParamN = 21 fields: reserved, link path size, link path, descriptor, data
  type, data size, name, units, help, min, max, default, scaling multiplier, divisor,
  base, offset, the four scaling links, decimal places. The engineering value is
  ``(raw + offset) * multiplier * base / (divisor * 10 ** decimals)``.

Every error is an :class:`EdsError` naming the file, the line and the key.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from enum import IntFlag

from adapters.devicenet.errors import EdsError

# ---------------------------------------------------------------- the text layer


@dataclass(frozen=True, slots=True)
class Quoted:
    """A quoted string field (``"..."``), as distinct from a bare token."""

    text: str


Field = str | Quoted  # a bare token ("" when the field is empty) or a quoted string


@dataclass(frozen=True, slots=True)
class Entry:
    key: str
    fields: tuple[Field, ...]
    line: int = field(default=0, compare=False)


@dataclass(frozen=True, slots=True)
class Section:
    name: str
    entries: tuple[Entry, ...]
    line: int = field(default=0, compare=False)

    def get(self, key: str) -> Entry | None:
        low = key.lower()
        for entry in self.entries:
            if entry.key.lower() == low:
                return entry
        return None


@dataclass(frozen=True, slots=True)
class Document:
    sections: tuple[Section, ...]

    def section(self, name: str) -> Section | None:
        low = name.lower()
        for s in self.sections:
            if s.name.lower() == low:
                return s
        return None


class _Scanner:
    """Character scanner that knows its line number."""

    def __init__(self, text: str, file: str) -> None:
        self.text, self.file, self.pos, self.line = text, file, 0, 1

    def peek(self) -> str:
        return self.text[self.pos] if self.pos < len(self.text) else ""

    def take(self) -> str:
        ch = self.peek()
        self.pos += 1
        if ch == "\n":
            self.line += 1
        return ch

    def skip_comment(self) -> None:
        while self.peek() not in ("", "\n"):
            self.pos += 1

    def skip_blank(self) -> None:
        while True:
            ch = self.peek()
            if ch == "$":
                self.skip_comment()
            elif ch and ch.isspace():
                self.take()
            else:
                return

    def error(self, key: str, reason: str, line: int | None = None) -> EdsError:
        return EdsError(self.file, line or self.line, key, reason)


def parse_document(text: str, file: str = "<eds>") -> Document:
    """The sections and entries of an EDS text, fields as written (no meaning yet)."""
    sc = _Scanner(text, file)
    sections: list[Section] = []
    name: str | None = None
    start = 0
    entries: list[Entry] = []
    seen: set[str] = set()
    while True:
        sc.skip_blank()
        ch = sc.peek()
        if not ch:
            break
        if ch == "[":
            if name is not None:
                sections.append(Section(name, tuple(entries), start))
            name, start, entries, seen = _header(sc), sc.line, [], set()
            if any(s.name.lower() == name.lower() for s in sections):
                raise sc.error(f"[{name}]", "section appears twice")
            continue
        if name is None:
            raise sc.error("", "an entry before the first [section]")
        entry = _entry(sc, name)
        if entry.key.lower() in seen:
            raise sc.error(f"[{name}] {entry.key}", "key appears twice in its section", entry.line)
        seen.add(entry.key.lower())
        entries.append(entry)
    if name is not None:
        sections.append(Section(name, tuple(entries), start))
    return Document(tuple(sections))


def _header(sc: _Scanner) -> str:
    sc.take()  # "["
    chars: list[str] = []
    while sc.peek() not in ("]", "\n", ""):
        chars.append(sc.take())
    if sc.peek() != "]":
        raise sc.error("[" + "".join(chars).strip(), "section header without ']'")
    sc.take()
    name = "".join(chars).strip()
    if not name:
        raise sc.error("[]", "empty section name")
    return name


def _entry(sc: _Scanner, section: str) -> Entry:
    line = sc.line
    chars: list[str] = []
    while sc.peek() not in ("=", "\n", "", ";", "$"):
        chars.append(sc.take())
    key = "".join(chars).strip()
    where = f"[{section}] {key}"
    if sc.peek() != "=":
        raise sc.error(where, "expected 'key = value;'", line)
    if not key or not all(c.isalnum() or c in "_-." for c in key):
        raise sc.error(where, "is not a keyword", line)
    sc.take()
    return Entry(key, tuple(_fields(sc, where, line)), line)


def _fields(sc: _Scanner, where: str, line: int) -> Iterator[Field]:
    bare: list[str] = []
    quoted: list[str] | None = None
    while True:
        ch = sc.peek()
        if not ch:
            raise sc.error(where, f"no ';' ends the entry begun on line {line}", line)
        if ch == "$":
            sc.skip_comment()
        elif ch == '"':
            if "".join(bare).strip():
                raise sc.error(where, "a quoted string after a bare value in one field")
            quoted = (quoted or []) + [_string(sc, where)]
        elif ch in ",;":
            sc.take()
            yield _field(sc, where, bare, quoted)
            if ch == ";":
                return
            bare, quoted = [], None
        elif quoted is not None and not ch.isspace():
            raise sc.error(where, f"{ch!r} after a quoted string (missing ',')")
        else:
            bare.append(sc.take())


def _field(sc: _Scanner, where: str, bare: list[str], quoted: list[str] | None) -> Field:
    if quoted is not None:
        return Quoted("".join(quoted))
    token = " ".join("".join(bare).split())
    return token


def _number(text: str) -> int:
    """An EDS number: ``0x``-prefixed hex, else decimal, leading zeros allowed (``01``,
    as vendors write revisions); ValueError otherwise."""
    body = text[1:] if text[:1] in "+-" else text
    if body[:2].lower() == "0x":
        value = int(body[2:], 16)
    elif body.isdigit():
        value = int(body, 10)
    else:
        raise ValueError(text)
    return -value if text[:1] == "-" else value


def _string(sc: _Scanner, where: str) -> str:
    line = sc.line
    sc.take()  # opening quote
    chars: list[str] = []
    while True:
        ch = sc.take()
        if ch in ("", "\n"):
            raise sc.error(where, "a quoted string does not end on its line", line)
        if ch == '"':
            return "".join(chars)
        if ch == "\\":
            nxt = sc.take()
            if nxt in ("", "\n"):
                raise sc.error(where, "a quoted string does not end on its line", line)
            chars.append({"n": "\n", "t": "\t"}.get(nxt, nxt))
        else:
            chars.append(ch)


def render_document(doc: Document) -> str:
    """The text of a document; :func:`parse_document` gives it back."""
    out: list[str] = []
    for s in doc.sections:
        out.append(f"[{s.name}]")
        for e in s.entries:
            out.append(f"    {e.key} = {', '.join(_render_field(f) for f in e.fields)};")
        out.append("")
    return "\n".join(out)


def _render_field(f: Field) -> str:
    if isinstance(f, Quoted):
        text = f.text.replace("\\", "\\\\").replace('"', '\\"')
        return '"' + text.replace("\n", "\\n").replace("\t", "\\t") + '"'
    return f


# ---------------------------------------------------------------- the meaning


class ConnectionType(IntFlag):
    """The connection type bits of [IO_Info] masks."""

    POLL = 0x01
    STROBE = 0x02
    COS = 0x04
    CYCLIC = 0x08


@dataclass(frozen=True, slots=True)
class FileInfo:
    description: str = ""
    create_date: str = ""
    create_time: str = ""
    mod_date: str = ""
    mod_time: str = ""
    revision: str = ""


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """[Device]: what the Identity object (class 1) must show."""

    vendor_code: int
    product_type: int
    product_code: int
    major_rev: int
    minor_rev: int
    product_name: str
    vendor_name: str = ""
    product_type_str: str = ""
    catalog: str = ""


@dataclass(frozen=True, slots=True)
class IoEntry:
    """InputN / OutputN: one I/O data image."""

    number: int
    size: int
    bits: int
    types: ConnectionType
    name: str
    path: bytes


@dataclass(frozen=True, slots=True)
class IoConnection:
    """PollInfo / StrobeInfo / COSInfo / CyclicInfo."""

    types: ConnectionType
    default_input: int
    default_output: int


@dataclass(frozen=True, slots=True)
class IoInfo:
    default: ConnectionType = ConnectionType.POLL
    connections: Mapping[ConnectionType, IoConnection] = field(default_factory=dict)
    inputs: Mapping[int, IoEntry] = field(default_factory=dict)
    outputs: Mapping[int, IoEntry] = field(default_factory=dict)

    def sizes(self, kind: ConnectionType) -> tuple[int, int] | None:
        """(input bytes, output bytes) of a connection's default images; None if absent."""
        conn = self.connections.get(kind)
        if conn is None:
            return None
        inp = self.inputs.get(conn.default_input)
        out = self.outputs.get(conn.default_output)
        return (inp.size if inp else 0, out.size if out else 0)


@dataclass(frozen=True, slots=True)
class Param:
    """ParamN: one parameter, its path and its scaling."""

    number: int
    path: bytes
    descriptor: int
    data_type: int
    data_size: int
    name: str
    units: str
    help: str
    minimum: int | None
    maximum: int | None
    default: int | None
    multiplier: int = 1
    divisor: int = 1
    base: int = 1
    offset: int = 0
    decimals: int = 0

    def scale(self, raw: int) -> float:
        """The engineering value of a raw value."""
        value = (raw + self.offset) * self.multiplier * self.base
        return float(value) / float(self.divisor * 10**self.decimals)


@dataclass(frozen=True, slots=True)
class Eds:
    file: str
    info: FileInfo
    device: DeviceInfo
    io: IoInfo
    params: Mapping[int, Param]


def decode_eds(raw: bytes, name: str = "<eds>") -> Eds:
    """Parse an EDS file's bytes; ``name`` names it in errors. The format's text is ASCII;
    vendors' files carry other bytes in comments and strings (a unit in degrees, a name
    in their language), written by their tools as UTF-8 (with or without a byte order
    mark) or ISO-8859-1: UTF-8 when the bytes are UTF-8, ISO-8859-1 otherwise (every byte
    is a character there). A NUL byte is no text. Reading the file is the caller's
    (``adapters.devicenet.options.load_eds``)."""
    if raw.startswith(_BOM):
        raw = raw[len(_BOM) :]
    nul = raw.find(b"\0")
    if nul >= 0:
        line = raw[:nul].count(b"\n") + 1
        raise EdsError(name, line, "", "byte 0x00 is not text")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("iso-8859-1")
    return parse_eds(text, name)


_BOM = b"\xef\xbb\xbf"


def parse_eds(text: str, file: str = "<eds>") -> Eds:
    doc = parse_document(text.replace("\r\n", "\n"), file)
    return Eds(
        file=file,
        info=_file_info(doc, file),
        device=_device(doc, file),
        io=_io_info(doc, file),
        params=_params(doc, file),
    )


class _Reader:
    """Typed access to one entry's fields, errors naming file, line and key."""

    def __init__(self, file: str, section: str, entry: Entry) -> None:
        self.file, self.entry = file, entry
        self.where = f"[{section}] {entry.key}"

    def error(self, reason: str) -> EdsError:
        return EdsError(self.file, self.entry.line, self.where, reason)

    def raw(self, index: int) -> Field:
        fields = self.entry.fields
        return fields[index] if index < len(fields) else ""

    def need(self, count: int) -> None:
        if len(self.entry.fields) < count:
            raise self.error(f"has {len(self.entry.fields)} fields, {count} expected")

    def integer(self, index: int, what: str, lo: int, hi: int) -> int:
        value = self.optional(index, what, lo, hi)
        if value is None:
            raise self.error(f"field {index + 1} ({what}) is empty")
        return value

    def optional(self, index: int, what: str, lo: int, hi: int) -> int | None:
        f = self.raw(index)
        if isinstance(f, Quoted):
            raise self.error(f"field {index + 1} ({what}) is a string, a number expected")
        if not f:
            return None
        try:
            value = _number(f)
        except ValueError:
            raise self.error(f"field {index + 1} ({what}) {f!r} is not a number") from None
        if not lo <= value <= hi:
            raise self.error(f"field {index + 1} ({what}) {value} is outside {lo}..{hi}")
        return value

    def string(self, index: int, what: str) -> str:
        f = self.raw(index)
        if isinstance(f, Quoted):
            return f.text
        if f:
            raise self.error(f"field {index + 1} ({what}) must be a quoted string")
        return ""

    def path(self, index: int, what: str) -> bytes:
        text = self.string(index, what)
        try:
            return bytes.fromhex(text)
        except ValueError:
            raise self.error(f"field {index + 1} ({what}) {text!r} is not hex bytes") from None


def _need_section(doc: Document, file: str, name: str) -> Section:
    s = doc.section(name)
    if s is None:
        raise EdsError(file, 0, f"[{name}]", "section missing")
    return s


def _need_entry(file: str, s: Section, key: str) -> _Reader:
    e = s.get(key)
    if e is None:
        raise EdsError(file, s.line, f"[{s.name}] {key}", "key missing")
    return _Reader(file, s.name, e)


def _text(file: str, s: Section | None, key: str) -> str:
    if s is None:
        return ""
    e = s.get(key)
    return "" if e is None else _Reader(file, s.name, e).string(0, key)


def _bare(file: str, s: Section | None, key: str) -> str:
    if s is None:
        return ""
    e = s.get(key)
    if e is None:
        return ""
    f = e.fields[0] if e.fields else ""
    return f.text if isinstance(f, Quoted) else f


def _file_info(doc: Document, file: str) -> FileInfo:
    s = _need_section(doc, file, "File")
    return FileInfo(
        description=_text(file, s, "DescText"),
        create_date=_bare(file, s, "CreateDate"),
        create_time=_bare(file, s, "CreateTime"),
        mod_date=_bare(file, s, "ModDate"),
        mod_time=_bare(file, s, "ModTime"),
        revision=_bare(file, s, "Revision"),
    )


def _device(doc: Document, file: str) -> DeviceInfo:
    s = _need_section(doc, file, "Device")

    def num(key: str, hi: int) -> int:
        return _need_entry(file, s, key).integer(0, key, 0, hi)

    return DeviceInfo(
        vendor_code=num("VendCode", 0xFFFF),
        product_type=num("ProdType", 0xFFFF),
        product_code=num("ProdCode", 0xFFFF),
        major_rev=num("MajRev", 0x7F),  # Identity attribute 4: USINT major, 7 bits used
        minor_rev=num("MinRev", 0xFF),
        product_name=_need_entry(file, s, "ProdName").string(0, "ProdName"),
        vendor_name=_text(file, s, "VendName"),
        product_type_str=_text(file, s, "ProdTypeStr"),
        catalog=_text(file, s, "Catalog"),
    )


_CONNECTION_KEYS = {
    "pollinfo": ConnectionType.POLL,
    "strobeinfo": ConnectionType.STROBE,
    "cosinfo": ConnectionType.COS,
    "cyclicinfo": ConnectionType.CYCLIC,
}
_ALL_TYPES = 0xFFFF


def _io_info(doc: Document, file: str) -> IoInfo:
    s = doc.section("IO_Info")
    if s is None:
        return IoInfo()
    default = ConnectionType.POLL
    connections: dict[ConnectionType, IoConnection] = {}
    images: dict[str, dict[int, IoEntry]] = {"input": {}, "output": {}}
    for e in s.entries:
        r = _Reader(file, s.name, e)
        low = e.key.lower()
        if low == "default":
            default = ConnectionType(r.integer(0, "connection mask", 0, 0x0F))
        elif low in _CONNECTION_KEYS:
            r.need(3)
            connections[_CONNECTION_KEYS[low]] = IoConnection(
                ConnectionType(r.integer(0, "connection mask", 0, _ALL_TYPES) & 0x0F),
                r.integer(1, "default input", 0, 0xFFFF),
                r.integer(2, "default output", 0, 0xFFFF),
            )
        else:
            image, number = _numbered(low, ("input", "output"))
            if image is not None:
                images[image][number] = _io_entry(r, number)
    for conn_type, conn in connections.items():
        for table, n, what in (
            (images["input"], conn.default_input, "Input"),
            (images["output"], conn.default_output, "Output"),
        ):
            if n and n not in table:
                key = next(k for k, v in _CONNECTION_KEYS.items() if v is conn_type)
                e = next(x for x in s.entries if x.key.lower() == key)
                raise EdsError(file, e.line, f"[{s.name}] {e.key}", f"names {what}{n}, not defined")
    return IoInfo(default, connections, images["input"], images["output"])


def _numbered(low: str, prefixes: tuple[str, ...]) -> tuple[str | None, int]:
    for prefix in prefixes:
        rest = low[len(prefix) :]
        if low.startswith(prefix) and rest.isdigit() and int(rest) > 0:
            return prefix, int(rest)
    return None, 0


def _io_entry(r: _Reader, number: int) -> IoEntry:
    r.need(6)
    size = r.integer(0, "size", 0, 0xFFFF)
    bits = r.integer(1, "bits used", 0, 0xFFFF)
    types = ConnectionType(r.integer(2, "connection mask", 0, _ALL_TYPES) & 0x0F)
    name = r.string(3, "name")
    path_size = r.integer(4, "path size", 0, 0xFF)
    path = r.path(5, "path")
    if len(path) != path_size:
        raise r.error(f"the path has {len(path)} bytes, its size field says {path_size}")
    return IoEntry(number, size, bits, types, name, path)


PARAM_FIELDS = 21
_DATA_SIZES = {
    0xC1: 1,  # BOOL
    0xC2: 1,  # SINT
    0xC3: 2,  # INT
    0xC4: 4,  # DINT
    0xC5: 8,  # LINT
    0xC6: 1,  # USINT
    0xC7: 2,  # UINT
    0xC8: 4,  # UDINT
    0xC9: 8,  # ULINT
    0xCA: 4,  # REAL
    0xCB: 8,  # LREAL
    0xD1: 1,  # BYTE
    0xD2: 2,  # WORD
    0xD3: 4,  # DWORD
    0xD4: 8,  # LWORD
}
_SIGNED = frozenset((0xC2, 0xC3, 0xC4, 0xC5))
INTEGER_TYPES = frozenset(_DATA_SIZES) - {0xCA, 0xCB}


def _params(doc: Document, file: str) -> dict[int, Param]:
    s = doc.section("Params")
    out: dict[int, Param] = {}
    if s is None:
        return out
    for e in s.entries:
        kind, number = _numbered(e.key.lower(), ("param",))
        if kind is None:
            continue
        r = _Reader(file, s.name, e)
        if r.integer(4, "data type", 0, 0xFF) in INTEGER_TYPES:
            out[number] = _param(r, number)
        else:  # a REAL, a string...: its path and size checked, the parameter left out
            _other_param(r)
    return out


def _other_param(r: _Reader) -> None:
    """A parameter whose data type is no integer (REAL, LREAL, a string, a structure):
    the gateway reads and writes integers only, so it is left out of the parameters;
    its link path and data size are still checked."""
    r.need(PARAM_FIELDS - 1)
    _link_path(r)
    data_type = r.integer(4, "data type", 0, 0xFF)
    data_size = r.integer(5, "data size", 0, 0xFF)
    expected = _DATA_SIZES.get(data_type)
    if expected is not None and data_size != expected:
        raise r.error(f"data type 0x{data_type:02X} is {expected} bytes, not {data_size}")


def _link_path(r: _Reader) -> bytes:
    """Fields 2-3: the link path and its size; both empty for a parameter linked to no
    attribute (configuration tools write ``, ,,`` for one that only a configuration
    assembly carries)."""
    size = r.optional(1, "link path size", 0, 0xFF)
    path = r.path(2, "link path")
    if len(path) != (size or 0):
        raise r.error(f"the link path has {len(path)} bytes, its size field says {size or 0}")
    return path


def _param(r: _Reader, number: int) -> Param:
    r.need(PARAM_FIELDS - 1)  # the decimal places may be left out
    path = _link_path(r)
    data_type = r.integer(4, "data type", 0, 0xFF)
    data_size = r.integer(5, "data size", 0, 0xFF)
    expected = _DATA_SIZES.get(data_type)
    if expected is not None and data_size != expected:
        raise r.error(f"data type 0x{data_type:02X} is {expected} bytes, not {data_size}")
    lo, hi = _range(data_type, data_size)
    minimum = r.optional(9, "min", lo, hi)
    maximum = r.optional(10, "max", lo, hi)
    default = r.optional(11, "default", lo, hi)
    if minimum is not None and maximum is not None and minimum > maximum:
        raise r.error(f"min {minimum} is above max {maximum}")
    if default is not None and not _within(default, minimum, maximum):
        raise r.error(f"default {default} is outside min..max")
    divisor = _scaling(r, 13, "divisor")
    if divisor == 0:
        raise r.error("field 14 (divisor) is 0")
    return Param(
        number=number,
        path=path,
        descriptor=r.integer(3, "descriptor", 0, 0xFFFF),
        data_type=data_type,
        data_size=data_size,
        name=r.string(6, "name"),
        units=r.string(7, "units"),
        help=r.string(8, "help"),
        minimum=minimum,
        maximum=maximum,
        default=default,
        multiplier=_scaling(r, 12, "multiplier"),
        divisor=divisor,
        base=_scaling(r, 14, "base"),
        offset=r.optional(15, "offset", -0x8000, 0xFFFF) or 0,
        decimals=r.optional(20, "decimal places", 0, 15) or 0,
    )


def _scaling(r: _Reader, index: int, what: str) -> int:
    value = r.optional(index, what, 0, 0xFFFF)
    return 1 if value is None else value


def _range(data_type: int, data_size: int) -> tuple[int, int]:
    bits = 8 * max(data_size, 1)
    if data_type in _SIGNED:  # SINT, INT, DINT, LINT
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    return 0, (1 << bits) - 1


def _within(value: int, lo: int | None, hi: int | None) -> bool:
    return (lo is None or value >= lo) and (hi is None or value <= hi)
