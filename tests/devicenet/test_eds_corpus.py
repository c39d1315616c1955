"""The DeviceNet EDS corpus (tests/data/eds/corpus/devicenet, written from the EDS format in
the styles vendors' tools use): each file loaded by the drive's loader (``load_eds``) and
its identity, I/O images and integer parameters compared with what was worked out by hand
from the file. Before the loader read numbers with leading zeros, UTF-8 and ISO-8859-1
text, REAL parameters and parameters without a link path, 4 of the 5 files were refused."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from adapters.devicenet.codec.eds import ConnectionType, DeviceInfo, Eds, parse_eds
from adapters.devicenet.errors import EdsError
from adapters.devicenet.options import load_eds

CORPUS = Path(__file__).parents[1] / "data" / "eds" / "corpus" / "devicenet"
POLL, COS, CYCLIC = ConnectionType.POLL, ConnectionType.COS, ConnectionType.CYCLIC
ASSEMBLY = "20 04 24 {:02X} 30 03"

# file: (description, identity, default connection, {type: (in, out)}, {In/Out n: (size,
# path)}, {ParamN: (path, type, size, name, units, min, max, default, decimals)})
GOLDEN: dict[str, tuple[object, ...]] = {
    "minimal.eds": (
        "Minimal EDS",
        DeviceInfo(1234, 7, 21, 1, 2, "DIO-8", "Corpus Devices", "General Purpose Discrete I/O"),
        POLL,
        {},
        {},
        {},
    ),
    "tool-style.eds": (
        "AC Drive, 0.75 kW",
        DeviceInfo(
            0x123, 2, 10, 3, 11, "XD-200 AC Drive", "Example Drives", "AC Drive", "XD-200-0P7"
        ),
        POLL,
        {POLL: (1, 1)},
        {"In1": (4, ASSEMBLY.format(70)), "Out1": (4, ASSEMBLY.format(20))},
        {
            1: ("20 2A 24 01 30 08", 0xC7, 2, "Speed reference", "rpm", 0, 1800, 0, 0),
            2: ("20 28 24 01 30 06", 0xC7, 2, "Rated current", "A", 0, 9999, 41, 1),
            3: ("20 29 24 01 30 11", 0xC6, 1, "Comm loss action", "", 0, 3, 2, 0),
            4: ("", 0xC7, 2, "Start delay", "ms", 0, 5000, 100, 0),  # no link path
        },
    ),
    "reordered.eds": (
        "Reordered",
        DeviceInfo(0x355, 2, 8, 4, 6, "Small Drive"),
        POLL,
        {POLL: (1, 1)},
        {"In1": (4, ASSEMBLY.format(71)), "Out1": (4, ASSEMBLY.format(21))},
        {  # Param2 is a REAL: left out
            1: ("20 0F 24 01 30 01", 0xC3, 2, "Torque limit", "%", -150, 150, 100, 0),
            3: ("20 0F 24 03 30 01", 0xC7, 2, "Frequency", "Hz", 0, 6000, 600, 1),
        },
    ),
    "latin1.eds": (
        "Frequenzumrichter für Pumpen",
        DeviceInfo(0x4D2, 2, 300, 2, 0, "FU-300", "Müller Antriebe"),
        POLL,
        {},
        {},
        {7: ("20 64 24 01 30 07", 0xC3, 2, "Kühlkörper", "°C", -40, 150, None, 0)},
    ),
    "utf8-bom.eds": (
        "Ventilateur µ-drive",
        DeviceInfo(77, 2, 0x102, 1, 5, "µDrive 8"),
        COS,
        {COS: (1, 1), CYCLIC: (1, 2)},
        {
            "In1": (8, ASSEMBLY.format(100)),
            "Out1": (4, ASSEMBLY.format(20)),
            "Out2": (2, ASSEMBLY.format(21)),
        },
        {},
    ),
}


def test_the_corpus_is_the_golden_table() -> None:
    assert sorted(p.name for p in CORPUS.glob("*.eds")) == sorted(GOLDEN)


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_each_file_loads_as_worked_out(name: str) -> None:
    description, device, default, connections, images, params = GOLDEN[name]
    eds = load_eds(CORPUS / name)
    assert eds.info.description == description
    assert eds.device == device
    assert eds.io.default == default
    assert {t: (c.default_input, c.default_output) for t, c in eds.io.connections.items()} == (
        connections
    )
    assert _images(eds) == images
    assert {n: _param(eds, n) for n in eds.params} == params


def _images(eds: Eds) -> dict[str, tuple[int, str]]:
    out = {f"In{n}": (e.size, e.path.hex(" ").upper()) for n, e in eds.io.inputs.items()}
    out.update({f"Out{n}": (e.size, e.path.hex(" ").upper()) for n, e in eds.io.outputs.items()})
    return out


def _param(eds: Eds, number: int) -> tuple[object, ...]:
    p = eds.params[number]
    return (
        p.path.hex(" ").upper(),
        p.data_type,
        p.data_size,
        p.name,
        p.units,
        p.minimum,
        p.maximum,
        p.default,
        p.decimals,
    )


def test_the_sizes_a_connection_names() -> None:
    eds = load_eds(CORPUS / "utf8-bom.eds")
    assert eds.io.sizes(COS) == (8, 4)
    assert eds.io.sizes(CYCLIC) == (8, 2)
    assert eds.io.sizes(POLL) is None


def test_scaling_of_a_corpus_parameter() -> None:
    current = load_eds(CORPUS / "tool-style.eds").params[2]
    assert current.scale(41) == pytest.approx(4.1)


HEAD = '[File]\nDescText = "x";\n[Device]\nVendCode = 1; ProdType = 2; ProdCode = 3;\n'


@pytest.mark.parametrize(
    ("device", "message"),
    [
        ('MajRev = 08; MinRev = 0x; ProdName = "x";', "field 1 (MinRev) '0x' is not a number"),
        ('MajRev = 1e3; MinRev = 0; ProdName = "x";', "field 1 (MajRev) '1e3' is not a number"),
        ('MajRev = 0o7; MinRev = 0; ProdName = "x";', "field 1 (MajRev) '0o7' is not a number"),
    ],
)
def test_numbers_are_decimal_or_0x_hex_only(device: str, message: str) -> None:
    with pytest.raises(EdsError, match=re.escape(message)):
        parse_eds(HEAD + device + "\n", "t.eds")


def test_a_real_parameter_is_still_checked() -> None:
    text = (
        HEAD
        + 'MajRev = 1; MinRev = 0; ProdName = "x";\n[Params]\n'
        + 'Param1 = 0, 6, "20 0F 24 01 30 01", 0, 0xCA, 2, "r", "", "", 0.0, 1.0, 0.5,'
        + " 1, 1, 1, 0, 0, 0, 0, 0, 0;\n"
    )
    with pytest.raises(EdsError, match="data type 0xCA is 4 bytes, not 2"):
        parse_eds(text, "t.eds")


def test_a_link_path_size_without_its_path_is_refused() -> None:
    text = (
        HEAD
        + 'MajRev = 1; MinRev = 0; ProdName = "x";\n[Params]\n'
        + 'Param1 = 0, 6, "", 0, 0xC7, 2, "r", "", "", 0, 1, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0;\n'
    )
    with pytest.raises(EdsError, match="the link path has 0 bytes, its size field says 6"):
        parse_eds(text, "t.eds")
