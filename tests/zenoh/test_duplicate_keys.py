"""Issue 32 item 10: a JSON payload that names a key twice is refused on Zenoh."""

from __future__ import annotations

import pytest

from gateway import jsontext
from gateway.zenoh.requests import decode_json


@pytest.mark.parametrize(
    "payload",
    [b'{"run": false, "run": true}', b'{"speed_rpm": 1, "run": true, "speed_rpm": 1}'],
)
def test_a_duplicate_key_is_refused_with_its_name(payload: bytes) -> None:
    with pytest.raises(ValueError, match="is given twice in one JSON object"):
        decode_json(payload)


def test_nested_duplicates_are_refused_and_plain_objects_pass() -> None:
    with pytest.raises(jsontext.DuplicateKey):
        jsontext.loads('{"a": {"b": 1, "b": 2}}')
    assert jsontext.loads(b'{"run": true, "speed_rpm": 900}') == {"run": True, "speed_rpm": 900}
