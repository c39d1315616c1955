"""``drive-gateway users hash`` and ``users token``: the lines a ``[[users]]`` table takes.

``hash`` reads a password (twice, without echo, from a terminal; one line from standard
input otherwise) and prints its scrypt line for ``password = "..."``. ``token`` makes a
new API token: the token once on standard error (give it to the user) and the line for
``token_sha256 = "..."`` on standard output. Neither ever writes a secret into a file.
"""

from __future__ import annotations

import argparse
import getpass
import sys
from typing import Any

from gateway.access.passwords import hash_password, new_token, token_digest

MIN_PASSWORD = 8


def _read_password() -> str | None:
    if sys.stdin.isatty():
        first = getpass.getpass("password: ")
        if first != getpass.getpass("again: "):
            print("error: the two passwords differ", file=sys.stderr)
            return None
        return first
    return sys.stdin.readline().rstrip("\r\n")


def _hash(args: argparse.Namespace) -> int:
    password = _read_password()
    if password is None:
        return 2
    if len(password) < MIN_PASSWORD:
        print(f"error: a password has at least {MIN_PASSWORD} characters", file=sys.stderr)
        return 2
    print(f'password = "{hash_password(password).line()}"')
    return 0


def _token(args: argparse.Namespace) -> int:
    token = new_token()
    print(f"the token (give it to the user; it is shown once): {token}", file=sys.stderr)
    print(f'token_sha256 = "{token_digest(token)}"')
    return 0


def add_users(sub: Any) -> None:
    p = sub.add_parser(
        "users",
        help="make the password hash or API token line of a [[users]] table",
        description="Print the line a [[users]] table of the config takes: the config holds "
        "hashes only, never a password or a token.",
    )
    tools = p.add_subparsers(dest="users_tool", metavar="TOOL", required=True)
    h = tools.add_parser(
        "hash",
        help="read a password and print its scrypt hash line (password = ...)",
        description="Read a password (twice from a terminal, else one line of standard input) "
        'and print the line password = "scrypt$..." for a [[users]] table.',
    )
    h.set_defaults(handler=_hash)
    t = tools.add_parser(
        "token",
        help="make an API token: the token on standard error, token_sha256 = ... on output",
    )
    t.set_defaults(handler=_token)
