"""The host names the page answers to (``web.names``): a request whose Host names another
site (a page of that site, its name pointed at the gateway: DNS rebinding) gets 421 on
every path before any handler runs, counted and logged once per period; the feed is
refused to a page whose Origin names another site, whatever the request's Host says.
Forged headers go on raw connections (an HTTP client writes the Host of its URL).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
from collections.abc import AsyncIterator

import pytest

from gateway.web.hosts import host_admitted, name_of_host, origin_admitted
from gateway.webconfig import LOOPBACK_NAMES
from tests.web.harness import TIMEOUT, Small, small_gateway, web_section

FORGED = "evil.example"
PATHS = ("/", "/api/health", "/metrics", "/ws")
WS_HEADERS = (
    "Upgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
)
NAMES = frozenset(LOOPBACK_NAMES)


@contextlib.asynccontextmanager
async def connection(gw: Small) -> AsyncIterator[tuple[asyncio.StreamReader, asyncio.StreamWriter]]:
    assert gw.web.address is not None
    reader, writer = await asyncio.open_connection(*gw.web.address)
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


def request(path: str, host: str | None, headers: str = "", version: str = "1.1") -> bytes:
    """A GET of ``path`` giving ``host`` (None: no Host header); the feed's path asks for
    the WebSocket upgrade, every other closes after its answer."""
    lines = f"Host: {host}\r\n" if host is not None else ""
    lines += WS_HEADERS if path == "/ws" else "Connection: close\r\n"
    return f"GET {path} HTTP/{version}\r\n{lines}{headers}\r\n".encode()


async def status_of(gw: Small, data: bytes) -> tuple[int, bytes]:
    """The status of the answer to ``data``, and its head and body (a feed that opens
    stays open: its head alone)."""
    async with connection(gw) as (reader, writer):
        writer.write(data)
        async with asyncio.timeout(TIMEOUT):
            head = await reader.readuntil(b"\r\n\r\n")
            length = re.search(rb"\r\nContent-Length: (\d+)\r\n", head, re.IGNORECASE)
            body = await reader.readexactly(int(length.group(1))) if length else b""
    return int(head.split(b" ", 2)[1]), head + body


def port_of(gw: Small) -> int:
    assert gw.web.address is not None
    return gw.web.address[1]


# ---------------------------------------------------------------- Host


async def test_a_forged_host_gets_421_on_every_path_counted_and_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with small_gateway(web_section()) as gw:
        forged = f"{FORGED}:{port_of(gw)}"
        with caplog.at_level(logging.INFO, logger="gateway.web"):
            for path in PATHS:
                status, answer = await status_of(gw, request(path, forged))
                assert status == 421, (path, answer)
                assert b"web.names" in answer and b"snapshot" not in answer
                assert b"\r\nConnection: close\r\n" in answer
        assert gw.web.counters.refused["host"] == len(PATHS)
        assert gw.web.counted().refused["host"] == len(PATHS)
        lines = [r.getMessage() for r in caplog.records if r.name == "gateway.web"]
        refused = [line for line in lines if "(421)" in line]
        assert refused == [
            f"web request from 127.0.0.1 refused (421): its Host '{forged}' is not in web.names"
        ]
        assert gw.web.feed.counters.clients_connected == 0


async def test_the_names_of_this_machine_are_answered() -> None:
    async with small_gateway(web_section()) as gw:
        port = port_of(gw)
        for host in (
            f"127.0.0.1:{port}",
            "127.0.0.1",
            f"localhost:{port}",
            f"LocalHost.:{port}",
            f"[::1]:{port}",
            "[0:0::1]",
        ):
            status, answer = await status_of(gw, request("/api/health", host))
            assert status == 200, (host, answer)
        async with gw.http.get(gw.url) as r:  # what a browser sends for http://127.0.0.1:PORT/
            assert r.status == 200
        assert gw.web.counters.refused["host"] == 0


async def test_a_site_answers_to_the_names_it_lists_and_no_other() -> None:
    section = web_section(names=("edge-box-3.plant.example", "10.1.2.3"))
    async with small_gateway(section) as gw:
        for host in ("edge-box-3.plant.example:8080", "EDGE-BOX-3.plant.example", "10.1.2.3:80"):
            assert (await status_of(gw, request("/api/health", host)))[0] == 200, host
        for host in (f"127.0.0.1:{port_of(gw)}", "edge-box-3.plant.example.evil.example", "x"):
            assert (await status_of(gw, request("/api/health", host)))[0] == 421, host


async def test_a_request_without_a_host_is_refused_from_http_1_1_on() -> None:
    async with small_gateway(web_section()) as gw:
        status, _ = await status_of(gw, request("/api/health", None))
        assert status in (400, 421)  # aiohttp's parser refuses it first (400)
        status, _ = await status_of(gw, request("/api/health", None, version="1.0"))
        assert status == 200  # not a browser: HTTP/1.0 has no Host to forge


def test_the_host_header_is_read_as_a_name_and_a_port() -> None:
    assert name_of_host("LOCALHOST:8080") == "localhost"
    assert name_of_host("[::1]:8080") == "[::1]"
    assert name_of_host("127.0.0.1:") == "127.0.0.1"
    for bad in ("", "a b", "localhost:80:80", "[::1", "[::1]x", "localhost:8o", "a/b", "a@b"):
        assert name_of_host(bad) is None, bad
    assert not host_admitted(None, (1, 1), NAMES) and host_admitted(None, (1, 0), NAMES)
    assert not host_admitted("localhost.evil.example", (1, 1), NAMES)


# ---------------------------------------------------------------- Origin


async def test_a_page_of_another_site_gets_no_feed_even_with_the_host_forged_to_match() -> None:
    async with small_gateway(web_section()) as gw:
        port = port_of(gw)
        counters = gw.web.counters
        # the host forged to match the page's origin, as a rebound name gives it
        status, _ = await status_of(
            gw, request("/ws", f"{FORGED}:{port}", f"Origin: http://{FORGED}:{port}\r\n")
        )
        assert status == 421
        for origin in (f"http://{FORGED}:{port}", "null", f"ftp://127.0.0.1:{port}"):
            status, _ = await status_of(
                gw, request("/ws", f"127.0.0.1:{port}", f"Origin: {origin}\r\n")
            )
            assert status == 403, origin
        assert (counters.refused["host"], counters.refused["origin"]) == (1, 3)
        # the page itself, and the page through a tunnel or a proxy on a port of its own
        for origin in (f"http://127.0.0.1:{port}", "https://localhost:8443", "http://[::1]"):
            status, _ = await status_of(
                gw, request("/ws", f"127.0.0.1:{port}", f"Origin: {origin}\r\n")
            )
            assert status == 101, origin


def test_an_origin_is_compared_with_the_names_never_with_the_host() -> None:
    assert origin_admitted(None, NAMES)  # not a browser
    assert origin_admitted("http://localhost:8080", NAMES)
    assert origin_admitted("HTTPS://127.0.0.1", NAMES)
    for origin in (
        "http://evil.example:8080",
        "http://127.0.0.1.evil.example",
        "http://localhost@evil.example",
        "null",
        "localhost",
        "ws://localhost",
    ):
        assert not origin_admitted(origin, NAMES), origin
    assert origin_admitted("http://evil.example", frozenset({"evil.example"}))
