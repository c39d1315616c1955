"""JSON from the outside, read strictly: an object that names a key twice is refused.

``{"run": false, "run": true}`` is a run to Python's ``json`` (the last key wins) and a
stop to a proxy, a log reader or a reviewer that reads the first: a command must mean
one thing to everyone who reads it (docs/safety.md, "Duplicate keys").
"""

from __future__ import annotations

import json
from typing import Any

from gateway.errors import GatewayError


class DuplicateKey(GatewayError, ValueError):
    """A JSON object names a key twice."""


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKey(f"key {key!r} is given twice in one JSON object")
        out[key] = value
    return out


def loads(text: str | bytes) -> Any:
    """``json.loads`` that refuses duplicate keys (:class:`DuplicateKey`, a ValueError);
    other errors are ``json.JSONDecodeError``, ``UnicodeDecodeError`` and ``RecursionError``
    as from ``json.loads``."""
    return json.loads(text, object_pairs_hook=_pairs)
