"""docs/architecture.md names code: the parts that do are checked here."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from gateway import devices
from gateway.devices import Device, published, with_registry_table
from gateway.loader import load

DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"


def test_the_registry_table_is_the_registry() -> None:
    text = DOC.read_text()
    assert with_registry_table(text) == text, (
        "docs/architecture.md is stale: run `python -m gateway.devices docs/architecture.md`"
    )


def test_main_rewrites_the_table(tmp_path: Path) -> None:
    stale = tmp_path / "architecture.md"
    stale.write_text(f"x\n{devices.TABLE_START}\n| old |\n{devices.TABLE_END}\ny\n")
    assert devices.main([str(stale)]) == 0
    table = "\n".join(devices.registry_table())
    expected = f"x\n{devices.TABLE_START}\n{table}\n{devices.TABLE_END}\ny\n"
    assert stale.read_text() == expected


def test_models_and_codes_are_unique() -> None:
    assert len({d.value for d in Device}) == len(Device)
    assert len({d.spec.code for d in Device}) == len(Device)
    assert all(0 < d.spec.code < 256 for d in Device)
    assert Device.TEST not in published()


@pytest.mark.parametrize("device", list(Device), ids=lambda d: d.name)
def test_every_registered_class_loads(device: Device) -> None:
    spec = device.spec
    if spec.profile:
        profile = load(spec.profile)
        assert profile.device is device
    if spec.simulator:
        assert callable(load(spec.simulator).for_drive)
    assert spec.package.startswith("adapters.")
    assert load(f"{spec.package}:__name__") == spec.package


GLOSSARY = "## Same words on both buses"
IDEAS = (
    "engine",
    "engine events",
    "line figures",
    "link",
    "driver",
    "profile contract",
    "simulator",
    "CLI",
)


def glossary_rows() -> list[list[str]]:
    text = DOC.read_text()
    start = text.index(GLOSSARY)
    end = text.find("\n## ", start + len(GLOSSARY))
    section = text[start : end if end != -1 else len(text)]
    rows = [line.strip("|").split(" | ") for line in section.splitlines() if line.startswith("| ")]
    return [[cell.strip() for cell in row] for row in rows[1:]]  # past the header


def test_the_glossary_covers_the_ideas_of_both_buses() -> None:
    ideas = {row[0].split(":")[0] for row in glossary_rows()}
    assert set(IDEAS) - ideas == set()


def test_the_glossary_names_code_that_exists() -> None:
    root = DOC.parents[1]
    for row in glossary_rows():
        assert len(row) == 4, row  # idea, Profibus, DeviceNet, CANopen
        for cell in row[1:]:
            module = None
            for name in re.findall(r"`([^`]+)`", cell):
                if name.endswith(".py"):
                    assert (root / name).is_file(), name
                    module = importlib.import_module(name.removesuffix(".py").replace("/", "."))
                else:
                    assert module is not None and hasattr(module, name), f"{cell}: no {name}"
