"""OPC UA sessions log in as the config's users (gateway/opcua/users.py): the password
checked against the user's scrypt hash, the role deciding who operates, guessing locked
out without a check, a good check remembered."""

from __future__ import annotations

from pathlib import Path

import pytest
from asyncua import Client, ua

from gateway.access.passwords import hash_password, verify_password
from gateway.access.roles import Role as AccessRole
from gateway.access.users import User
from gateway.opcua import users as users_mod
from gateway.opcua.sessions import Role, SessionUser
from gateway.opcua.users import LOCKOUT, MAX_FAILURES, ConfiguredUsers
from tests.opcua.harness import TIMEOUT, running_gateway
from tests.opcua.test_asyncua_e2e import call, text

FAST = 1 << 14  # scrypt N for tests: the least the config takes, the same check
ANA = User("ana", AccessRole.OPERATOR, hash_password("ana-secret", n=FAST))
VIC = User("vic", AccessRole.VIEWER, hash_password("vic-secret", n=FAST))


def session(name: str | None) -> SessionUser:
    return SessionUser(client="session 1", user_name=name, peer="127.0.0.1:5000")


def test_a_password_is_checked_against_the_users_hash_and_the_role_decides() -> None:
    users = ConfiguredUsers((ANA, VIC), Role.OBSERVE)
    assert users.get_user(None, "ana", "ana-secret") is not None
    assert users.get_user(None, "ana", "wrong") is None
    assert users.get_user(None, "nobody", "x") is None
    assert users.role_of(session("ana")) is Role.OPERATE
    assert users.role_of(session("vic")) is Role.OBSERVE
    assert users.role_of(session(None)) is Role.OBSERVE  # anonymous: the configured role
    assert users.role_of(session("nobody")) is Role.OBSERVE


def test_guessing_is_locked_out_without_a_check_and_a_good_check_is_remembered(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    now = [0.0]
    users = ConfiguredUsers((ANA,), Role.OBSERVE, clock=lambda: now[0])
    checks: list[str] = []

    def counted(password: str, stored: object) -> bool:
        checks.append(password)
        return verify_password(password, stored)  # type: ignore[arg-type]

    monkeypatch.setattr(users_mod, "verify_password", counted)
    for _ in range(MAX_FAILURES):
        assert users.get_user(None, "ana", "guess") is None
    assert len(checks) == MAX_FAILURES
    assert users.get_user(None, "ana", "ana-secret") is None  # locked: not even checked
    assert len(checks) == MAX_FAILURES
    now[0] += LOCKOUT + 1
    assert users.get_user(None, "ana", "ana-secret") is not None
    assert users.get_user(None, "ana", "ana-secret") is not None  # remembered
    assert len(checks) == MAX_FAILURES + 1


USERS = f"""
[[users]]
name = "ana"
role = "operator"
password = "{ANA.password.line() if ANA.password else ""}"

[[users]]
name = "vic"
role = "viewer"
password = "{VIC.password.line() if VIC.password else ""}"
"""


async def test_a_viewer_session_is_refused_run_and_an_operator_runs(tmp_path: Path) -> None:
    async with running_gateway(tmp_path, extra_root=USERS) as gateway:
        viewer = Client(gateway.endpoint, timeout=TIMEOUT)
        viewer.set_user("vic")
        viewer.set_password("vic-secret")
        async with viewer:
            result = await call(viewer, "m1", "Run")
            assert result.StatusCode.value == ua.StatusCodes.BadUserAccessDenied
            assert "may not operate" in text(result)
        assert not gateway.daemon.hub.desired("m1").run
        operator = Client(gateway.endpoint, timeout=TIMEOUT)
        operator.set_user("ana")
        operator.set_password("ana-secret")
        async with operator:
            assert (await call(operator, "m1", "Run")).StatusCode.is_good()
        assert gateway.daemon.hub.desired("m1").run
        wrong = Client(gateway.endpoint, timeout=TIMEOUT)
        wrong.set_user("ana")
        wrong.set_password("not-hers")
        with pytest.raises(ua.UaStatusCodeError):
            async with wrong:
                pass
