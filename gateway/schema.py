"""Typed reading of one TOML table, with errors that name the file, key path and reason.

Every adapter validates its own table with :class:`Table`; the core uses it for
its own sections. A table remembers which keys were read, and :meth:`Table.finish`
turns every key nobody read into an error (with the nearest known key as a hint):
unknown keys are never ignored.

Every error of a file is reported in one pass (``collect=True``, as the config
loader reads a document): a key that has a default and a bad value is recorded in
:attr:`Table.errors` (one list shared by a document's tables) and the reader goes
on with the default; a required key that is missing or bad raises, which ends that
table (a section, a bus, a drive), not the document. A table made without
``collect`` raises at the first error (an adapter's own unit tests).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Mapping
from enum import Enum
from typing import Any, TypeVar

from gateway.errors import ConfigError, ConfigErrors

E = TypeVar("E", bound=Enum)


class _Missing:
    def __repr__(self) -> str:
        return "<required>"


REQUIRED: Any = _Missing()


def _type_name(value: Any) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "an array",
        dict: "a table",
    }.get(type(value), type(value).__name__)


class Table:
    """One TOML table being read; ``path`` is its dotted key path in the file."""

    def __init__(
        self,
        data: Mapping[str, Any],
        file: str,
        path: str = "",
        errors: list[ConfigError] | None = None,
        *,
        collect: bool = False,
    ) -> None:
        self.data = data
        self.file = file
        self.path = path
        self.collect = collect
        self.errors: list[ConfigError] = [] if errors is None else errors
        """Errors recorded while reading on (shared with the tables read from this one)."""
        self._read: set[str] = set()

    def child(self, data: Mapping[str, Any], path: str) -> Table:
        """A table inside this one (its errors go to the same list)."""
        return Table(data, self.file, path, self.errors, collect=self.collect)

    def _soft(self, read: Callable[..., Any], key: str, default: Any, **kw: Any) -> Any:
        """``read(key, default, **kw)``; a bad value of a key that has a default is
        recorded and the default used, so the rest of the file is still checked."""
        try:
            return read(key, default, **kw)
        except ConfigError as exc:
            if default is REQUIRED or not self.collect:
                raise
            self.errors.append(exc)
            return default

    def key(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str, reason: str) -> ConfigError:
        return ConfigError(self.file, self.key(key), reason)

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        self._read.add(key)
        if key in self.data:
            return self.data[key]
        if default is REQUIRED:
            raise self.error(key, "is required")
        return default

    def raw(self, key: str, default: Any = REQUIRED) -> Any:
        return self._get(key, default)

    def _string(
        self, key: str, default: Any = REQUIRED, *, choices: Iterable[str] | None = None
    ) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if not isinstance(value, str):
            raise self.error(key, f"must be a string, not {_type_name(value)}")
        if choices is not None:
            allowed = list(choices)
            if value not in allowed:
                raise self.error(key, f"{value!r} is not one of {', '.join(map(repr, allowed))}")
        return value

    def _boolean(self, key: str, default: Any = REQUIRED) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, not {_type_name(value)}")
        return value

    def _integer(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
        allowed: Iterable[int] | None = None,
        what: str = "",
    ) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"must be an integer, not {_type_name(value)}")
        if allowed is not None:
            allowed_list = list(allowed)
            if value not in allowed_list:
                shown = ", ".join(str(a) for a in allowed_list)
                raise self.error(key, f"{value} is not {what or 'an allowed value'} ({shown})")
        self._check_range(key, value, minimum, maximum)
        return value

    def _number(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: float | None = None,
        maximum: float | None = None,
    ) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"must be a number, not {_type_name(value)}")
        if not math.isfinite(value):
            raise self.error(key, "must be a finite number")
        self._check_range(key, value, minimum, maximum)
        return float(value)

    def _check_range(
        self, key: str, value: float, minimum: float | None, maximum: float | None
    ) -> None:
        if minimum is not None and value < minimum:
            raise self.error(key, f"{value} is below the minimum {minimum}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"{value} is above the maximum {maximum}")

    def enum(self, key: str, enum: type[E], default: Any = REQUIRED) -> Any:
        choices = [str(m.value) for m in enum]
        value = self.string(key, default, choices=choices)
        if isinstance(value, str):
            return enum(value)
        return value

    def _int_list(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
    ) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if not isinstance(value, list):
            raise self.error(key, f"must be an array of integers, not {_type_name(value)}")
        for i, item in enumerate(value):
            if isinstance(item, bool) or not isinstance(item, int):
                raise self.error(f"{key}[{i}]", f"must be an integer, not {_type_name(item)}")
            self._check_range(f"{key}[{i}]", item, minimum, maximum)
        return tuple(value)

    def _str_list(self, key: str, default: Any = REQUIRED) -> Any:
        value = self._get(key, default)
        if value is default and key not in self.data:
            return value
        if not isinstance(value, list):
            raise self.error(key, f"must be an array of strings, not {_type_name(value)}")
        for i, item in enumerate(value):
            if not isinstance(item, str):
                raise self.error(f"{key}[{i}]", f"must be a string, not {_type_name(item)}")
        return tuple(value)

    # the getters: a bad value of a key with a default is recorded (see _soft)

    def string(
        self, key: str, default: Any = REQUIRED, *, choices: Iterable[str] | None = None
    ) -> Any:
        return self._soft(self._string, key, default, choices=choices)

    def boolean(self, key: str, default: Any = REQUIRED) -> Any:
        return self._soft(self._boolean, key, default)

    def integer(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
        allowed: Iterable[int] | None = None,
        what: str = "",
    ) -> Any:
        return self._soft(
            self._integer,
            key,
            default,
            minimum=minimum,
            maximum=maximum,
            allowed=allowed,
            what=what,
        )

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: float | None = None,
        maximum: float | None = None,
    ) -> Any:
        return self._soft(self._number, key, default, minimum=minimum, maximum=maximum)

    def int_list(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
    ) -> Any:
        return self._soft(self._int_list, key, default, minimum=minimum, maximum=maximum)

    def str_list(self, key: str, default: Any = REQUIRED) -> Any:
        return self._soft(self._str_list, key, default)

    def table(self, key: str, required: bool = False) -> Table:
        value = self._get(key, REQUIRED if required else {})
        if not isinstance(value, Mapping):
            raise self.error(key, f"must be a table, not {_type_name(value)}")
        return self.child(value, self.key(key))

    def table_list(self, key: str) -> list[Table]:
        value = self._get(key, [])
        if not isinstance(value, list):
            raise self.error(key, f"must be an array of tables ([[{self.key(key)}]])")
        out = []
        for i, item in enumerate(value):
            if not isinstance(item, Mapping):
                raise self.error(f"{key}[{i}]", f"must be a table, not {_type_name(item)}")
            out.append(self.child(item, f"{self.key(key)}[{i}]"))
        return out

    def tables(self, key: str) -> dict[str, Table]:
        """A table of named sub-tables (``[buses.<name>]``)."""
        outer = self.table(key)
        out: dict[str, Table] = {}
        for name, value in outer.data.items():
            outer._read.add(name)
            if not isinstance(value, Mapping):
                raise outer.error(name, f"must be a table, not {_type_name(value)}")
            out[name] = self.child(value, outer.key(name))
        return out

    def unread(self) -> list[str]:
        return sorted(k for k in self.data if k not in self._read)

    def unknown_key(self, key: str) -> ConfigError:
        """An unknown key, with the nearest key this table knows as a hint."""
        known = sorted(self._read)
        close = difflib.get_close_matches(str(key), known, n=1)
        return self.error(
            key, f"unknown key (did you mean {close[0]!r}?)" if close else "unknown key"
        )

    def finish(self) -> None:
        """Raise for the keys that nobody read: all of them (ConfigErrors) when
        collecting, else the first (ConfigError)."""
        unknown = [self.unknown_key(k) for k in self.unread()]
        if unknown and self.collect:
            raise ConfigErrors(unknown)
        if unknown:
            raise unknown[0]
