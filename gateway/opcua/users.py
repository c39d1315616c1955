"""OPC UA sessions' users: the config's ``[[users]]`` (gateway/access), mapped to roles.

A session that activates with a user name and password is checked against that user's
scrypt hash (the web's own users and hashes: one user directory for every interface); its
role is the user's. A session may operate (call the drives' methods, acknowledge alarms)
when its user's role is operator or above; every session may browse, read, subscribe and
read history. Without ``[[users]]`` in the config the server keeps its default
(:func:`gateway.opcua.sessions.default_roles`: every session operates on a loopback-only
server, none elsewhere).

Password checks cost about 0.1 s of CPU each (scrypt, decision 0080) and asyncua asks on
the daemon's loop: a check that succeeded is remembered (a digest of the name and password,
never the password) so a client reconnecting does not pay it again, and a user name with
:data:`MAX_FAILURES` failed checks in a row is refused without a check for
:data:`LOCKOUT` s, so guessing cannot hold the loop.
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable
from typing import Any, Final

from asyncua.crypto.permission_rules import User as UaUser
from asyncua.crypto.permission_rules import UserRole

from gateway.access.passwords import verify_password
from gateway.access.roles import Role as AccessRole
from gateway.access.users import User
from gateway.opcua.sessions import Role, SessionUser

log = logging.getLogger(__name__)

MAX_FAILURES: Final = 5  # failed checks of one user name in a row before the lockout
LOCKOUT: Final = 60.0  # s a locked user name is refused without a check
REMEMBERED: Final = 256  # successful checks remembered (a digest each)


class ConfiguredUsers:
    """asyncua's user manager over the config's users (see the module docstring)."""

    def __init__(
        self,
        users: tuple[User, ...],
        anonymous: Role,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._users = {u.name: u for u in users}
        self._anonymous = anonymous
        self._clock = clock
        self._verified: set[bytes] = set()
        self._failures: dict[str, tuple[int, float]] = {}  # name -> (in a row, last)
        self.refused = 0

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> UaUser | None:
        """The session's user, or None (the activation is refused: BadIdentityTokenRejected)."""
        if username is None:
            return UaUser(role=UserRole.User, name=None)
        if self._check(username, password or ""):
            return UaUser(role=UserRole.User, name=username)
        self.refused += 1
        return None

    def role_of(self, user: SessionUser) -> Role:
        """OPERATE for a user of role operator or above; OBSERVE else (anonymous: the
        configured ``anonymous`` role)."""
        if user.user_name is None:
            return self._anonymous
        found = self._users.get(user.user_name)
        if found is None:
            return Role.OBSERVE
        return Role.OPERATE if found.role >= AccessRole.OPERATOR else Role.OBSERVE

    def _check(self, name: str, password: str) -> bool:
        user = self._users.get(name)
        now = self._clock()
        count, last = self._failures.get(name, (0, 0.0))
        if count >= MAX_FAILURES and now - last < LOCKOUT:
            return False
        key = hashlib.sha256(f"{name}\0{password}".encode()).digest()
        if key in self._verified:
            return True
        if user is None or user.password is None or not verify_password(password, user.password):
            self._failures[name if user is not None else ""] = (count + 1, now)
            if count + 1 == MAX_FAILURES:
                log.warning(
                    "OPC UA: user %r refused %d times in a row: locked %g s",
                    name,
                    count + 1,
                    LOCKOUT,
                )
            return False
        self._failures.pop(name, None)
        if len(self._verified) >= REMEMBERED:
            self._verified.clear()
        self._verified.add(key)
        return True
