"""Roles are ordered, and each action names the least role that may take it."""

from __future__ import annotations

import pytest

from gateway.access.roles import LEAST_ROLE, Action, Identity, Role, may, refusal

ORDER = [Role.VIEWER, Role.OPERATOR, Role.ENGINEER, Role.ADMIN]
# what the issue names: viewer states/events/page, operator commands, engineer parameters,
# backups and restores, admin reload and users
EXPECTED = {
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


def test_every_action_has_its_least_role() -> None:
    assert LEAST_ROLE == EXPECTED


@pytest.mark.parametrize("action", list(Action))
@pytest.mark.parametrize("role", ORDER)
def test_a_role_may_what_the_roles_below_it_may(role: Role, action: Action) -> None:
    me = Identity("u", role)
    assert may(me, action) == (ORDER.index(role) >= ORDER.index(EXPECTED[action]))
    assert (refusal(me, action) is None) == may(me, action)


def test_a_refusal_names_who_what_and_the_role_needed() -> None:
    assert refusal(Identity("vic", Role.VIEWER), Action.COMMAND) == (
        "vic has the viewer role; command needs operator or above"
    )
    assert refusal(None, Action.READ) == "read needs a login with the viewer role or above"
    assert not may(None, Action.READ)


def test_roles_by_name() -> None:
    assert [Role.named(n) for n in ("viewer", "Operator", " engineer ", "admin")] == ORDER
    assert Role.named("root") is None and Role.named("") is None
