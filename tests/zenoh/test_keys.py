"""The key table, the key space helpers, and the generated document."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.adapter import EventKind
from gateway.model import COMMAND_FIELDS, EXTRA_JSON_FIELDS, JSON_FIELDS
from gateway.zenoh import keys
from gateway.zenoh.keys import KeyKind, KeySpace, ParsedKey, is_concrete

DOC = Path(__file__).resolve().parents[2] / "docs" / "zenoh-keys.md"


def test_the_document_is_generated_from_the_code() -> None:
    assert DOC.read_text(encoding="utf-8") == keys.render_markdown(), (
        "docs/zenoh-keys.md is out of date: run "
        "`.venv/bin/python -m gateway.zenoh.keys > docs/zenoh-keys.md`"
    )


def test_main_writes_the_document(capsys: pytest.CaptureFixture[str]) -> None:
    assert keys.main() == 0
    assert capsys.readouterr().out == keys.render_markdown()


def test_the_document_covers_every_field_and_kind_of_the_model() -> None:
    assert list(keys.COMMAND_FIELD_DOC) == list(COMMAND_FIELDS)
    assert list(keys.STATE_FIELD_DOC) == list(JSON_FIELDS + EXTRA_JSON_FIELDS)
    assert set(keys.EVENT_KIND_DOC) == set(EventKind)
    assert {spec.kind for spec in keys.KEYS} == set(KeyKind)
    doc = keys.render_markdown()
    for name in (*COMMAND_FIELDS, *JSON_FIELDS, *EXTRA_JSON_FIELDS):
        assert f"| `{name}` |" in doc


def test_keys_of_one_prefix() -> None:
    ks = KeySpace("site/a")
    assert ks.key(KeyKind.STATE, "d1") == "site/a/drives/d1/state"
    assert ks.key(KeyKind.COMMAND, "d1") == "site/a/drives/d1/command"
    assert ks.key(KeyKind.EVENTS, "d1") == "site/a/drives/d1/events"
    assert ks.key(KeyKind.DIAG, "d1") == "site/a/drives/d1/diag"
    assert ks.key(KeyKind.PARAM, "d1") == "site/a/drives/d1/params"
    assert ks.param("d1", 100) == "site/a/drives/d1/params/100"
    assert ks.param("d1", 100, 2) == "site/a/drives/d1/params/100/2"
    assert ks.key(KeyKind.DRIVE_TOKEN, "d1") == "site/a/drives/d1"
    assert ks.key(KeyKind.GATEWAY_TOKEN) == "site/a/gateway"
    assert ks.key(KeyKind.HEALTH) == "site/a/gateway/health"
    assert ks.all_drives(KeyKind.COMMAND) == "site/a/drives/*/command"
    assert ks.all_drives(KeyKind.PARAM) == "site/a/drives/*/params/**"


@pytest.mark.parametrize(
    ("key", "parsed"),
    [
        ("p/drives/d1/command", ParsedKey("d1", "command")),
        ("p/drives/d1/params/100/2", ParsedKey("d1", "params", ("100", "2"))),
        ("p/drives/*/command", ParsedKey("*", "command")),
        ("p/drives/d1", None),
        ("p/drives//command", None),
        ("q/drives/d1/command", None),
        ("p/gateway/health", None),
    ],
)
def test_parse(key: str, parsed: ParsedKey | None) -> None:
    assert KeySpace("p").parse(key) == parsed


def test_is_concrete() -> None:
    assert is_concrete("demo/drives/d1/command")
    assert not is_concrete("demo/drives/*/command")
    assert not is_concrete("demo/**")
    assert not is_concrete("demo/drives/d$*/command")
