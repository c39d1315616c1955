"""The one "module:name" loader: the project's tables name code as strings, imported late.

The core never imports an adapter (docs/architecture.md, layers): its tables (adapters, front
ends, command-line commands, the device registry) name the code as ``"module:name"`` and
:func:`load` imports it when it is first needed.
"""

from __future__ import annotations

import importlib
from typing import Any

from gateway.errors import GatewayError


class NotLoadable(GatewayError, LookupError):
    """A ``"module:name"`` target whose module has no such name."""


def split(target: str) -> tuple[str, str]:
    """``"module:name"`` -> (module, name)."""
    module_name, _, name = target.partition(":")
    return module_name, name


def load(target: str) -> Any:
    """The object ``target`` names; the module's import errors propagate as they are,
    a missing name is :class:`NotLoadable` ("<module> has no <name>")."""
    module_name, name = split(target)
    module = importlib.import_module(module_name)
    try:
        return getattr(module, name)
    except AttributeError:
        raise NotLoadable(f"{module_name} has no {name}") from None


def load_optional(target: str) -> Any | None:
    """:func:`load`, or None when the target's own module (or its package) is not part of
    this build; any other import error propagates."""
    module_name, _ = split(target)
    try:
        return load(target)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            return None
        raise
