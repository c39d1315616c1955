"""The CANopen EDS/DCF corpus (tests/data/eds/corpus/canopen, written from CiA 306 in the
styles vendors' tools use): each file loaded by the drive's loader (``read_eds`` and
``Dictionary``) and its objects compared with what was worked out by hand, and, where the
canopen library reads the file as written, with the library's own ``import_od`` of the
same file, object by object. The loader reads three files the library refuses as written:
sub-index sections before their object with keywords in another case, a CompactSubObj's
names before the array, and ISO-8859-1 text (before, the loader refused all three)."""

from __future__ import annotations

from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import ObjectDictionary, ODArray, ODRecord, ODVariable

from adapters.canopen.codec.od import Dictionary, canonical_text
from adapters.canopen.errors import EdsError
from adapters.canopen.options import read_eds
from adapters.canopen.sim.node import load_od
from gateway.config import parse as parse_config
from gateway.errors import ConfigErrors

CORPUS = Path(__file__).parents[1] / "data" / "eds" / "corpus" / "canopen"
NODE = 5

# (index, sub): (name, data type, access, default, min, max, mappable, DCF value, unit)
Row = tuple[str, int, str, object, object, object, bool, object, str]
IDENTITY: dict[tuple[int, int], Row] = {
    (0x1000, 0): ("Device type", 7, "ro", 0x00020192, None, None, False, None, ""),
    (0x1001, 0): ("Error register", 5, "ro", 0, None, None, False, None, ""),
}
GOLDEN: dict[str, dict[tuple[int, int], Row]] = {
    "minimal.eds": {
        (0x1000, 0): ("Device type", 7, "ro", 0x191, None, None, False, None, ""),
        (0x1001, 0): ("Error register", 5, "ro", 0, None, None, True, None, ""),
        (0x1018, 0): ("Highest sub-index supported", 5, "const", 1, None, None, False, None, ""),
        (0x1018, 1): ("Vendor-ID", 7, "ro", 0x4D2, None, None, False, None, ""),
    },
    "vendor-tool.eds": {
        **{
            (i, 0): (f"Dummy000{i}", i, "const", None, None, None, False, None, "")
            for i in (2, 5, 6, 7)
        },
        (0x1000, 0): IDENTITY[(0x1000, 0)],
        (0x1001, 0): ("Error register", 5, "ro", 0, None, None, True, None, ""),
        (0x1003, 0): ("Number of entries", 5, "rw", None, None, None, False, None, ""),
        (0x1003, 1): ("Pre-defined error field", 7, "ro", None, None, None, False, None, ""),
        (0x1017, 0): ("Producer heartbeat time", 6, "rw", 0, None, None, False, None, ""),
        (0x1018, 0): ("Number of entries", 5, "const", 2, None, None, False, None, ""),
        (0x1018, 1): ("Vendor-ID", 7, "ro", 0x123, None, None, False, None, ""),
        (0x1018, 2): ("Product code", 7, "ro", 0x2200, None, None, False, None, ""),
        (0x1400, 0): ("Highest sub-index supported", 5, "const", 2, None, None, False, None, ""),
        (0x1400, 1): ("COB-ID used by RPDO1", 7, "rw", 0x200 + NODE, None, None, False, None, ""),
        (0x1400, 2): ("Transmission type", 5, "rw", 0xFF, None, None, False, None, ""),
        (0x1600, 0): ("Number of mapped objects", 5, "rw", 2, None, None, False, None, ""),
        (0x1600, 1): ("Mapped object 1", 7, "rw", 0x60400010, None, None, False, None, ""),
        (0x1600, 2): ("Mapped object 2", 7, "rw", 0x60420010, None, None, False, None, ""),
        (0x1800, 0): ("Highest sub-index supported", 5, "const", 2, None, None, False, None, ""),
        (0x1800, 1): ("COB-ID used by TPDO1", 7, "rw", 0x180 + NODE, None, None, False, None, ""),
        (0x1800, 2): ("Transmission type", 5, "rw", 0xFF, None, None, False, None, ""),
        (0x1A00, 0): ("Number of mapped objects", 5, "rw", 1, None, None, False, None, ""),
        (0x1A00, 1): ("Mapped object 1", 7, "rw", 0x60410010, None, None, False, None, ""),
        (0x2001, 0): ("Acceleration time", 8, "rw", 2.5, None, None, False, None, "s"),
        (0x2002, 0): ("Torque offset", 4, "rw", -1000, -(2**31), 2**31 - 1, True, None, ""),
        (0x6040, 0): ("Controlword", 6, "rww", 0, None, None, True, None, ""),
        (0x6041, 0): ("Statusword", 6, "ro", 0, None, None, True, None, ""),
        (0x6042, 0): ("vl target velocity", 3, "rww", 0, -3000, 3000, True, None, ""),
        (0x6044, 0): ("vl velocity actual value", 3, "ro", 0, None, None, True, None, ""),
        (0x6046, 0): ("Number of entries", 5, "const", 2, None, None, False, None, ""),
        (0x6046, 1): ("vl velocity min amount", 7, "rw", 0, None, None, False, None, ""),
        (0x6046, 2): ("vl velocity max amount", 7, "rw", 1500, None, None, False, None, ""),
        (0x6060, 0): ("Modes of operation", 2, "rw", 2, None, None, True, None, ""),
    },
    "reordered.eds": {
        **IDENTITY,
        (0x1018, 0): ("Number of entries", 5, "const", 1, None, None, False, None, ""),
        (0x1018, 1): ("Vendor-ID", 7, "ro", 0x355, None, None, False, None, ""),
        (0x6041, 0): ("Statusword", 6, "ro", None, None, None, True, None, ""),
    },
    "node5.dcf": {
        (0x1000, 0): ("Device type", 7, "ro", 0x00020192, None, None, False, 0x00020192, ""),
        (0x1001, 0): IDENTITY[(0x1001, 0)],
        (0x1017, 0): ("Producer heartbeat time", 6, "rw", 0, None, None, False, 200, ""),
        (0x1018, 0): ("Number of entries", 5, "const", 1, None, None, False, None, ""),
        (0x1018, 1): ("Vendor-ID", 7, "ro", 0x123, None, None, False, None, ""),
        (0x1800, 0): ("Highest sub-index supported", 5, "const", 1, None, None, False, None, ""),
        (0x1800, 1): ("COB-ID used by TPDO1", 7, "rw", 0x185, None, None, False, 0x185, ""),
        (0x6042, 0): ("vl target velocity", 3, "rww", 0, -3000, 3000, True, -1500, ""),
    },
    "compact.eds": {
        (0x1000, 0): ("Device type", 7, "ro", 0x191, None, None, False, None, ""),
        (0x1001, 0): IDENTITY[(0x1001, 0)],
        (0x1003, 0): ("Number of entries", 5, "rw", None, None, None, False, None, ""),
        (0x1003, 1): ("Newest error", 7, "ro", None, None, None, False, None, ""),
        (0x1003, 2): ("Older error", 7, "ro", None, None, None, False, None, ""),
    },
    "latin1.eds": {
        (0x1000, 0): ("Gerätetyp", 7, "ro", 0x00020192, None, None, False, None, ""),
        (0x1001, 0): ("Fehlerregister", 5, "ro", 0, None, None, False, None, ""),
        (0x2010, 0): ("Kühlkörpertemperatur", 3, "ro", 25, -40, 150, True, None, "°C"),
    },
}
# the files the library reads as written, compared with it object by object
LIBRARY_READS = ("minimal.eds", "vendor-tool.eds", "node5.dcf")


