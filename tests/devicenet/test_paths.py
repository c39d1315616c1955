"""Connection paths (Connection attributes 14 and 16, seed tables 12-14): the packed
logical path of an Assembly instance's Data (fact sheet 2.10 step 4), golden bytes."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.devicenet.codec.objects import LogicalPath, assembly_path, decode_path
from adapters.devicenet.errors import DataTypeDecodeError
from gateway.errors import FrameEncodeError


@pytest.mark.parametrize(
    ("instance", "golden"),
    [
        (20, "20 04 24 14 30 03"),
        (21, "20 04 24 15 30 03"),
        (100, "20 04 24 64 30 03"),
        (70, "20 04 24 46 30 03"),
        (71, "20 04 24 47 30 03"),
        (150, "20 04 24 96 30 03"),
        (0x1234, "20 04 25 34 12 30 03"),
    ],
)
def test_assembly_paths(instance: int, golden: str) -> None:
    assert assembly_path(instance).hex(" ") == golden
    path = decode_path(bytes.fromhex(golden))
    assert path == LogicalPath(4, instance, 3) and path.assembly == instance


def test_paths_that_name_no_assembly() -> None:
    assert decode_path(b"").assembly is None  # no path: nothing in force to show
    assert decode_path(bytes.fromhex("20 05 24 02")).assembly is None  # a Connection
    assert decode_path(bytes.fromhex("20 04 24 47 30 04")).assembly is None  # not Data
    assert decode_path(bytes.fromhex("20 04 24 47")).assembly == 71  # no attribute: Data


@pytest.mark.parametrize(
    "raw",
    ["91 04", "20", "20 04 24", "20 04 20 04", "20 04 25 47", "28 04"],
    ids=["symbolic", "short", "no-instance-value", "class-twice", "short-16", "other-logical"],
)
def test_bad_paths_are_typed_errors(raw: str) -> None:
    with pytest.raises(DataTypeDecodeError):
        decode_path(bytes.fromhex(raw))


def test_an_instance_beyond_16_bits_has_no_path() -> None:
    with pytest.raises(FrameEncodeError):
        assembly_path(0x10000)


@given(st.integers(0, 0xFFFF))
def test_round_trip(instance: int) -> None:
    assert decode_path(assembly_path(instance)).assembly == instance


@given(st.binary(max_size=12))
def test_any_bytes_decode_or_raise_typed(raw: bytes) -> None:
    with contextlib.suppress(DataTypeDecodeError):
        path = decode_path(raw)
        assert path.assembly is None or path.class_id == 4
