"""Users and roles on the web: login and its session cookie, CSRF, what each role may do,
failed logins limited per address, every decision audited; HTTPS from the configured
certificate (gateway/web/auth.py, gateway/access)."""

from __future__ import annotations

import datetime
import ssl
from dataclasses import replace
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from gateway.access.passwords import hash_password, token_digest
from gateway.access.roles import Role
from gateway.access.users import User
from gateway.webconfig import WebLimits
from tests.web.harness import TIMEOUT, Small, small_gateway, web_section

PASSWORD = "a good password"
_HASH = hash_password(PASSWORD, n=1 << 14)
USERS = tuple(
    User(name, role, _HASH, token_digest(f"token-of-{name}"))
    for name, role in (
        ("vic", Role.VIEWER),
        ("ana", Role.OPERATOR),
        ("eng", Role.ENGINEER),
    )
)
RUN = {"run": True}


def gateway(**web: Any) -> Any:
    section = web_section(commands=True, **web)
    return small_gateway(section, users=USERS)


async def login(gw: Small, user: str, password: str = PASSWORD) -> tuple[int, dict[str, Any]]:
    async with gw.http.post(f"{gw.url}api/login", json={"user": user, "password": password}) as r:
        return r.status, await r.json()


async def command(gw: Small, csrf: str | None = None, token: str | None = None) -> Any:
    headers = {}
    if csrf is not None:
        headers["X-CSRF-Token"] = csrf
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    async with gw.http.post(f"{gw.url}api/drives/d1/command", json=RUN, headers=headers) as r:
        return r.status, await r.json()


def audit(gw: Small) -> list[dict[str, Any]]:
    return gw.runtime.audit.newest()


async def test_a_login_opens_a_session_in_a_strict_http_only_cookie() -> None:
    async with gateway() as gw:
        async with gw.http.post(
            f"{gw.url}api/login", json={"user": "ana", "password": PASSWORD}
        ) as r:
            assert r.status == 200
            body = await r.json()
            cookie = r.headers["Set-Cookie"]
        assert body["user"] == "ana" and body["role"] == "operator" and len(body["csrf"]) > 40
        assert "dg_session=" in cookie and "HttpOnly" in cookie and "SameSite=Strict" in cookie
        assert "Secure" not in cookie  # plain HTTP: a Secure cookie would never come back
        async with gw.http.get(f"{gw.url}api/session") as r:
            assert await r.json() == {"user": "ana", "role": "operator", "csrf": body["csrf"]}
        last = audit(gw)[-1]
        assert (last["type"], last["result"], last["identity"], last["role"]) == (
            "login",
            "success",
            "ana",
            "operator",
        )
        assert last["interface"] == "web" and last["peer"] == "127.0.0.1"
        async with gw.http.post(f"{gw.url}api/logout", headers={"X-CSRF-Token": body["csrf"]}) as r:
            assert r.status == 200
        async with gw.http.get(f"{gw.url}api/session") as r:
            assert (await r.json())["user"] is None
        assert audit(gw)[-1]["type"] == "logout"


async def test_a_viewer_is_refused_a_command_with_the_reason_and_it_is_audited() -> None:
    from gateway.adapter import EventKind

    async with gateway() as gw:
        _, body = await login(gw, "vic")
        with gw.hub.subscribe_events() as events:
            status, answer = await command(gw, csrf=body["csrf"])
            refused = [e for e in events.drain() if e.kind is EventKind.COMMAND_REFUSED]
        assert [e.text for e in refused] == [
            "command from web 127.0.0.1 refused: vic has the viewer role; command needs "
            "operator or above"
        ]
        assert status == 403 and answer == {
            "accepted": False,
            "error": "vic has the viewer role; command needs operator or above",
        }
        assert not gw.hub.desired("d1").run
        last = audit(gw)[-1]
        assert (last["type"], last["category"], last["event_id"], last["result"]) == (
            "refused",
            "access",
            1010,
            "failure",
        )
        assert last["identity"] == "vic" and "command needs operator" in last["detail"]
        assert gw.web.counters.refused["role"] == 1