def test_the_corpus_is_the_golden_table() -> None:
    assert sorted(p.name for p in CORPUS.iterdir() if p.suffix != ".md") == sorted(GOLDEN)


def loaded(name: str) -> Dictionary:
    path = CORPUS / name
    return Dictionary(path, NODE, read_eds(path))


def rows(od: ObjectDictionary) -> dict[tuple[int, int], Row]:
    out: dict[tuple[int, int], Row] = {}
    for entry in od.values():
        members = entry.values() if isinstance(entry, ODRecord | ODArray) else [entry]
        for var in members:
            if isinstance(var, ODVariable):
                out[(var.index, var.subindex)] = (
                    var.name,
                    int(var.data_type or 0),
                    var.access_type,
                    var.default,
                    var.min,
                    var.max,
                    bool(var.pdo_mappable),
                    getattr(var, "value", None),
                    var.unit or "",
                )
    return out


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_each_file_loads_as_worked_out(name: str) -> None:
    eds = loaded(name)
    assert rows(eds.od) == GOLDEN[name]
    for index, sub in GOLDEN[name]:
        assert eds.has(index, sub)
        assert eds.variable(index, sub).name == GOLDEN[name][(index, sub)][0]


@pytest.mark.parametrize("name", LIBRARY_READS)
def test_the_loader_reads_what_the_library_reads(name: str) -> None:
    library = canopen.import_od(str(CORPUS / name), NODE)
    assert rows(loaded(name).od) == rows(library)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_the_library_refuses_three_files_the_loader_reads() -> None:
    with pytest.raises(KeyError, match="0x1018 was not found"):
        canopen.import_od(str(CORPUS / "reordered.eds"), NODE)
    with pytest.raises(KeyError, match="0x1003 was not found"):
        canopen.import_od(str(CORPUS / "compact.eds"), NODE)
    with pytest.raises(UnicodeDecodeError):
        canopen.import_od(str(CORPUS / "latin1.eds"), NODE)


