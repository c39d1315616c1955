"""docs/architecture.md, "Links, driver loop and simulators", names the code as it is."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SECTION = "## Links, driver loop and simulators"


def section() -> str:
    text = (ROOT / "docs" / "architecture.md").read_text()
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    return text[start : end if end != -1 else len(text)]


def test_the_table_lists_every_module_of_the_shared_link_layer() -> None:
    listed = set(re.findall(r"^\| `(\w+\.py)` \|", section(), re.MULTILINE))
    modules = {p.name for p in (ROOT / "adapters" / "link").glob("*.py")} - {"__init__.py"}
    assert listed == modules


def test_the_files_and_tests_it_names_exist() -> None:
    text = section()
    for path in re.findall(r"`((?:adapters|gateway|tests)/[\w/]+\.py)`", text):
        assert (ROOT / path).is_file(), path
    layering = (ROOT / "tests" / "test_layering.py").read_text()
    for name in re.findall(r"`(test_\w+)`", text):
        assert f"def {name}(" in layering, name
