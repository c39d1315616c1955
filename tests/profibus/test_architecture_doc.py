"""docs/architecture.md, section "Profibus master": the code it names exists, and the master's
parts stay small (issue 21: no class over about 40 methods)."""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "adapters" / "profibus" / "master"
MAX_METHODS = 40
MODULES = (
    "adapters.profibus.master.engine",
    "adapters.profibus.master.station",
    "adapters.profibus.master.scheduler",
    "adapters.profibus.master.acyclic",
    "adapters.profibus.master.line",
    "adapters.profibus.master.common",
    "adapters.profibus.weg.records",
    "adapters.mcd600.params",
)


def section() -> str:
    text = (ROOT / "docs" / "architecture.md").read_text()
    start = text.index("## Profibus master")
    end = text.find("\n## ", start + 1)
    return text[start : end if end >= 0 else len(text)]


def classes() -> dict[str, type]:
    found: dict[str, type] = {}
    for name in MODULES:
        module: ModuleType = importlib.import_module(name)
        for attr, value in vars(module).items():
            if inspect.isclass(value) and value.__module__ == name:
                found[attr] = value
    return found


def test_the_files_named_exist() -> None:
    for path in re.findall(r"`([\w/]+\.py)`", section()):
        where = PACKAGE.parent / path if path.startswith("master/") else ROOT / path
        assert where.is_file(), f"docs/architecture.md names {path}, which does not exist"


def test_each_part_is_in_the_module_the_table_names() -> None:
    rows = re.findall(r"\| `(master/\w+)\.py` \| `(\w+)`", section())
    assert len(rows) == 4
    for module, name in rows:
        imported = importlib.import_module(f"adapters.profibus.{module.replace('/', '.')}")
        assert inspect.isclass(getattr(imported, name, None)), f"no class {name} in {module}"


def test_the_classes_and_members_named_exist() -> None:
    known = classes()
    modules = [importlib.import_module(m) for m in MODULES]
    text = section()
    for name in sorted(set(re.findall(r"`([A-Z][A-Za-z]*[a-z][A-Za-z]*)`", text))):
        assert name in known or any(hasattr(m, name) for m in modules), f"no {name}"
    for owner, member in re.findall(r"`([A-Z]\w+)\.(\w+)(?:\([^`]*\))?`", text):
        cls = known[owner]
        fields = getattr(cls, "__dataclass_fields__", {})
        assert hasattr(cls, member) or member in fields, f"no {owner}.{member}"


def test_no_class_of_the_master_has_more_than_40_methods() -> None:
    for path in sorted(PACKAGE.glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                methods = [
                    n for n in node.body if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)
                ]
                assert len(methods) <= MAX_METHODS, f"{path.name}: {node.name} has {len(methods)}"
