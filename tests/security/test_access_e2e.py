"""Who may do what, through the demo daemon with its buses simulated (issue 35): web
users by role with sessions and CSRF, failed logins limited per address, Modbus peers by
rights, Zenoh commands and parameter writes on the audit trail, the audit file as written
and the trail read back by an engineer on the page and on Zenoh."""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import struct
from collections.abc import AsyncIterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import aiohttp

from gateway.access.audit import AuditSection
from gateway.access.passwords import hash_password
from gateway.access.roles import Role
from gateway.access.users import User
from gateway.runtime.daemon import READY_BOUND, Daemon
from gateway.runtime.systemd import Notifier
from gateway.web.frontend import WebFrontEnd
from gateway.webconfig import WebLimits
from tests.modbus.conftest import mbap
from tests.support.net import zenoh_endpoint
from tests.web.harness import DEMO_DRIVES, PREFIX, TIMEOUT, demo_config
from tests.zenoh.client import Client

PASSWORD = "a good password"
_HASH = hash_password(PASSWORD, n=1 << 14)
USERS = (
    User("vic", Role.VIEWER, _HASH),
    User("ana", Role.OPERATOR, _HASH),
    User("eng", Role.ENGINEER, _HASH),
)
READ_ONLY_PEER = "127.0.0.2"  # [[modbus.peers]] rights = "read"
FAILURES = 3  # web.token_failures of this test
DRIVE, UNIT = "cfw11", 1  # the demo's first Profibus drive and its Modbus unit
RUN_WORD, STOP_WORD = 0x0001, 0x0000
ILLEGAL_FUNCTION = 1


@dataclass
class Site:
    daemon: Daemon
    zenoh: Client
    url: str
    modbus_port: int
    audit_file: Path

    def session(self, local: str = "127.0.0.1") -> aiohttp.ClientSession:
        return aiohttp.ClientSession(
            timeout=aiohttp.ClientTimeout(total=TIMEOUT),
            cookie_jar=aiohttp.CookieJar(unsafe=True),
            connector=aiohttp.TCPConnector(local_addr=(local, 0)),
        )

    def audit(self) -> list[dict[str, Any]]:
        return self.daemon.runtime.audit.newest()

    def audit_lines(self) -> list[dict[str, Any]]:
        return [json.loads(line) for line in self.audit_file.read_text().splitlines()]


@contextlib.asynccontextmanager
async def site(tmp_path: Path) -> AsyncIterator[Site]:
    client_endpoint = zenoh_endpoint()
    zenoh = Client(client_endpoint, asyncio.get_running_loop(), listen=True)
    config = demo_config(client_endpoint)
    limits = replace(WebLimits(), token_failures=FAILURES, token_window=600.0)
    audit_file = tmp_path / "audit.log"
    config = replace(
        config,
        users=USERS,
        web=replace(config.web, commands=True, limits=limits),
        modbus=replace(
            config.modbus,
            peers=((ipaddress.ip_network(f"{READ_ONLY_PEER}/32"), False),),
        ),
        audit=AuditSection(file=audit_file, max_kib=256, backups=2, journal=False),
    )
    daemon = Daemon(config, notifier=Notifier({}))
    task = asyncio.create_task(daemon.run())
    try:
        await asyncio.wait_for(daemon.ready.wait(), READY_BOUND + TIMEOUT)
        for drive in DEMO_DRIVES:
            await asyncio.wait_for(daemon.hub.wait_for(drive, lambda s: s.online), TIMEOUT)
        web = daemon.front_ends["web"]
        assert isinstance(web, WebFrontEnd)
        yield Site(daemon, zenoh, web.url, config.modbus.port, audit_file)
    finally:
        daemon.request_stop()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, 15)
        zenoh.close()


async def login(http: aiohttp.ClientSession, url: str, user: str, password: str = PASSWORD) -> Any:
    async with http.post(f"{url}api/login", json={"user": user, "password": password}) as r:
        return r.status, await r.json()


async def command(
    http: aiohttp.ClientSession, url: str, body: dict[str, Any], csrf: str | None
) -> Any:
    headers = {"X-CSRF-Token": csrf} if csrf is not None else {}
    async with http.post(f"{url}api/drives/{DRIVE}/command", json=body, headers=headers) as r:
        return r.status, await r.json()