async def test_an_operators_command_needs_the_csrf_token_and_is_audited() -> None:
    async with gateway() as gw:
        _, body = await login(gw, "ana")
        status, answer = await command(gw)  # the cookie alone: what another site's page has
        assert status == 403 and "X-CSRF-Token" in answer["error"]
        status, _ = await command(gw, csrf="not-it")
        assert status == 403 and not gw.hub.desired("d1").run
        # the second within 10 s of the first is counted, and said in the next record
        assert [r["type"] for r in audit(gw)[-2:]] == ["login", "csrf"]
        assert gw.runtime.audit.counts["csrf:failure"] == 2
        status, answer = await command(gw, csrf=body["csrf"])
        assert status == 200 and answer["accepted"] is True
        assert gw.hub.desired("d1").run
        last = audit(gw)[-1]
        assert (last["type"], last["result"], last["identity"]) == ("command", "success", "ana")
        assert last["detail"].startswith("drive d1: ")
        async with gw.http.post(  # the page's keep-alive: no record of its own
            f"{gw.url}api/drives/d1/command", json={}, headers={"X-CSRF-Token": body["csrf"]}
        ) as r:
            assert r.status == 200
        assert audit(gw)[-1] == last


async def test_api_tokens_identify_their_user() -> None:
    async with gateway() as gw:
        status, answer = await command(gw, token="token-of-vic")
        assert status == 403 and answer["error"].startswith("vic has the viewer role")
        status, _ = await command(gw, token="token-of-ana")
        assert status == 200 and gw.hub.desired("d1").run
        assert audit(gw)[-1]["identity"] == "ana"
        status, _ = await command(gw, token="token-of-nobody")
        assert status == 401 and audit(gw)[-1]["type"] == "token"


async def test_the_audit_trail_is_for_engineers() -> None:
    async with gateway() as gw:
        async with gw.http.get(
            f"{gw.url}api/audit", headers={"Authorization": "Bearer token-of-ana"}
        ) as r:
            assert r.status == 403
            assert "audit_read needs engineer" in (await r.json())["error"]
        await login(gw, "eng")
        async with gw.http.get(f"{gw.url}api/audit?limit=3") as r:
            assert r.status == 200
            records = (await r.json())["records"]
        assert [(r["type"], r["identity"]) for r in records] == [
            ("refused", "ana"),
            ("login", "eng"),
        ]
        async with gw.http.get(f"{gw.url}api/audit?since=1") as r:
            assert [r["seq"] for r in (await r.json())["records"]] == [2]
        assert {"timestamp", "interface", "peer", "identity", "category", "type"} <= set(records[0])


async def test_failed_logins_are_limited_per_address() -> None:
    limits = replace(WebLimits(), token_failures=3, token_window=600.0)
    async with gateway(limits=limits) as gw:
        for _ in range(3):
            status, answer = await login(gw, "ana", "wrong")
            assert status == 401 and answer["error"] == "wrong user name or password"
        status, _ = await login(gw, "nobody", "wrong")
        assert status == 429
        status, _ = await login(gw, "ana")  # the right password, unchecked: still refused
        assert status == 429
        # another address is not held back by this one's failures
        other = aiohttp.ClientSession(
            connector=aiohttp.TCPConnector(local_addr=("127.0.0.2", 0)),
            timeout=aiohttp.ClientTimeout(total=TIMEOUT),
        )
        async with (
            other,
            other.post(f"{gw.url}api/login", json={"user": "ana", "password": PASSWORD}) as r,
        ):
            assert r.status == 200
        assert gw.web.counters.logins == {"success": 1, "failure": 3, "limited": 2}
        async with gw.http.get(f"{gw.url}metrics") as r:
            text = await r.text()
        assert 'drive_gateway_web_logins_total{result="limited"} 2.0' in text
        assert 'drive_gateway_audit_records_total{result="failure",type="login"} 3.0' in text
        kinds = [(r["type"], r["result"], r["peer"]) for r in audit(gw)]
        assert kinds.count(("login", "failure", "127.0.0.1")) == 3
        # refused unchecked: the first of 10 s written, the next counted (audit.FOLD_PERIOD)
        assert kinds.count(("login_limited", "failure", "127.0.0.1")) == 1
        assert gw.runtime.audit.counts["login_limited:failure"] == 2
        assert ("login", "success", "127.0.0.2") in kinds


