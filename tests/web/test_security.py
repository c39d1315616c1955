"""The web front end refuses what it must: commands while they are off, a command without
the token, every connection from outside ``web.allow``; and answers with its security
headers."""

from __future__ import annotations

import ipaddress

import aiohttp
import pytest

from gateway.adapter import EventKind
from gateway.model import Source, client_label
from gateway.web.admission import allowed
from tests.web.harness import TOKEN, TOKEN_SHA256, small_gateway, web_section

RUN = {"run": True}


async def post(http: aiohttp.ClientSession, url: str, body: object, token: str | None = None):
    headers = {"X-Page-Id": "page-1"}
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    async with http.post(url, json=body, headers=headers) as r:
        return r.status, await r.json()


async def test_with_commands_off_a_command_is_refused_even_with_a_token() -> None:
    async with small_gateway(web_section(token_sha256=TOKEN_SHA256)) as gw:
        status, body = await post(gw.http, f"{gw.url}api/drives/d1/command", RUN, TOKEN)
        assert status == 403 and body["accepted"] is False and "web.commands" in body["error"]
        assert not gw.hub.desired("d1").run
        assert gw.web.counters.refused["commands_off"] == 1


async def test_with_commands_on_a_command_without_the_token_is_refused() -> None:
    async with small_gateway(web_section(commands=True, token_sha256=TOKEN_SHA256)) as gw:
        url = f"{gw.url}api/drives/d1/command"
        for token in (None, "", "wrong", TOKEN + " "):
            status, body = await post(gw.http, url, RUN, token)
            if token == TOKEN + " ":  # the token itself, padded: accepted (stripped)
                continue
            assert status == 401 and body["accepted"] is False, (token, status, body)
            assert not gw.hub.desired("d1").run
        async with gw.http.post(url, json=RUN, headers={"Authorization": f"Basic {TOKEN}"}) as r:
            assert r.status == 401
        assert gw.web.counters.refused["token"] >= 4


async def test_a_command_with_the_token_goes_through_the_hub_as_a_web_client() -> None:
    async with small_gateway(web_section(commands=True, token_sha256=TOKEN_SHA256)) as gw:
        with gw.hub.subscribe_events() as events:
            status, body = await post(gw.http, f"{gw.url}api/drives/d1/command", RUN, TOKEN)
            me = f"127.0.0.1 {client_label('page-1')}"
            assert (status, body) == (200, {"accepted": True, "client": me})
            desired = gw.hub.desired("d1")
            assert desired.run and desired.source is Source.WEB
            assert desired.client == me  # the page id itself is never published (issue 32)
            assert "page-1" not in str(gw.hub.state("d1").control_client)
            audit = [e for e in events.drain() if e.kind is EventKind.COMMAND]
        assert audit and audit[0].data["source"] == "web"
        assert f"command from web {me} accepted" in audit[0].text


async def test_the_safety_rules_apply_to_the_page_as_to_any_client() -> None:
    async with small_gateway(web_section(commands=True, token_sha256=TOKEN_SHA256)) as gw:
        url = f"{gw.url}api/drives/d1/command"
        status, body = await post(gw.http, url, {"run": True, "fault_reset": True}, TOKEN)
        assert status == 409 and "fault reset" in body["error"]
        status, body = await post(gw.http, url, {"run": "yes"}, TOKEN)
        assert status == 400 and "true or false" in body["error"]
        async with gw.http.post(
            url, data=b"{" * 10, headers={"Authorization": f"Bearer {TOKEN}"}
        ) as r:
            assert r.status == 400
        async with gw.http.post(
            url, data=b" " * 5000, headers={"Authorization": f"Bearer {TOKEN}"}
        ) as r:
            assert r.status in (400, 413)
        status, _ = await post(gw.http, f"{gw.url}api/drives/nope/command", RUN, TOKEN)
        assert status == 404
        assert not gw.hub.desired("d1").run


async def test_requests_from_outside_web_allow_get_no_answer() -> None:
    section = web_section(allow=(ipaddress.ip_network("10.0.0.0/8"),))
    async with small_gateway(section) as gw:
        for path in ("", "app.js", "metrics", "api/health", "api/drives", "ws"):
            with pytest.raises(aiohttp.ClientConnectionError):
                async with gw.http.get(f"{gw.url}{path}"):
                    pass
        # aiohttp's client tries a GET again once on a fresh connection
        assert gw.web.counters.connections["refused"] >= 6
        assert gw.web.counters.connections["accepted"] == 0


def test_allow_matches_addresses_and_mapped_ipv4() -> None:
    nets = (ipaddress.ip_network("127.0.0.0/8"), ipaddress.ip_network("::1/128"))
    assert allowed("127.0.0.1", nets) and allowed("::1", nets)
    assert allowed("::ffff:127.0.0.1", nets)
    assert not allowed("10.1.2.3", nets) and not allowed(None, nets)
    assert not allowed("not an address", nets)


async def test_every_answer_carries_the_security_headers() -> None:
    async with small_gateway(web_section()) as gw:
        for path in ("", "app.js", "api/drives", "metrics"):
            async with gw.http.get(f"{gw.url}{path}") as r:
                assert r.status == 200, path
                csp = r.headers["Content-Security-Policy"]
                assert "script-src 'self'" in csp and "default-src 'none'" in csp
                assert r.headers["X-Content-Type-Options"] == "nosniff"


async def test_the_feed_is_refused_to_a_page_of_another_site() -> None:
    async with small_gateway(web_section()) as gw:
        host = gw.url.removeprefix("http://").rstrip("/")
        with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
            await gw.http.ws_connect(f"{gw.url}ws", origin="http://evil.example")
        assert refused.value.status == 403
        assert gw.web.counters.refused["origin"] == 1
        async with gw.http.ws_connect(f"{gw.url}ws", origin=f"http://{host}") as ws:
            first = await ws.receive_json(timeout=10)
            assert first["type"] == "snapshot" and [d["id"] for d in first["drives"]] == [
                "d1",
                "d2",
            ]


async def test_a_command_that_names_a_key_twice_is_refused() -> None:
    """Issue 32 item 10: {"run": false, "run": true} was taken as a run; a proxy or a
    reviewer reading the first key sees a stop."""
    async with small_gateway(web_section(commands=True, token_sha256=TOKEN_SHA256)) as gw:
        url = f"{gw.url}api/drives/d1/command"
        headers = {"Authorization": f"Bearer {TOKEN}", "X-Page-Id": "page-1"}
        async with gw.http.post(url, data=b'{"run": false, "run": true}', headers=headers) as r:
            body = await r.json()
            assert r.status == 400
            assert "'run' is given twice" in body["error"]
        assert not gw.hub.desired("d1").run
