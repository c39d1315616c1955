"""docs/architecture.md, "DeviceNet scanner": the code it names exists, and the scanner's
parts stay small (issue 21: no class over about 40 methods)."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

from adapters.devicenet.contract import DnProfile, DrivePort

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
SCANNER = ROOT / "adapters" / "devicenet" / "scanner"
MAX_METHODS = 40


def section() -> str:
    text = DOC.read_text()
    start = text.index("## DeviceNet scanner")
    end = text.find("\n## ", start + 1)
    return text[start : end if end != -1 else len(text)]


def test_the_scanner_parts_named_in_the_doc_exist() -> None:
    rows = re.findall(r"^\| `(\w+)\.py` \| `(\w+)` \|", section(), re.MULTILINE)
    assert len(rows) >= 5
    for module, cls in rows:
        mod = importlib.import_module(f"adapters.devicenet.scanner.{module}")
        assert isinstance(getattr(mod, cls, None), type), f"{module}.py has no class {cls}"


def test_the_doc_names_every_part_of_the_profile_contract() -> None:
    contract = section().split("### The scanner's parts")[0]
    named = set(re.findall(r"`(\w+)[(`]", contract))
    for proto in (DnProfile, DrivePort):
        members = {n for n in vars(proto) if not n.startswith("_")}
        assert members - named == set(), proto.__name__


def test_no_scanner_class_has_more_than_about_40_methods() -> None:
    big = []
    for path in sorted(SCANNER.glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef):
                count = sum(
                    isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef) for f in node.body
                )
                if count > MAX_METHODS:
                    big.append(f"{path.name}: {node.name} has {count} methods")
    assert big == []