async def test_logins_waiting_for_their_check_are_bounded(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import asyncio
    import threading

    from gateway.web import auth

    release = threading.Event()

    def held(password: str, stored: Any) -> bool:  # the KDF, held until the test says
        release.wait(TIMEOUT)
        return False

    monkeypatch.setattr(auth, "verify_password", held)
    async with gateway() as gw:
        real = gw.web.auth._kdf
        all_in = asyncio.Event()
        submitted: list[Any] = []

        class Counting:  # the KDF's executor, telling when every login is waiting
            def submit(self, fn: Any, *args: Any) -> Any:
                submitted.append(fn)
                if len(submitted) == auth.MAX_LOGINS_WAITING:
                    all_in.set()
                return real.submit(fn, *args)

        monkeypatch.setattr(gw.web.auth, "_kdf", Counting())
        n = auth.MAX_LOGINS_WAITING
        waiting = [asyncio.create_task(login(gw, "ana", "x")) for _ in range(n)]
        await asyncio.wait_for(all_in.wait(), TIMEOUT)
        status, body = await login(gw, "ana", "x")
        assert status == 503 and body["error"] == "too many logins at once: try again"
        release.set()
        assert [status for status, _ in await asyncio.gather(*waiting)] == [401] * 8
        assert gw.web.counters.refused["login_busy"] == 1
        monkeypatch.setattr(gw.web.auth, "_kdf", real)  # shut down with the front end


@pytest.mark.parametrize(
    "body",
    [
        b"",
        b"{",
        b'{"user": "ana"}',
        b'{"user": 1, "password": "x"}',
        b'{"user": "ana", "password": "' + b"x" * 300 + b'"}',
    ],
)
async def test_a_malformed_login_is_refused_unchecked(body: bytes) -> None:
    async with gateway() as gw:
        json_type = {"Content-Type": "application/json"}
        async with gw.http.post(f"{gw.url}api/login", data=body, headers=json_type) as r:
            assert r.status == 400
        assert gw.web.counters.logins["failure"] == 0


async def test_a_login_from_a_form_of_another_site_is_refused() -> None:
    """A text/plain form can forge a JSON body (name ``{"user":"x","password":"p``, value
    ``w"}``) and log the operator's browser in as someone else: refused unchecked."""
    forged = b'{"user":"ana","password":"a good pass=word"}'
    async with gateway() as gw:
        async with gw.http.post(
            f"{gw.url}api/login", data=forged, headers={"Content-Type": "text/plain"}
        ) as r:
            assert r.status == 415
        async with gw.http.post(
            f"{gw.url}api/login",
            json={"user": "ana", "password": PASSWORD},
            headers={"Origin": "https://evil.example"},
        ) as r:
            assert r.status == 403
            assert "Set-Cookie" not in r.headers
        assert gw.web.counters.logins == {"success": 0, "failure": 0, "limited": 0}


async def test_a_wrong_token_on_a_read_is_refused_and_counted() -> None:
    limits = replace(WebLimits(), token_failures=2, token_window=600.0)
    async with gateway(limits=limits) as gw:
        wrong = {"Authorization": "Bearer guess"}
        for status in (401, 401, 429):
            async with gw.http.get(f"{gw.url}api/audit", headers=wrong) as r:
                assert r.status == status
        async with gw.http.get(  # the right token from that address: held back too
            f"{gw.url}api/audit", headers={"Authorization": "Bearer token-of-eng"}
        ) as r:
            assert r.status == 429
        async with gw.http.get(f"{gw.url}api/drives") as r:  # no token: a viewer still
            assert r.status == 200


async def test_with_anonymous_none_only_the_page_and_the_login_are_open() -> None:
    async with gateway(anonymous=False) as gw:
        async with gw.http.get(f"{gw.url}api/drives") as r:
            assert r.status == 401
        async with gw.http.get(gw.url) as r:
            assert r.status == 200
        await login(gw, "vic")
        async with gw.http.get(f"{gw.url}api/drives") as r:
            assert r.status == 200


async def test_refusals_at_the_door_are_audited() -> None:
    import ipaddress

    async with gateway() as gw:
        async with gw.http.get(f"{gw.url}api/health", headers={"Host": "evil.example"}) as r:
            assert r.status == 421
        host = audit(gw)[-1]
        assert (host["type"], host["category"], host["event_id"]) == (
            "request_refused",
            "access",
            1012,
        )
        assert host["detail"].startswith("host: web request from 127.0.0.1 refused (421)")
    only_other = (ipaddress.ip_network("127.0.0.2/32"),)
    async with small_gateway(web_section(allow=only_other)) as gw:
        with pytest.raises(aiohttp.ClientError):
            async with gw.http.get(f"{gw.url}api/health") as r:
                await r.read()
        refused = audit(gw)[-1]
        assert (refused["type"], refused["peer"]) == ("request_refused", "127.0.0.1")
        assert refused["detail"].startswith("allow: web connection from 127.0.0.1 refused")


# ---------------------------------------------------------------- TLS


def self_signed(tmp_path: Path) -> tuple[Path, Path]:
    """A certificate for 127.0.0.1 and its key, made now (the cryptography package)."""
    x509 = pytest.importorskip("cryptography.x509")
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")])
    now = datetime.datetime.now(datetime.UTC)
    import ipaddress

    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
            critical=False,
        )
        .sign(key, hashes.SHA256())
    )
    cert_path, key_path = tmp_path / "web.crt", tmp_path / "web.key"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return cert_path, key_path


