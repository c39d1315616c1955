"""CANopen objects as parameters on the command line and in the core's config."""

from __future__ import annotations

import argparse

import pytest

from gateway.cli.tools import param_ref
from gateway.config import parse_param_ref


@pytest.mark.parametrize(
    ("text", "ref"),
    [
        ("100", (100, None)),
        ("P0100", (100, None)),
        ("p134", (134, None)),
        ("0x6083", (0x6083, None)),
        ("0x2000:4", (0x2000, 4)),
        ("0X605a:0x0", (0x605A, 0)),
    ],
)
def test_parameter_references(text: str, ref: tuple[int, int | None]) -> None:
    assert parse_param_ref(text) == ref
    assert param_ref(text) == ref


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("0xZZ", "is not a parameter"),
        ("0x10000", "beyond 0..65535"),
        ("0x2000:256", "subindex beyond 0..255"),
        ("P", "is not a parameter"),
    ],
)
def test_bad_references(text: str, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        parse_param_ref(text)
    with pytest.raises(argparse.ArgumentTypeError, match=why):
        param_ref(text)
