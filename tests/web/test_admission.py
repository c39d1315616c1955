"""What the web front end admits: the allow-list at accept, the connection and page caps,
the header and body deadlines, the send budget of a page, one ``/metrics`` render per
``web.metrics_max_age``, and the limit on wrong tokens. Every client runs on 127.0.0.x
(several loopback addresses stand for several clients) and every load is bounded in count.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import logging
import socket
from collections.abc import AsyncIterator, Callable

import aiohttp
import pytest

from gateway.web import admission, frontend
from gateway.web.tokens import TokenFailures
from gateway.webconfig import WebLimits
from tests.web.harness import TIMEOUT, TOKEN, TOKEN_SHA256, Small, small_gateway, web_section

HEALTH = b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
FOREVER = 3600.0  # s: a deadline the test never reaches (the behaviour under test is another)


async def until(predicate: Callable[[], bool]) -> None:
    """Wait for ``predicate`` to hold (the front end runs on this loop)."""
    async with asyncio.timeout(TIMEOUT):
        while not predicate():  # noqa: ASYNC110 - a counter of the front end has no event
            await asyncio.sleep(0.01)


@contextlib.asynccontextmanager
async def connection(
    gw: Small, source: str = "127.0.0.1"
) -> AsyncIterator[tuple[asyncio.StreamReader, asyncio.StreamWriter]]:
    """A raw TCP connection to the front end from ``source``."""
    assert gw.web.address is not None
    host, port = gw.web.address
    reader, writer = await asyncio.open_connection(host, port, local_addr=(source, 0))
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def answer(reader: asyncio.StreamReader) -> bytes:
    """Everything the server sends until it closes the connection (b"": nothing)."""
    try:
        return await asyncio.wait_for(reader.read(), TIMEOUT)
    except ConnectionResetError:
        return b""


def session_from(source: str) -> aiohttp.ClientSession:
    return aiohttp.ClientSession(
        connector=aiohttp.TCPConnector(local_addr=(source, 0)),
        timeout=aiohttp.ClientTimeout(total=TIMEOUT),
    )


# ---------------------------------------------------------------- at accept


async def test_a_connection_from_outside_web_allow_is_closed_at_accept_unread() -> None:
    section = web_section(
        allow=(ipaddress.ip_network("127.0.0.1/32"),), limits=WebLimits(header_timeout=FOREVER)
    )
    async with small_gateway(section) as gw:
        async with connection(gw, "127.0.0.2") as (reader, _):
            # nothing sent: only a refusal at accept closes it before the test's bound
            assert await answer(reader) == b""
        counters = gw.web.counters
        assert counters.connections["refused"] == 1 and counters.connections["accepted"] == 0
        async with connection(gw, "127.0.0.1") as (reader, writer):
            writer.write(HEALTH)
            assert (await answer(reader)).startswith(b"HTTP/1.1 200")
        assert counters.connections["accepted"] == 1


async def test_connections_are_capped_in_all_and_per_address() -> None:
    limits = WebLimits(max_connections=3, max_connections_per_peer=2, header_timeout=FOREVER)
    async with small_gateway(web_section(limits=limits)) as gw, contextlib.AsyncExitStack() as held:
        counters = gw.web.counters
        for source in ("127.0.0.1", "127.0.0.1"):
            await held.enter_async_context(connection(gw, source))
        await until(lambda: counters.connections_open == 2)
        async with connection(gw, "127.0.0.1") as (reader, _):
            assert await answer(reader) == b""
        assert counters.connections["over_peer_limit"] == 1

        await held.enter_async_context(connection(gw, "127.0.0.2"))
        await until(lambda: counters.connections_open == 3)
        async with connection(gw, "127.0.0.3") as (reader, _):
            assert await answer(reader) == b""
        assert counters.connections["over_limit"] == 1

        await held.aclose()  # the places are free again
        await until(lambda: counters.connections_open == 0)
        async with connection(gw, "127.0.0.3") as (reader, writer):
            writer.write(HEALTH)
            assert (await answer(reader)).startswith(b"HTTP/1.1 200")
        counted = gw.web.counted()
        assert (counted.connections_accepted, counted.connections_over_limit) == (4, 2)


# ---------------------------------------------------------------- deadlines


async def test_a_request_head_sent_a_byte_at_a_time_is_cut_at_the_header_timeout() -> None:
    async with small_gateway(web_section(limits=WebLimits(header_timeout=0.5))) as gw:
        counters = gw.web.counters
        async with connection(gw) as (reader, writer):
            writer.write(b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            heard = asyncio.create_task(answer(reader))
            for byte in b"X-Slow: " + b"a" * 200:  # at most 208 bytes, 0.05 s apart
                if heard.done():
                    break
                with contextlib.suppress(ConnectionError):
                    writer.write(bytes([byte]))
                await asyncio.sleep(0.05)
            assert await heard == b""  # closed with no answer
        assert counters.timeouts["header"] == 1

        async with connection(gw) as (reader, _):  # says nothing: closed as idle, uncounted
            assert await answer(reader) == b""
        assert counters.timeouts["header"] == 1

        async with gw.http.get(f"{gw.url}api/health") as r:  # a client that asks is served
            assert r.status == 200


async def test_a_command_body_slower_than_the_body_timeout_gets_408() -> None:
    section = web_section(
        commands=True, token_sha256=TOKEN_SHA256, limits=WebLimits(body_timeout=0.5)
    )
    async with small_gateway(section) as gw, connection(gw) as (reader, writer):
        writer.write(
            b"POST /api/drives/d1/command HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            b"Authorization: Bearer " + TOKEN.encode() + b"\r\n"
            b"Content-Type: application/json\r\nContent-Length: 200\r\n\r\n{"
        )
        heard = asyncio.create_task(answer(reader))
        # never the whole body: a byte every 0.05 s while the body timeout runs, then
        # nothing (a byte written after the 408 and its close, still unread by the server,
        # makes its kernel reset the connection, and a reset can drop the 408 before the
        # client reads it: on a loaded machine this loop can lag the server's close)
        for _ in range(8):
            if heard.done():
                break
            with contextlib.suppress(ConnectionError):
                writer.write(b" ")
            await asyncio.sleep(0.05)
        assert (await heard).startswith(b"HTTP/1.1 408")
        assert gw.web.counters.timeouts["body"] == 1
        assert not gw.hub.desired("d1").run


async def test_a_client_that_never_reads_its_answer_is_cut(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(admission, "ANSWER_TIMEOUT", 0.5)
    async with small_gateway(web_section(limits=WebLimits(body_timeout=0.5))) as gw:
        counters = gw.web.counters
        gw.web.static["/"] = (b"x" * 16_000_000, "text/html")  # beyond what the kernel holds
        sock = await raw_socket(gw, "127.0.0.1")
        try:
            await asyncio.get_running_loop().sock_sendall(
                sock, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
            )
            await until(lambda: counters.timeouts["answer"] == 1)
            await until(lambda: counters.connections_open == 0)  # its place is free
        finally:
            sock.close()
        async with gw.http.get(f"{gw.url}api/health") as r:
            assert r.status == 200


# ---------------------------------------------------------------- pages


async def test_pages_are_capped_in_all_and_per_address() -> None:
    limits = WebLimits(max_pages=2, max_pages_per_peer=1)
    async with (
        small_gateway(web_section(limits=limits)) as gw,
        contextlib.AsyncExitStack() as stack,
    ):
        counters = gw.web.counters
        sessions = {
            source: await stack.enter_async_context(session_from(source))
            for source in ("127.0.0.1", "127.0.0.2", "127.0.0.3")
        }
        first = await stack.enter_async_context(sessions["127.0.0.1"].ws_connect(f"{gw.url}ws"))
        with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
            await sessions["127.0.0.1"].ws_connect(f"{gw.url}ws")
        assert refused.value.status == 503 and counters.refused["pages_per_peer"] == 1
        await stack.enter_async_context(sessions["127.0.0.2"].ws_connect(f"{gw.url}ws"))
        with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
            await sessions["127.0.0.3"].ws_connect(f"{gw.url}ws")
        assert refused.value.status == 503 and counters.refused["pages"] == 1
        assert counters.clients_open == 2

        await first.close()  # a page closed frees its place
        await until(lambda: counters.clients_open == 1)
        async with sessions["127.0.0.3"].ws_connect(f"{gw.url}ws") as ws:
            assert (await ws.receive_json(timeout=TIMEOUT))["type"] == "snapshot"


async def raw_socket(gw: Small, source: str) -> socket.socket:
    """A connection from ``source`` with a small receive buffer, for a client that stops
    reading."""
    assert gw.web.address is not None
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.bind((source, 0))
    sock.setblocking(False)
    await asyncio.get_running_loop().sock_connect(sock, gw.web.address)
    return sock


async def silent_page(gw: Small, source: str = "127.0.0.1") -> socket.socket:
    """A page that opens the feed and then never reads."""
    assert gw.web.address is not None
    host, port = gw.web.address
    loop = asyncio.get_running_loop()
    sock = await raw_socket(gw, source)
    await loop.sock_sendall(
        sock,
        f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
        "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
        "Sec-WebSocket-Version: 13\r\n\r\n".encode(),
    )
    head = b""
    async with asyncio.timeout(TIMEOUT):
        while b"\r\n\r\n" not in head:
            head += await loop.sock_recv(sock, 1)
    assert head.startswith(b"HTTP/1.1 101"), head
    return sock


async def test_a_page_that_never_reads_is_dropped_over_its_budget_and_the_others_go_on() -> None:
    drives = tuple(f"d{i}" for i in range(60))  # about 48 kB per update of every drive
    section = web_section(limits=WebLimits(page_send_budget_kib=64))
    async with small_gateway(section, drives=drives) as gw:
        counters = gw.web.counters
        reading = await gw.http.ws_connect(f"{gw.url}ws", max_msg_size=0)
        texts: list[str] = []

        async def read() -> None:
            async for msg in reading:
                texts.append(msg.data)

        reader = asyncio.create_task(read())
        sock = await silent_page(gw)
        try:
            await until(lambda: counters.clients_open == 2)
            for i in range(400):  # at most about 19 MB: beyond what the kernel holds
                if counters.clients_over_budget:
                    break
                for drive in drives:
                    gw.hub.update(drive, speed_rpm=float(i))
                gw.web.feed.step()
                await asyncio.sleep(0.005)
            assert counters.clients_over_budget == 1
            await until(lambda: counters.clients_open == 1)
            assert gw.web.feed.counters.clients_stuck == 0  # the budget, not the send timeout

            seen = len(texts)
            gw.hub.update("d0", speed_rpm=-1.0)

            def fresh() -> bool:
                for text in texts[seen:]:
                    rows = json.loads(text).get("drives", [])
                    if any(r["id"] == "d0" and r["speed_rpm"] == -1.0 for r in rows):
                        return True
                return False

            await until(fresh)
            assert not reading.closed
        finally:
            sock.close()
            await reading.close()
            await reader


async def test_a_silent_page_closed_by_its_unanswered_ping_frees_its_connection(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(frontend, "WS_HEARTBEAT", 1.0)
    drives = tuple(f"d{i}" for i in range(60))
    # neither the budget nor the connection's idle deadline frees it here
    limits = WebLimits(page_send_budget_kib=65536, header_timeout=FOREVER)
    async with small_gateway(web_section(limits=limits), drives=drives) as gw:
        counters = gw.web.counters
        reading = await gw.http.ws_connect(f"{gw.url}ws", max_msg_size=0)

        async def read() -> None:
            async for _ in reading:  # it answers the pings as it reads
                pass

        reader = asyncio.create_task(read())
        sock = await silent_page(gw, "127.0.0.2")
        try:
            await until(lambda: counters.clients_open == 2)
            (silent,) = [p for p in gw.web._pages if p.peer == "127.0.0.2"]
            for i in range(600):  # at most about 29 MB, far beyond what the kernel holds
                if silent not in gw.web._pages:  # its ping went unanswered
                    break
                for drive in drives:
                    gw.hub.update(drive, speed_rpm=float(i))
                gw.web.feed.step()
                await asyncio.sleep(0.005)
            # its close may still be under way (a loaded machine: megabytes to drop)
            await until(lambda: silent not in gw.web._pages and counters.clients_open == 1)
            await until(lambda: counters.connections_open == 1)  # its connection is gone too
            assert counters.clients_over_budget == 0
        finally:
            sock.close()
            await reading.close()
            await reader


async def test_pages_opening_together_share_one_snapshot(monkeypatch: pytest.MonkeyPatch) -> None:
    async with small_gateway(web_section()) as gw:
        feed = gw.web.feed
        built: list[str] = []
        build = feed._build_snapshot

        def counted() -> str:
            built.append(text := build())
            return text

        monkeypatch.setattr(feed, "_build_snapshot", counted)
        feed.step()
        texts = {feed.snapshot() for _ in range(10)}
        assert len(built) == 1 and texts == {built[0]}
        gw.hub.update("d1", speed_rpm=5.0)
        feed.step()
        assert json.loads(feed.snapshot())["drives"][0]["speed_rpm"] == 5.0
        assert len(built) == 2


# ---------------------------------------------------------------- /metrics


async def test_scrapes_within_the_max_age_share_one_render() -> None:
    async with small_gateway(web_section()) as gw:
        now = [1000.0]
        gw.web.metrics.clock = lambda: now[0]
        counters = gw.web.counters

        async def scrape() -> bytes:
            async with gw.http.get(f"{gw.url}metrics") as r:
                assert r.status == 200
                return await r.read()

        bodies = set(await asyncio.gather(*(scrape() for _ in range(20))))
        assert counters.metrics_renders == 1 and len(bodies) == 1
        assert b"drive_gateway_web_metrics_renders_total 1.0" in bodies.pop()
        now[0] += 0.49
        await scrape()
        assert counters.metrics_renders == 1
        now[0] += 0.01  # 0.5 s after the render
        assert b"drive_gateway_web_metrics_renders_total 2.0" in await scrape()
        assert counters.metrics_renders == 2


# ---------------------------------------------------------------- tokens


async def test_token_guessing_gets_429_unchecked_after_the_limit(
    caplog: pytest.LogCaptureFixture,
) -> None:
    section = web_section(
        commands=True,
        token_sha256=TOKEN_SHA256,
        limits=WebLimits(token_failures=3, token_window=FOREVER),
    )
    async with small_gateway(section) as gw, session_from("127.0.0.2") as other:
        url = f"{gw.url}api/drives/d1/command"
        counters = gw.web.counters

        async def post(http: aiohttp.ClientSession, token: str) -> tuple[int, dict[str, str]]:
            headers = {"Authorization": f"Bearer {token}"}
            async with http.post(url, json={"run": True}, headers=headers) as r:
                return r.status, dict(r.headers)

        with caplog.at_level(logging.INFO, logger="gateway.web"):
            for guess in range(3):
                assert (await post(gw.http, f"guess {guess}"))[0] == 401
            for guess in range(20):
                status, headers = await post(gw.http, f"guess {guess}")
                assert status == 429 and int(headers["Retry-After"]) > 0
            status, _ = await post(gw.http, TOKEN)  # even the right one: not checked
            assert status == 429 and not gw.hub.desired("d1").run
            assert (await post(other, TOKEN))[0] == 200  # another address is not held
        assert counters.refused["token"] == 3 and counters.refused["token_limit"] == 21
        lines = [r.getMessage() for r in caplog.records if r.name == "gateway.web"]
        assert len([x for x in lines if "(401)" in x]) == 1  # one line per interval
        assert len([x for x in lines if "(429)" in x]) == 1


def test_wrong_tokens_are_held_to_the_limit_in_any_window() -> None:
    failures = TokenFailures(failures=3, window=60.0, max_peers=2)
    for t in (0.0, 10.0, 20.0):
        assert failures.wait("a", t) == 0.0
        failures.failed("a", t)
    assert failures.wait("a", 30.0) == 30.0  # the first of the three ages out at 60 s
    assert failures.wait("a", 60.0) == 0.0
    failures.failed("a", 60.0)  # one more try, and it is held again until 70 s
    assert failures.wait("a", 61.0) == 9.0
    failures.succeeded("a")
    assert failures.wait("a", 61.0) == 0.0
    for peer in ("b", "c", "d"):
        failures.failed(peer, 0.0)
    assert len(failures) == 2  # bounded: the oldest address is forgotten


# ---------------------------------------------------------------- request rate


async def test_an_address_over_its_request_rate_is_read_no_faster_than_the_rate() -> None:
    """A client asking flat out is answered (never refused: a refusal costs as much as an
    answer), but its connection is not read while it is over ``web.request_rate``; another
    address is not held back."""
    section = web_section(limits=WebLimits(request_rate=20.0, request_burst=5))
    async with small_gateway(section) as gw:
        async with session_from("127.0.0.1") as fast:
            statuses = []
            for _ in range(15):
                async with fast.get(f"{gw.url}api/health") as r:
                    statuses.append(r.status)
        assert statuses == [200] * 15
        throttled = gw.web.counters.throttled
        assert throttled >= 15 - 5 - 1  # the burst, and one the rate refilled at most
        async with session_from("127.0.0.2") as other:
            for _ in range(3):
                async with other.get(f"{gw.url}api/health") as r:
                    assert r.status == 200
        assert gw.web.counters.throttled == throttled


def test_the_request_rate_refills_with_time() -> None:
    from gateway.web.rate import RequestRate

    rate = RequestRate(rate=10.0, burst=2)
    assert [rate.take("a", 0.0) for _ in range(2)] == [0.0, 0.0]
    assert rate.take("a", 0.0) == pytest.approx(0.1)  # one over: 0.1 s unread
    assert rate.wait("b", 0.0) == 0.0  # another address has its own
    assert rate.take("a", 0.2) == 0.0  # 2 tokens back at 10/s, one owed
    assert rate.wait("a", 0.2) == 0.0
