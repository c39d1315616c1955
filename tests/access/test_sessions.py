"""Web sessions: found while fresh, ended when idle, old, closed or crowded out; CSRF."""

from __future__ import annotations

from gateway.access.roles import Identity, Role
from gateway.access.sessions import Sessions, csrf_ok

ANA = Identity("ana", Role.OPERATOR)
BOB = Identity("bob", Role.VIEWER)


def test_a_session_is_found_by_its_id_only() -> None:
    sessions = Sessions(idle=10, lifetime=100)
    opened = sessions.open(ANA, 0.0)
    found = sessions.find(opened.session_id, 1.0)
    assert found is not None and found.identity == ANA and found.csrf == opened.csrf
    assert sessions.find(opened.session_id + "x", 1.0) is None
    assert sessions.find(None, 1.0) is None and sessions.find("", 1.0) is None
    assert opened.session_id not in repr(sessions._by_digest)  # only digests are kept


def test_a_session_ends_when_idle_or_old() -> None:
    sessions = Sessions(idle=10, lifetime=25)
    idle = sessions.open(ANA, 0.0)
    assert sessions.find(idle.session_id, 10.0) is not None  # at the bound: still on
    assert sessions.find(idle.session_id, 20.5) is None  # 10.5 s unused
    used = sessions.open(ANA, 0.0)
    for t in (8.0, 16.0, 24.0):
        assert sessions.find(used.session_id, t) is not None
    assert sessions.find(used.session_id, 25.5) is None  # past its lifetime, though used
    assert len(sessions) == 0


def test_logout_and_a_user_change_end_sessions() -> None:
    sessions = Sessions()
    a1, a2, b = sessions.open(ANA, 0), sessions.open(ANA, 0), sessions.open(BOB, 0)
    assert sessions.close(a1.session_id) is not None
    assert sessions.find(a1.session_id, 1) is None
    assert sessions.close_user("ana") == 1
    assert sessions.find(a2.session_id, 1) is None and sessions.find(b.session_id, 1)


def test_the_table_is_bounded_and_the_least_used_goes_first() -> None:
    sessions = Sessions(limit=3)
    first, second = sessions.open(ANA, 0), sessions.open(ANA, 0)
    sessions.open(BOB, 0)
    assert sessions.find(first.session_id, 1)  # used: now the most recent
    sessions.open(BOB, 2)
    assert len(sessions) == 3
    assert sessions.find(second.session_id, 3) is None
    assert sessions.find(first.session_id, 3) is not None


def test_csrf_needs_the_sessions_own_token() -> None:
    sessions = Sessions()
    opened = sessions.open(ANA, 0)
    other = sessions.open(ANA, 0)
    session = sessions.find(opened.session_id, 1)
    assert session is not None
    assert csrf_ok(session, opened.csrf)
    assert not csrf_ok(session, None) and not csrf_ok(session, "")
    assert not csrf_ok(session, other.csrf)
    assert not csrf_ok(session, opened.csrf + "\udcff")
