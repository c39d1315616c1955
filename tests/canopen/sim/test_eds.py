"""config/eds/cia402-drive.eds: the canopen library reads it, and it says what CiA 301/402
say of each object (types, access, PDO mapping)."""

from __future__ import annotations

import canopen
import pytest
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from tests.canopen.sim.conftest import EDS

OD = canopen.import_od(str(EDS), 5)
U8, U16, U32, I8, I16, I32 = 0x5, 0x6, 0x7, 0x2, 0x3, 0x4


def var(index: int, sub: int = 0) -> ODVariable:
    obj = OD[index]
    if isinstance(obj, ODVariable):
        return obj
    member = obj[sub]
    assert isinstance(member, ODVariable)
    return member


@pytest.mark.parametrize(
    ("index", "sub", "data_type", "access", "mappable"),
    [
        (0x1000, 0, U32, "ro", False),
        (0x1001, 0, U8, "ro", True),
        (0x1017, 0, U16, "rw", False),
        (0x1018, 1, U32, "ro", False),
        (0x1016, 1, U32, "rw", False),
        (0x603F, 0, U16, "ro", True),
        (0x6040, 0, U16, "rw", True),
        (0x6041, 0, U16, "ro", True),
        (0x6007, 0, I16, "rw", False),
        (0x605A, 0, I16, "rw", False),
        (0x6060, 0, I8, "rw", True),
        (0x6061, 0, I8, "ro", True),
        (0x6042, 0, I16, "rw", True),
        (0x6044, 0, I16, "ro", True),
        (0x6046, 2, U32, "rw", False),
        (0x6048, 1, U32, "rw", False),
        (0x6049, 2, U16, "rw", False),
        (0x60FF, 0, I32, "rw", True),
        (0x606C, 0, I32, "ro", True),
        (0x6077, 0, I16, "ro", True),
        (0x6078, 0, I16, "ro", True),
        (0x6075, 0, U32, "rw", False),
        (0x2000, 1, U16, "ro", True),
    ],
)
def test_objects(index: int, sub: int, data_type: int, access: str, mappable: bool) -> None:
    v = var(index, sub)
    assert (v.data_type, v.access_type, v.pdo_mappable) == (data_type, access, mappable)


def test_communication_objects_and_default_mapping() -> None:
    assert var(0x1000).default == 0x00010192  # CiA 402, frequency converter
    assert var(0x1200, 1).default == 0x605 and var(0x1200, 2).default == 0x585
    assert [var(0x1400 + n, 1).default for n in range(2)] == [0x205, 0x305]
    assert [var(0x1800 + n, 1).default for n in range(2)] == [0x185, 0x285]
    assert [var(0x1600, s).default for s in range(3)] == [2, 0x60400010, 0x60420010]
    assert [var(0x1A00, s).default for s in range(3)] == [2, 0x60410010, 0x60440010]
    assert isinstance(OD[0x1018], ODRecord) and isinstance(OD[0x6046], ODArray)
    name: object = var(0x1008).default
    assert name == "CiA402 test drive"  # 17 bytes: a segmented upload


def test_limits_the_simulator_checks() -> None:
    assert (var(0x6007).min, var(0x6007).max) == (0, 3)
    assert (var(0x605A).min, var(0x605A).max) == (0, 8)
    assert (var(0x6046, 2).min, var(0x6046, 2).max) == (1, 6000)
    assert var(0x6075).min == 100
