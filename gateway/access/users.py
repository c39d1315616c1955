"""The ``[[users]]`` tables: who may log in to the web page or call its API, and as what.

Each user has a ``name``, a ``role`` (viewer, operator, engineer, admin) and at least one
secret, both as hashes only: ``password`` (a scrypt line from ``drive-gateway users hash``)
and ``token_sha256`` (the SHA-256 of an API token from ``drive-gateway users token``).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

from gateway.access.passwords import BadHash, ScryptHash, is_token_digest, parse_hash
from gateway.access.roles import ROLE_NAMES, Identity, Role
from gateway.errors import ConfigError, ConfigErrors
from gateway.schema import Table

MAX_USERS = 256
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._@-]{0,63}")


@dataclass(frozen=True, slots=True)
class User:
    name: str
    role: Role
    password: ScryptHash | None = None
    token_sha256: str | None = None

    @property
    def identity(self) -> Identity:
        return Identity(self.name, self.role)


def read_role(t: Table, key: str) -> Role:
    text: str = t.string(key)
    role = Role.named(text)
    if role is None:
        raise t.error(key, f"{text!r} is not a role ({', '.join(ROLE_NAMES)})")
    return role


def _user(t: Table) -> User:
    name: str = t.string("name")
    if not _NAME.fullmatch(name):
        raise t.error("name", f"{name!r} is not a user name (letters, digits, . _ @ -)")
    role = read_role(t, "role")
    password: ScryptHash | None = None
    line: str | None = t.string("password", None)
    if line is not None:
        try:
            password = parse_hash(line)
        except BadHash as exc:
            t.errors.append(t.error("password", f"{exc} (make one: drive-gateway users hash)"))
    token: str | None = t.string("token_sha256", None)
    if token is not None and not is_token_digest(token):
        t.errors.append(
            t.error("token_sha256", "must be the 64 lower-case hex digits of the token's SHA-256")
        )
        token = None
    if line is None and token is None:
        raise t.error("name", f"user {name!r} has neither a password nor a token_sha256")
    return User(name, role, password, token)


def read_users(root: Table) -> tuple[User, ...]:
    """Every ``[[users]]`` table (errors recorded in ``root.errors``)."""
    try:
        tables = root.table_list("users")
    except ConfigError as exc:
        root.errors.append(exc)
        return ()
    users: list[User] = []
    for t in tables[: MAX_USERS + 1]:
        try:
            users.append(_user(t))
            t.finish()
        except ConfigErrors as exc:
            root.errors.extend(exc.errors)
        except ConfigError as exc:
            root.errors.append(exc)
    if len(tables) > MAX_USERS:
        root.errors.append(root.error("users", f"at most {MAX_USERS} users"))
    seen: set[str] = set()
    for user in users:
        if user.name in seen:
            root.errors.append(root.error("users", f"user {user.name!r} is named twice"))
        seen.add(user.name)
    tokens = [u.token_sha256 for u in users if u.token_sha256]
    if len(tokens) != len(set(tokens)):
        root.errors.append(root.error("users", "two users have the same token_sha256"))
    return tuple(users)


def fingerprints(users: tuple[User, ...]) -> dict[str, dict[str, str]]:
    """What the audit trail keeps of the users between runs: each name's role and a digest
    of its hashes (a changed password or token shows; no hash is kept)."""
    out: dict[str, dict[str, str]] = {}
    for user in users:
        secret = (user.password.line() if user.password else "") + "|" + (user.token_sha256 or "")
        digest = hashlib.sha256(secret.encode("utf-8")).hexdigest()[:16]
        out[user.name] = {"role": user.role.label, "secrets": digest}
    return out


def user_changes(before: dict[str, dict[str, str]], after: dict[str, dict[str, str]]) -> list[str]:
    """The user changes from one run's fingerprints to the next, one line each."""
    lines: list[str] = []
    for name in sorted(after.keys() - before.keys()):
        lines.append(f"user {name} added with the {after[name]['role']} role")
    for name in sorted(before.keys() - after.keys()):
        lines.append(f"user {name} removed")
    for name in sorted(before.keys() & after.keys()):
        old, new = before[name], after[name]
        if old.get("role") != new["role"]:
            lines.append(f"user {name}: role {old.get('role')} -> {new['role']}")
        if old.get("secrets") != new["secrets"]:
            lines.append(f"user {name}: password or token changed")
    return lines