async def test_web_roles_csrf_and_the_audit_trail(tmp_path: Path) -> None:
    async with site(tmp_path) as gw, gw.session() as viewer, gw.session() as operator:
        # a viewer is refused a command with the reason, and the refusal is audited
        _, vic = await login(viewer, gw.url, "vic")
        status, body = await command(viewer, gw.url, {"run": True, "speed_rpm": 300}, vic["csrf"])
        assert (status, body["error"]) == (
            403,
            "vic has the viewer role; command needs operator or above",
        )
        assert not gw.daemon.hub.desired(DRIVE).run
        # an operator's command without the session's CSRF token is refused, then with it
        # accepted; both audited
        _, ana = await login(operator, gw.url, "ana")
        status, body = await command(operator, gw.url, {"run": True, "speed_rpm": 300}, None)
        assert status == 403 and "X-CSRF-Token" in body["error"]
        assert not gw.daemon.hub.desired(DRIVE).run
        status, body = await command(operator, gw.url, {"run": True, "speed_rpm": 300}, ana["csrf"])
        assert status == 200 and body["accepted"], body
        await asyncio.wait_for(gw.daemon.hub.wait_for(DRIVE, lambda s: s.running), TIMEOUT)
        status, _ = await command(operator, gw.url, {"run": False}, ana["csrf"])
        assert status == 200
        await asyncio.wait_for(gw.daemon.hub.wait_for(DRIVE, lambda s: not s.running), TIMEOUT)
        # the operator may not read the audit trail; the engineer may
        async with operator.get(f"{gw.url}api/audit") as r:
            assert r.status == 403
        async with gw.session() as engineer:
            await login(engineer, gw.url, "eng")
            async with engineer.get(f"{gw.url}api/audit") as r:
                assert r.status == 200
                records = (await r.json())["records"]
    seen = [(r["type"], r["result"], r["identity"]) for r in records]
    assert seen[0] == ("config_load", "success", "drive-gateway")
    assert ("refused", "failure", "vic") in seen
    assert ("csrf", "failure", "ana") in seen
    assert seen.count(("command", "success", "ana")) == 2  # run, then stop
    assert ("login", "success", "eng") in seen
    assert ("refused", "failure", "ana") in seen  # the operator asking for the audit
    # the file holds the same records, one JSON line each, with CR 2.8's fields
    lines = gw.audit_lines()
    assert [r["seq"] for r in lines] == sorted(r["seq"] for r in lines)
    refusal = next(r for r in lines if r["type"] == "refused" and r["identity"] == "vic")
    assert refusal | {"timestamp": "-", "seq": 0} == {
        "seq": 0,
        "timestamp": "-",
        "interface": "web",
        "peer": "127.0.0.1",
        "identity": "vic",
        "role": "viewer",
        "category": "access",
        "type": "refused",
        "event_id": 1010,
        "result": "failure",
        "detail": f"POST /api/drives/{DRIVE}/command: vic has the viewer role; command needs "
        "operator or above",
    }
    assert refusal["timestamp"].endswith("Z")


async def test_failed_logins_lock_out_the_address_only(tmp_path: Path) -> None:
    async with site(tmp_path) as gw, gw.session() as guesser, gw.session("127.0.0.3") as other:
        for _ in range(FAILURES):
            status, _ = await login(guesser, gw.url, "ana", "guess")
            assert status == 401
        status, body = await login(guesser, gw.url, "ana")  # the right one, not even checked
        assert status == 429 and "too many failed logins" in body["error"]
        status, _ = await login(other, gw.url, "ana")
        assert status == 200
        async with other.get(f"{gw.url}metrics") as r:
            metrics = await r.text()
    assert 'drive_gateway_web_logins_total{result="failure"} 3.0' in metrics
    assert 'drive_gateway_web_logins_total{result="limited"} 1.0' in metrics
    kinds = [(r["type"], r["result"], r["peer"]) for r in gw.audit_lines()]
    assert kinds.count(("login", "failure", "127.0.0.1")) == FAILURES
    assert ("login_limited", "failure", "127.0.0.1") in kinds
    assert ("login", "success", "127.0.0.3") in kinds


async def modbus_write(port: int, local: str, word: int, tid: int) -> bytes:
    """Write the command word of the drive's unit from ``local``; the reply."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(local, 0))
    try:
        writer.write(mbap(UNIT, struct.pack(">BHH", 6, 0, word), tid))
        await writer.drain()
        return await asyncio.wait_for(reader.read(260), TIMEOUT)
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def test_a_read_only_modbus_peer_is_refused_and_zenoh_is_audited(tmp_path: Path) -> None:
    async with site(tmp_path) as gw:
        answer = await modbus_write(gw.modbus_port, READ_ONLY_PEER, RUN_WORD, tid=7)
        assert answer == mbap(UNIT, bytes([6 | 0x80, ILLEGAL_FUNCTION]), 7)
        assert not gw.daemon.hub.desired(DRIVE).run
        # a Zenoh command and a parameter write are on the trail with the session's label
        reply = await gw.zenoh.aone(f"{PREFIX}/drives/{DRIVE}/command", {"quick_stop": True})
        assert reply.json() == {"accepted": True}
        await gw.zenoh.aone(f"{PREFIX}/drives/{DRIVE}/params/100", {"value": 25})
        # an engineer's SCADA reads the trail on Zenoh
        reply = await gw.zenoh.aone(f"{PREFIX}/gateway/audit")
        records = reply.json()["records"]
        since = records[-2]["seq"]
        newer = (await gw.zenoh.aone(f"{PREFIX}/gateway/audit?since={since}")).json()["records"]
    refusal = next(r for r in records if r["interface"] == "modbus")
    assert (refusal["type"], refusal["result"], refusal["peer"]) == (
        "refused",
        "failure",
        READ_ONLY_PEER,
    )
    assert "this client may read only (its [[modbus.peers]] rights)" in refusal["detail"]
    link = next(r for r in records if r["type"] == "link_open")
    assert link["interface"] == "zenoh" and link["detail"].endswith(", no certificate")
    zenoh = [r for r in records if r["interface"] == "zenoh" and r["category"] != "access"]
    assert [(r["type"], r["result"]) for r in zenoh] == [
        ("command", "success"),
        ("param_write", "success"),
    ]
    assert zenoh[1]["detail"] == f"drive {DRIVE} parameter 100/0 = 25"
    assert [r["seq"] for r in newer] == [records[-1]["seq"]]
