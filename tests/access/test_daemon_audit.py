"""The daemon opens the configured audit trail before anything serves: its first record is
the configuration loaded; a file it cannot open stops the start with the reason."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from gateway.access.audit import AuditSection
from gateway.access.passwords import hash_password
from gateway.access.roles import Role
from gateway.access.users import User
from gateway.config import Config, ModbusSection, ZenohSection
from gateway.runtime.daemon import EXIT_STARTUP, READY_BOUND, Daemon
from gateway.runtime.systemd import Notifier
from tests.support.timing import scaled

TIMEOUT = scaled(30.0)


def config(audit: AuditSection, users: tuple[User, ...] = ()) -> Config:
    return Config(
        file="site.toml",
        zenoh=ZenohSection(enabled=False),
        modbus=ModbusSection(enabled=False),
        audit=audit,
        users=users,
    )


async def run_once(cfg: Config) -> None:
    daemon = Daemon(cfg, notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
    daemon.request_stop()
    assert await asyncio.wait_for(task, TIMEOUT) == 0


async def test_user_changes_between_starts_are_recorded(tmp_path: Path) -> None:
    path = tmp_path / "audit.log"
    audit = AuditSection(file=path, journal=False)
    old, new = hash_password("first password", n=1 << 14), hash_password("second", n=1 << 14)
    await run_once(config(audit, (User("ana", Role.OPERATOR, old), User("vic", Role.VIEWER, old))))
    await run_once(config(audit, (User("ana", Role.ENGINEER, new), User("bob", Role.VIEWER, old))))
    await run_once(config(audit, (User("ana", Role.ENGINEER, new), User("bob", Role.VIEWER, old))))
    changes = [
        r["detail"]
        for r in map(json.loads, path.read_text().splitlines())
        if r["type"] == "user_change"
    ]
    assert changes == [
        "user ana added with the operator role (site.toml)",
        "user vic added with the viewer role (site.toml)",
        "user bob added with the viewer role (site.toml)",
        "user vic removed (site.toml)",
        "user ana: role operator -> engineer (site.toml)",
        "user ana: password or token changed (site.toml)",
    ]
    assert "scrypt" not in (tmp_path / "audit.log.users").read_text()


async def test_the_first_record_is_the_configuration_loaded(tmp_path: Path) -> None:
    path = tmp_path / "audit.log"
    daemon = Daemon(config(AuditSection(file=path, journal=False)), notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
    daemon.check_reload()  # SIGHUP: no reload, and the trail says so
    daemon.request_stop()
    assert await asyncio.wait_for(task, TIMEOUT) == 0
    first, second = (json.loads(line) for line in path.read_text().splitlines())
    assert (first["type"], first["category"], first["event_id"], first["result"]) == (
        "config_load",
        "config",
        4001,
        "success",
    )
    assert first["detail"] == "site.toml: 0 drive(s), 0 user(s)"
    assert (second["type"], second["interface"], second["result"]) == (
        "config_reload",
        "signal",
        "failure",
    )


async def test_an_audit_file_that_cannot_be_opened_stops_the_start(tmp_path: Path) -> None:
    where = tmp_path / "no such directory" / "audit.log"
    daemon = Daemon(config(AuditSection(file=where, journal=False)), notifier=Notifier({}))
    assert await asyncio.wait_for(daemon.run(), TIMEOUT) == EXIT_STARTUP
    assert daemon.fatal is not None
    assert f"cannot open [audit] file {where}: no such file or directory" in str(daemon.fatal)