def test_the_canonical_text_is_what_the_library_reads_in_order() -> None:
    text = canonical_text((CORPUS / "reordered.eds").read_text())
    headers = [line for line in text.splitlines() if line.startswith("[")]
    assert headers == [
        "[6041]",
        "[1018]",
        "[1000]",
        "[1001]",
        "[MandatoryObjects]",
        "[DeviceInfo]",
        "[FileInfo]",
        "[1018sub1]",
        "[1018sub0]",
    ]
    assert "ParameterName=Vendor-ID" in text.splitlines()
    assert "AccessType=RO" in text.splitlines()  # values as written


def test_the_dcf_node_id_and_its_values_reach_the_gateway() -> None:
    eds = loaded("node5.dcf")
    assert eds.variable(0x1800, 1).default == 0x185
    assert eds.variable(0x6042).encode(-1500) == (-1500).to_bytes(2, "little", signed=True)


def test_a_nul_byte_is_no_text(tmp_path: Path) -> None:
    path = tmp_path / "nul.eds"
    path.write_bytes((CORPUS / "minimal.eds").read_bytes().replace(b"Minimal", b"Mini\0al"))
    with pytest.raises(EdsError, match="line 11: byte 0x00"):
        Dictionary(path, NODE, read_eds(path))


def drive_table(name: str, **keys: object) -> dict[str, object]:
    drive = {"id": "a", "device": "CiA 402", "address": NODE, "eds": str(CORPUS / name), **keys}
    bus = {"adapter": "canopen", "interface": "virtual", "channel": "corpus", "simulate": True}
    return {"buses": {"co": {**bus, "drives": [drive]}}}


def test_a_vendor_tool_s_eds_configures_a_drive() -> None:
    """The same reading check-config and run make: the objects the gateway needs, their
    PDO mapping flags, and ``max_rpm`` from 0x6046:2's default."""
    config = parse_config(drive_table("vendor-tool.eds"), "site.toml")
    options = config.buses[0].drives[0].options
    assert options.max_rpm == 1500.0
    assert (options.controlword.index, options.target.index) == (0x6040, 0x6042)
    assert options.target.signed and options.target.bits == 16
    sim = load_od(options.eds_path, NODE)
    tpdo1 = sim[0x1800]
    assert isinstance(tpdo1, ODRecord)
    assert tpdo1[1].default == 0x185


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("minimal.eds", "0x6040: the EDS has no object 0x6040 (controlword)"),
        ("latin1.eds", "0x6040: the EDS has no object 0x6040 (controlword)"),
    ],
)
def test_a_file_without_the_drive_objects_is_refused_by_name(name: str, problem: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        parse_config(drive_table(name, max_rpm=1500), "site.toml")
    [error] = err.value.errors
    assert error.reason == f"{CORPUS / name}: {problem}"
