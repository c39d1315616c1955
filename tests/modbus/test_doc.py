"""docs/modbus-map.md is generated from the tables in code; they must agree."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

from gateway.modbus.command import COMMAND_BITS
from gateway.modbus.doc import render
from gateway.modbus.health import GATEWAY_INPUTS
from gateway.modbus.map import (
    DEVICE_CODES,
    DRIVE_HOLDINGS,
    DRIVE_INPUTS,
    MIRROR_OFFSET,
    STATUS_BITS,
)
from gateway.modbus.regs import Field
from gateway.model import Device

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "modbus-map.md"


def test_the_document_matches_the_code() -> None:
    assert DOC.read_text(encoding="utf-8") == render(), (
        "docs/modbus-map.md is stale: run `python -m gateway.modbus.doc > docs/modbus-map.md`"
    )


def test_the_generator_runs_as_a_module() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "gateway.modbus.doc"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    )
    assert out.stdout == render()


def _contiguous(fields: tuple[Field[Any], ...]) -> None:
    address = 0
    for f in fields:
        assert f.address == address, f.name
        address += f.words


def test_tables_are_contiguous_and_consistent() -> None:
    _contiguous(DRIVE_INPUTS)
    _contiguous(GATEWAY_INPUTS)
    assert [h.address for h in DRIVE_HOLDINGS] == list(range(len(DRIVE_HOLDINGS)))
    assert max(h.address for h in DRIVE_HOLDINGS) < MIRROR_OFFSET
    # the fixed core of the map (issue 3)
    assert [f.name for f in DRIVE_INPUTS[:4]] == [
        "status_flags",
        "status_code",
        "speed_rpm",
        "speed_pct",
    ]
    assert [h.name for h in DRIVE_HOLDINGS[:3]] == ["command", "speed_ref_rpm", "speed_ref_pct"]
    assert [b.name for b in STATUS_BITS] == [
        "online", "ready", "running", "reverse", "at_reference", "faulted", "alarm", "remote",
        "local_control", "no_failsafe", "doubtful",
    ]  # fmt: skip
    assert [b.name for b in COMMAND_BITS] == [
        "run", "reverse", "fault_reset", "quick_stop", "coast_stop", "jog",
    ]  # fmt: skip
    assert set(DEVICE_CODES) == set(Device)
    assert len(set(DEVICE_CODES.values())) == len(DEVICE_CODES)
