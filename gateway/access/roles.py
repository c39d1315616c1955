"""The four roles and what each may do.

Roles are ordered: each may do what the roles below it may (viewer < operator < engineer <
admin). An action names the least role that may take it (:data:`LEAST_ROLE`): a table, not
a chain of checks, so a front end asks :func:`refusal` and gets the reason to answer with.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Role(enum.IntEnum):
    VIEWER = 1  # states, events, the page
    OPERATOR = 2  # drive commands
    ENGINEER = 3  # parameters, backups, restores, the audit trail
    ADMIN = 4  # reload, users

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def named(cls, text: str) -> Role | None:
        """The role called ``text`` (viewer, operator, engineer, admin), else None."""
        return cls.__members__.get(text.strip().upper())


ROLE_NAMES = tuple(r.label for r in Role)


class Action(enum.Enum):
    READ = "read"  # states, events, health, history, the page, the feed, /metrics
    COMMAND = "command"  # a drive command
    PARAM_READ = "param_read"
    PARAM_WRITE = "param_write"
    BACKUP = "backup"
    RESTORE = "restore"
    AUDIT_READ = "audit_read"
    RELOAD = "reload"
    USERS = "users"


LEAST_ROLE: dict[Action, Role] = {
    Action.READ: Role.VIEWER,
    Action.COMMAND: Role.OPERATOR,
    Action.PARAM_READ: Role.ENGINEER,
    Action.PARAM_WRITE: Role.ENGINEER,
    Action.BACKUP: Role.ENGINEER,
    Action.RESTORE: Role.ENGINEER,
    Action.AUDIT_READ: Role.ENGINEER,
    Action.RELOAD: Role.ADMIN,
    Action.USERS: Role.ADMIN,
}


@dataclass(frozen=True, slots=True)
class Identity:
    """Who asks, as a front end knows them: a name (a user, a certificate's common name,
    an address) and the role it is given."""

    name: str
    role: Role

    @property
    def label(self) -> str:
        return f"{self.name} ({self.role.label})"


ANONYMOUS = "anonymous"


def may(identity: Identity | None, action: Action) -> bool:
    return identity is not None and identity.role >= LEAST_ROLE[action]


def refusal(identity: Identity | None, action: Action) -> str | None:
    """Why ``identity`` may not take ``action`` (None: it may)."""
    least = LEAST_ROLE[action]
    if identity is None:
        return f"{action.value} needs a login with the {least.label} role or above"
    if identity.role >= least:
        return None
    return (
        f"{identity.name} has the {identity.role.label} role; "
        f"{action.value} needs {least.label} or above"
    )
