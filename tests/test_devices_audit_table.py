"""docs/devices.md, "The manuals' audits: every open row decided" (issue 36): one row for
each row the two audits of the manuals left as a mismatch, missing or open (106), each
with a decision, the manual's section and a test that exists (or "—" for n/a)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).parents[1]
SECTION = "## The manuals' audits: every open row decided (issue 36)"
DIRS = {
    "w/": "tests/profibus/weg/",
    "dn/": "tests/devicenet/",
    "mcd/": "tests/mcd600/",
    "gateway/": "tests/gateway/",
    "profibus/": "tests/profibus/",
}


def _ids(prefix: str, numbers: str) -> list[str]:
    return [f"{prefix}{n}" for n in numbers.split()]


AUDITED = {
    *_ids("C11-", "04 10 11 12 14 15 17 18 26 32 34 36 37 39 43 44 45 46 48 51 54 56 58"),
    *_ids("C11-", "66 68 69 70 72"),
    *_ids("C7-", "04 10 12 14 15 17 18 23 24 25 27 29 30 31 32 33 36 39 40 42 45 46 48"),
    *_ids("C3-", "01 04 09 10 11 15 16 17 18 19 20 22 23 26 29 31 32 35 36 37 38 39 40"),
    *_ids("C", "6 8 13 16 20 24 30 37 41 43 44 48 49 54 56 57 58 66 67"),
    *_ids("M", "9 18 33 35 37 39 48 50 51 52 53 54 55"),
}


def rows() -> dict[str, list[str]]:
    text = (ROOT / "docs" / "devices.md").read_text()
    body = text[text.index(SECTION) :]
    body = body[: body.index("\n## ", 1)]
    out: dict[str, list[str]] = {}
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if re.fullmatch(r"(C\d+-\d+|C\d+|M\d+)", cells[0]):
            assert cells[0] not in out, f"{cells[0]} twice"
            out[cells[0]] = cells[1:]
    return out


def test_every_audited_row_is_decided_once() -> None:
    assert len(AUDITED) == 106  # WEG 74, CFW-08 and MCD 600 32
    assert set(rows()) == AUDITED


def test_each_row_has_a_decision_a_section_and_a_test_that_exists() -> None:
    last = ""
    for row, (decision, section, tests) in rows().items():
        assert re.match(r"(fixed|decision|n/a)\b", decision), row
        assert section, row
        if decision.startswith("n/a"):
            assert tests == "—", row
            continue
        cited = re.findall(r"`([^`]*::[^`]*)`", tests)
        assert cited, row
        for cell in cited:
            file, name = cell.split("::")
            if file:
                prefix = next(p for p in DIRS if file.startswith(p))
                last = DIRS[prefix] + file[len(prefix) :]
            source = (ROOT / last).read_text()
            assert re.search(rf"def {re.escape(name)}\(", source), f"{row}: {cell}"
