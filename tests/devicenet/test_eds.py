"""The EDS parser: the project's CFW-08 test file parsed field by field, round trips of
the text layer by hypothesis, and bad files with errors naming file, line and key."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.devicenet.codec.eds import (
    ConnectionType,
    DeviceInfo,
    Document,
    Entry,
    Quoted,
    Section,
    parse_document,
    parse_eds,
    render_document,
)
from adapters.devicenet.errors import EdsError
from adapters.devicenet.options import load_eds
from gateway.errors import ConfigError, GatewayError

ROOT = Path(__file__).resolve().parents[2]
CFW08_EDS = ROOT / "config" / "eds" / "cfw08-test.eds"


def test_cfw08_test_file_golden() -> None:
    eds = load_eds(CFW08_EDS)
    assert eds.device == DeviceInfo(
        vendor_code=0x355,
        product_type=2,
        product_code=8,
        major_rev=4,
        minor_rev=6,
        product_name="CFW-08",
        vendor_name="WEG",
        product_type_str="AC Drive",
        catalog="KFB-DN-CFW-08",
    )
    assert eds.info.revision == "1.0" and eds.info.create_date == "11-24-2026"
    assert eds.info.description == "CFW-08 DeviceNet (drive-gateway test file)"
    io = eds.io
    assert io.default is ConnectionType.POLL
    assert set(io.connections) == {ConnectionType.POLL, ConnectionType.COS, ConnectionType.CYCLIC}
    assert io.sizes(ConnectionType.POLL) == (4, 4)
    assert io.sizes(ConnectionType.STROBE) is None
    assert io.inputs[1].path == bytes.fromhex("20 04 24 47 30 03")  # assembly 71
    assert io.outputs[1].path == bytes.fromhex("20 04 24 15 30 03")  # assembly 21
    assert io.inputs[1].name == "Extended Speed Status"
    assert io.inputs[1].types == ConnectionType.POLL | ConnectionType.COS | ConnectionType.CYCLIC
    p = eds.params[1]
    assert (p.name, p.units, p.help) == ("Acceleration time", "s", "ramp 1 acceleration")
    assert (p.minimum, p.maximum, p.default) == (1, 9990, 50)
    assert (p.multiplier, p.divisor, p.base, p.offset, p.decimals) == (1, 1, 1, 0, 1)
    assert (p.data_type, p.data_size, p.descriptor) == (0xC7, 2, 0)
    assert p.path == bytes.fromhex("20 65 24 01 30 64")
    assert p.scale(50) == 5.0
    assert eds.params[4].scale(1720) == 1720.0
    assert sorted(eds.params) == [1, 2, 3, 4, 5]


def test_scaling_formula() -> None:
    text = _eds(
        '[Params]\nParam1 = 0, 0, "", 0, 0xC3, 2, "T", "degC", "", -100, 100, 0, '
        "3, 4, 2, 10, , , , , 1;\n"
    )
    # (raw + offset) * multiplier * base / (divisor * 10 ** decimals)
    assert parse_eds(text).params[1].scale(2) == (2 + 10) * 3 * 2 / (4 * 10)


def test_syntax_details() -> None:
    doc = parse_document(
        '$ comment\n[a]\n  Key = 1, , "x $ not a comment" "y", 0x10 $ tail\n  ;\n'
        '[B]\nEmpty = ;\nTwo="a\\"b";\n'
    )
    assert doc.sections[0] == Section(
        "a", (Entry("Key", ("1", "", Quoted("x $ not a commenty"), "0x10")),)
    )
    assert doc.section("b") is not None and doc.section("b").get("empty") == Entry("Empty", ("",))  # type: ignore[union-attr]
    assert doc.sections[1].entries[1].fields == (Quoted('a"b'),)
    assert doc.sections[0].entries[0].line == 3


# ---------------------------------------------------------------- hypothesis round trips

_key = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True)
_bare = st.from_regex(r"(0x[0-9A-F]{1,4}|-?[0-9]{1,5}|[0-9]{2}-[0-9]{2}-[0-9]{4}|)", fullmatch=True)
_quoted = st.builds(
    Quoted, st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=20)
)
_field = st.one_of(_bare, _quoted)


@st.composite
def documents(draw: st.DrawFn) -> Document:
    names = draw(st.lists(_key, min_size=1, max_size=4, unique_by=str.lower))
    sections = []
    for name in names:
        keys = draw(st.lists(_key, max_size=5, unique_by=str.lower))
        entries = tuple(
            Entry(k, tuple(draw(st.lists(_field, min_size=1, max_size=6)))) for k in keys
        )
        sections.append(Section(name, entries))
    return Document(tuple(sections))


@given(documents())
def test_document_round_trip(doc: Document) -> None:
    assert parse_document(render_document(doc)) == doc


@given(
    st.tuples(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)),
    st.tuples(st.integers(0, 0x7F), st.integers(0, 0xFF)),
    st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=32),
    st.tuples(st.integers(0, 64), st.integers(0, 64)),
)
def test_device_and_sizes_round_trip(
    ids: tuple[int, int], rev: tuple[int, int], name: str, sizes: tuple[int, int]
) -> None:
    (vendor, code), (major, minor), (size_in, size_out) = ids, rev, sizes
    doc = Document(
        (
            Section("File", (Entry("Revision", ("1.0",)),)),
            Section(
                "Device",
                (
                    Entry("VendCode", (hex(vendor),)),
                    Entry("ProdType", ("2",)),
                    Entry("ProdCode", (str(code),)),
                    Entry("MajRev", (str(major),)),
                    Entry("MinRev", (str(minor),)),
                    Entry("ProdName", (Quoted(name),)),
                ),
            ),
            Section(
                "IO_Info",
                (
                    Entry("PollInfo", ("0x0001", "1", "1")),
                    Entry("Input1", (str(size_in), "0", "0x0001", Quoted("in"), "0", Quoted(""))),
                    Entry("Output1", (str(size_out), "0", "0x0001", Quoted("o"), "0", Quoted(""))),
                ),
            ),
        )
    )
    eds = parse_eds(render_document(doc))
    dev = eds.device
    assert (dev.vendor_code, dev.product_code, dev.major_rev, dev.minor_rev) == (
        vendor,
        code,
        major,
        minor,
    )
    assert dev.product_name == name
    assert eds.io.sizes(ConnectionType.POLL) == (size_in, size_out)


# ---------------------------------------------------------------- bad files

DEVICE = (
    "[Device]\nVendCode = 853;\nProdType = 2;\nProdCode = 8;\nMajRev = 4;\nMinRev = 6;\n"
    'ProdName = "CFW-08";\n'
)


def _eds(extra: str = "", device: str = DEVICE) -> str:
    return "[File]\nRevision = 1.0;\n" + device + extra


BAD = [
    (
        "[File]\nRevision = 1.0\n",
        "t.eds: line 2: [File] Revision: no ';' ends the entry begun on line 2",
    ),
    ("Key = 1;\n", "t.eds: line 1: an entry before the first [section]"),
    ("[File\n", "t.eds: line 1: [File: section header without ']'"),
    ("[File]\n[File]\n", "t.eds: line 2: [File]: section appears twice"),
    ("[File]\nA = 1;\na = 2;\n", "t.eds: line 3: [File] a: key appears twice in its section"),
    ("[File]\nA 1;\n", "t.eds: line 2: [File] A 1: expected 'key = value;'"),
    ('[File]\nA = "abc;\n', "t.eds: line 2: [File] A: a quoted string does not end on its line"),
    ('[File]\nA = "a" b;\n', "t.eds: line 2: [File] A: 'b' after a quoted string (missing ',')"),
    ("[File]\n", "t.eds: [Device]: section missing"),
    (
        _eds(device=DEVICE.replace("ProdCode = 8;\n", "")),
        "t.eds: line 3: [Device] ProdCode: key missing",
    ),
    (
        _eds(device=DEVICE.replace("853", "0x10000")),
        "t.eds: line 4: [Device] VendCode: field 1 (VendCode) 65536 is outside 0..65535",
    ),
    (
        _eds(device=DEVICE.replace("= 2;", "= two;")),
        "t.eds: line 5: [Device] ProdType: field 1 (ProdType) 'two' is not a number",
    ),
    (
        _eds(device=DEVICE.replace('"CFW-08"', "CFW-08")),
        "t.eds: line 9: [Device] ProdName: field 1 (ProdName) must be a quoted string",
    ),
    (
        _eds("[IO_Info]\nPollInfo = 1, 1, 1;\n"),
        "t.eds: line 11: [IO_Info] PollInfo: names Input1, not defined",
    ),
    (
        _eds('[IO_Info]\nInput1 = 4, 0, 1, "x", 2, "20 04 24";\n'),
        "t.eds: line 11: [IO_Info] Input1: the path has 3 bytes, its size field says 2",
    ),
    (
        _eds('[IO_Info]\nInput1 = 4, 0, 1, "x", 2, "2G";\n'),
        "t.eds: line 11: [IO_Info] Input1: field 6 (path) '2G' is not hex bytes",
    ),
    (
        _eds('[Params]\nParam1 = 0, 0, "", 0, 0xC7, 2;\n'),
        "t.eds: line 11: [Params] Param1: has 6 fields, 20 expected",
    ),
    (
        _eds('[Params]\nParam1 = 0,0,"",0,0xC7,2,"n","u","h",10,5,7,1,1,1,0,,,,,0;\n'),
        "t.eds: line 11: [Params] Param1: min 10 is above max 5",
    ),
    (
        _eds('[Params]\nParam1 = 0,0,"",0,0xC7,2,"n","u","h",0,5,7,1,1,1,0,,,,,0;\n'),
        "t.eds: line 11: [Params] Param1: default 7 is outside min..max",
    ),
    (
        _eds('[Params]\nParam1 = 0,0,"",0,0xC7,2,"n","u","h",-1,5,0,1,1,1,0,,,,,0;\n'),
        "t.eds: line 11: [Params] Param1: field 10 (min) -1 is outside 0..65535",
    ),
    (
        _eds('[Params]\nParam1 = 0,0,"",0,0xC7,4,"n","u","h",0,5,0,1,1,1,0,,,,,0;\n'),
        "t.eds: line 11: [Params] Param1: data type 0xC7 is 2 bytes, not 4",
    ),
    (
        _eds('[Params]\nParam1 = 0,0,"",0,0xC7,2,"n","u","h",0,5,0,1,0,1,0,,,,,0;\n'),
        "t.eds: line 11: [Params] Param1: field 14 (divisor) is 0",
    ),
]


@pytest.mark.parametrize(("text", "message"), BAD)
def test_bad_files(text: str, message: str) -> None:
    with pytest.raises(EdsError) as info:
        parse_eds(text, "t.eds")
    assert str(info.value) == message
    assert isinstance(info.value, ConfigError) and isinstance(info.value, GatewayError)


def test_bad_bytes_and_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "x.eds"
    path.write_bytes(b"[File]\n$ caf\x00\n")
    with pytest.raises(EdsError, match=r"x\.eds: line 2: byte 0x00 is not text"):
        load_eds(path)
    with pytest.raises(EdsError, match=r"missing\.eds: does not exist"):
        load_eds(tmp_path / "missing.eds")


def test_multi_line_entry_reports_its_first_line() -> None:
    text = _eds('[Params]\nParam1 =\n 0,\n 0,\n "",\n 0, 0xC7, 9;\n')
    with pytest.raises(EdsError) as info:
        parse_eds(text, "t.eds")
    assert info.value.line == 11