async def test_the_page_over_tls_with_a_secure_cookie(tmp_path: Path) -> None:
    cert, key = self_signed(tmp_path)
    async with gateway(tls_cert=cert, tls_key=key) as gw:
        assert gw.url.startswith("https://127.0.0.1:")
        trusting = ssl.create_default_context(cafile=str(cert))
        async with gw.http.post(
            f"{gw.url}api/login", json={"user": "ana", "password": PASSWORD}, ssl=trusting
        ) as r:
            assert r.status == 200
            assert "Secure" in r.headers["Set-Cookie"]
        plain = gw.url.replace("https://", "http://")
        with pytest.raises(aiohttp.ClientError):
            async with gw.http.get(f"{plain}api/health") as r:
                await r.read()


async def test_a_key_that_does_not_load_stops_the_start(tmp_path: Path) -> None:
    cert, _ = self_signed(tmp_path)
    bad = tmp_path / "bad.key"
    bad.write_text("not a key")
    from gateway.errors import StartupError

    with pytest.raises(StartupError, match=r"cannot load web\.tls_cert"):
        async with gateway(tls_cert=cert, tls_key=bad):
            pass


async def test_with_anonymous_none_the_first_html_shows_no_drive_before_the_login() -> None:
    """The page's first HTML carries the drive table (the script is not needed to see it):
    to a visitor who may not read, it carries none; after the login, the drives."""
    async with small_gateway(web_section(anonymous=False), users=USERS) as gw:
        async with gw.http.get(gw.url) as r:
            assert r.status == 200
            before = await r.text()
        assert 'data-drive="d1"' not in before and 'id="drives-body"' in before
        status, _ = await login(gw, "ana")
        assert status == 200
        async with gw.http.get(gw.url) as r:
            after = await r.text()
        assert 'data-drive="d1"' in after
