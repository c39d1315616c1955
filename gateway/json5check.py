"""A bounded JSON5 syntax check, run on a Zenoh config file before Zenoh sees it.

Zenoh's own parser recurses once per nesting level: a file nested some ten thousand
deep overflows its native stack and the process dies (SIGSEGV, no log, no
on_shutdown). This checker never recurses (an explicit stack), refuses nesting
deeper than ``max_depth`` and builds no values: it only says whether the text is
one JSON5 value (https://spec.json5.org/, 1.0.0) and, if not, where and why.

A library would not do: the pure-Python ``json5`` package recurses per level (a
RecursionError at about a thousand) and builds the whole document, and a checker
is needed anyway that stops at a depth bound before anything recursive runs.
"""

from __future__ import annotations

import re
import unicodedata

from gateway.errors import GatewayError

MAX_DEPTH = 64
"""Objects and arrays inside each other; Zenoh's own configs nest about 8 deep."""

_NUMBER = re.compile(
    r"[+-]?(?:Infinity|NaN|0[xX][0-9a-fA-F]+|"
    r"(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)"
)
_PLAIN = {'"': re.compile(r'[^"\\\n\r]*'), "'": re.compile(r"[^'\\\n\r]*")}
_HEX = "0123456789abcdefABCDEF"
_WHITESPACE = frozenset("\t\n\v\f\r \u00a0\u2028\u2029\ufeff")
_CLOSE = {"{": "}", "[": "]"}


class Json5Error(GatewayError, ValueError):
    """Text that is not one JSON5 value; ``line`` and ``column`` count from 1."""

    def __init__(self, reason: str, line: int, column: int) -> None:
        self.reason = reason
        self.line = line
        self.column = column
        super().__init__(f"{reason} (line {line}, column {column})")


def _is_space(ch: str) -> bool:
    return ch in _WHITESPACE or unicodedata.category(ch) == "Zs"


def _ident_char(ch: str, first: bool) -> bool:
    if ch in "$_" or ch.isalpha():
        return True
    if first:
        return False
    return ch.isdigit() or unicodedata.category(ch) in ("Mn", "Mc", "Nd", "Pc")


class _Scanner:
    def __init__(self, text: str) -> None:
        self.text = text
        self.pos = 0

    def error(self, reason: str, pos: int | None = None) -> Json5Error:
        at = self.pos if pos is None else pos
        line = self.text.count("\n", 0, at) + 1
        column = at - (self.text.rfind("\n", 0, at) + 1) + 1
        return Json5Error(reason, line, column)

    def peek(self) -> str:
        return self.text[self.pos] if self.pos < len(self.text) else ""

    def skip(self) -> None:
        """Whitespace and comments."""
        text = self.text
        while self.pos < len(text):
            ch = text[self.pos]
            if _is_space(ch):
                self.pos += 1
            elif text.startswith("//", self.pos):
                end = text.find("\n", self.pos)
                self.pos = len(text) if end < 0 else end + 1
            elif text.startswith("/*", self.pos):
                end = text.find("*/", self.pos + 2)
                if end < 0:
                    raise self.error("a /* comment is not closed")
                self.pos = end + 2
            else:
                return

    def string(self) -> None:
        quote = self.text[self.pos]
        start = self.pos
        self.pos += 1
        plain = _PLAIN[quote]
        while True:
            match = plain.match(self.text, self.pos)
            self.pos = match.end() if match else self.pos
            ch = self.peek()
            if ch == quote:
                self.pos += 1
                return
            if ch == "\\":
                self.escape()
            elif ch in ("\n", "\r"):
                raise self.error("a line break inside a string (escape it)")
            else:
                raise self.error("a string is not closed", start)

    def escape(self) -> None:
        self.pos += 1
        ch = self.peek()
        if ch == "":
            return  # reported as a string that is not closed
        if ch == "x":
            self.hex_digits(2)
        elif ch == "u":
            self.hex_digits(4)
        elif ch in "123456789":
            raise self.error(f"\\{ch} is not a JSON5 escape")
        elif ch == "0" and self.text[self.pos + 1 : self.pos + 2].isdigit():
            raise self.error("\\0 followed by a digit is not a JSON5 escape")
        elif ch == "\r" and self.text.startswith("\r\n", self.pos):
            self.pos += 2
        else:
            self.pos += 1  # \n \t ..., an escaped line break, or any other character

    def hex_digits(self, count: int) -> None:
        digits = self.text[self.pos + 1 : self.pos + 1 + count]
        if len(digits) != count or any(c not in _HEX for c in digits):
            raise self.error(f"\\{self.text[self.pos]} needs {count} hex digits")
        self.pos += 1 + count

    def identifier(self) -> str:
        start = self.pos
        text = self.text
        while self.pos < len(text):
            ch = text[self.pos]
            if ch == "\\" and text.startswith("\\u", self.pos):
                self.pos += 1
                self.hex_digits(4)
            elif _ident_char(ch, self.pos == start):
                self.pos += 1
            else:
                break
        return text[start : self.pos]

    def key(self) -> None:
        ch = self.peek()
        if ch in ('"', "'"):
            self.string()
        elif not self.identifier():
            raise self.error(self._expected("a key or '}'"))
        self.skip()
        if self.peek() != ":":
            raise self.error(self._expected("':' after the key"))
        self.pos += 1

    def scalar(self) -> None:
        ch = self.peek()
        if ch in ('"', "'"):
            self.string()
            return
        start = self.pos
        match = _NUMBER.match(self.text, self.pos)
        if match:
            self.pos = match.end()
        elif self.identifier() not in ("true", "false", "null"):
            self.pos = start
            raise self.error(self._expected("a value"))
        nxt = self.peek()
        if nxt and (_ident_char(nxt, False) or nxt == "."):
            raise self.error(f"{self.text[start : self.pos + 1]!r}... is not a value", start)

    def _expected(self, what: str) -> str:
        ch = self.peek()
        return f"expected {what}, found {'the end of the file' if not ch else repr(ch)}"


def check_json5(text: str, *, max_depth: int = MAX_DEPTH, top: str = "") -> None:
    """Raise :class:`Json5Error` unless ``text`` is one JSON5 value nested at most
    ``max_depth`` deep; ``top`` ("{" or "[") also requires that kind of value."""
    s = _Scanner(text)
    stack: list[str] = []
    s.skip()
    if top and s.peek() != top:
        raise s.error(s._expected("'{'" if top == "{" else "'['"))
    state = "value"
    while True:
        s.skip()
        ch = s.peek()
        if state in ("key", "item") and ch == _CLOSE[stack[-1]]:  # empty or trailing comma
            s.pos += 1
            stack.pop()
            state = "after"
        elif state == "key":
            s.key()
            state = "value"
        elif state in ("value", "item"):
            if ch in _CLOSE:
                stack.append(ch)
                if len(stack) > max_depth:
                    raise s.error(f"nested deeper than {max_depth} levels")
                s.pos += 1
                state = "key" if ch == "{" else "item"
            else:
                s.scalar()
                state = "after"
        elif not stack:  # after the one top-level value: only the end may follow
            if ch:
                raise s.error(s._expected("the end of the file"))
            return
        elif ch == ",":
            s.pos += 1
            state = "key" if stack[-1] == "{" else "item"
        elif ch == _CLOSE[stack[-1]]:
            s.pos += 1
            stack.pop()
        else:
            raise s.error(s._expected(f"',' or {_CLOSE[stack[-1]]!r}"))
