"""What aiohttp answers with an error itself: a malformed request keeps aiohttp's own 400
and writes one log line per period, without a traceback, however many come; a request
that fails in the gateway (a handler's exception) gets 500 and one line per period, the
first with its traceback. Both through the logger the front end gives aiohttp
(gateway/web/admission.py, ``RequestLog``).
"""

from __future__ import annotations

import asyncio
import logging

import pytest
from aiohttp.http_exceptions import BadHttpMessage

from gateway.web.admission import RefusalLog, RequestLog
from tests.web.harness import TIMEOUT, Small, small_gateway, web_section

MALFORMED = 100


async def exchange(gw: Small, data: bytes) -> bytes:
    """Everything the front end answers to ``data`` until it closes the connection."""
    assert gw.web.address is not None
    reader, writer = await asyncio.open_connection(*gw.web.address)
    try:
        writer.write(data)
        return await asyncio.wait_for(reader.read(), TIMEOUT)
    finally:
        writer.close()


def malformed(i: int) -> bytes:
    length = ("abc", "-1")[i % 2]
    return (
        "POST /api/drives/d1/command HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"Content-Length: {length}\r\n\r\n"
    ).encode()


def lines_of(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name.startswith(("gateway.web", "aiohttp"))]


async def test_malformed_requests_keep_their_400_and_log_one_line_without_a_traceback(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with small_gateway(web_section()) as gw:
        with caplog.at_level(logging.DEBUG, logger="gateway.web"):
            for i in range(MALFORMED):
                answer = await exchange(gw, malformed(i))
                assert answer.split(b"\r\n", 1)[0].endswith(b" 400 Bad Request"), answer
            health = await exchange(
                gw, b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
            )
            assert health.startswith(b"HTTP/1.1 200")  # the server goes on
    records = lines_of(caplog)
    assert [r.getMessage() for r in records if r.levelno >= logging.INFO] == [
        "web request from 127.0.0.1 refused (400): Invalid character in Content-Length:"
    ]
    assert not any(r.exc_info for r in caplog.records)
    assert "Traceback" not in caplog.text


async def test_a_request_that_fails_in_the_gateway_gets_500_and_one_line_with_its_traceback(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    async with small_gateway(web_section()) as gw:

        def broken() -> None:
            raise RuntimeError("the history cannot be read")

        monkeypatch.setattr(gw.web.feed.history, "all_json", broken)
        with caplog.at_level(logging.INFO, logger="gateway.web"):
            for _ in range(3):
                async with gw.http.get(f"{gw.url}api/history") as r:
                    assert r.status == 500
    records = [r for r in lines_of(caplog) if r.levelno >= logging.ERROR]
    assert [r.getMessage() for r in records] == [
        "web request from 127.0.0.1 failed in the gateway: RuntimeError: the history cannot be read"
    ]
    assert records[0].exc_info is not None and records[0].name == "gateway.web"


def test_the_repeats_of_a_period_are_one_summary_line(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    refusals = RefusalLog(clock=lambda: now[0])
    request_log = RequestLog(refusals)
    with caplog.at_level(logging.INFO, logger="gateway.web"):
        for _ in range(MALFORMED):
            try:
                raise BadHttpMessage("Invalid character in Content-Length:")
            except BadHttpMessage:
                request_log.exception("Error handling request from %s", "::ffff:10.1.2.3")
        now[0] = 10.0
        refusals.flush()
    assert [r.getMessage() for r in caplog.records] == [
        "web request from 10.1.2.3 refused (400): Invalid character in Content-Length:",
        f"web: {MALFORMED - 1} more malformed requests refused (400) since the last line",
    ]
    assert not any(r.exc_info for r in caplog.records)
