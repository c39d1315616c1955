"""The journal's native protocol: golden datagrams, and every record read back."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.access.journal import decode, encode, field_name


def test_a_simple_entry() -> None:
    assert encode({"MESSAGE": "hello", "PRIORITY": "5", "audit_type": "login"}) == (
        b"MESSAGE=hello\nPRIORITY=5\nAUDIT_TYPE=login\n"
    )


def test_a_value_with_a_newline_is_sent_with_its_length() -> None:
    assert encode({"MESSAGE": "a\nb"}) == b"MESSAGE\n" + struct.pack("<Q", 3) + b"a\nb\n"


def test_field_names() -> None:
    assert field_name("audit.event-id") == "AUDIT_EVENT_ID"
    assert field_name("_hidden") == "HIDDEN"  # journald's own fields cannot be forged
    assert len(field_name("x" * 100)) == 64
    with pytest.raises(ValueError):
        field_name("__")


@given(
    st.dictionaries(
        st.from_regex(r"[A-Z][A-Z0-9_]{0,20}", fullmatch=True),
        st.text(alphabet=st.characters(exclude_categories=["Cs"]), max_size=50),
        max_size=8,
    )
)
def test_every_entry_reads_back(fields: dict[str, str]) -> None:
    assert decode(encode(fields)) == fields
