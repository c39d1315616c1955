"""The loads benchmark's network loads and its Modbus probe, each in a process of its own.

``python -m bench.loads.clients KIND --port P --seconds S [options]``, KIND one of:

- ``pages``: ``--count`` WebSocket pages on ``/ws``, ``--quiet`` of them (spread among the
  others) never reading (a raw socket with a small receive buffer that reads the
  handshake's answer, then stops reading); the others read every message. Opened
  ``--in-flight`` at a time;
- ``scrape``: ``/metrics`` fetched by ``--workers`` clients, each again as soon as it has
  its answer;
- ``slow``: ``--count`` connections that send a request line, then one header byte every
  ``--every`` seconds, never finishing the request;
- ``tokens``: ``POST /api/drives/<--drive>/command`` with a wrong bearer token, one
  connection, again as soon as each answer is in;
- ``spin``: a busy loop (a CPU-bound process);
- ``probe``: a new Modbus TCP client every ``--every`` seconds (connect, read two holding
  registers of ``--unit``, close), each probe's start (``time.monotonic``, the same clock
  in every process) and its time to the answer printed as a JSON line.

The connections of ``pages`` and ``slow`` come from ``--peers`` loopback addresses
(127.0.0.2 and up), so that a limit per client address alone does not turn them away.
Everything goes to 127.0.0.1 only. Every kind prints ``{"ready": ...}`` once its load is
up, and (but ``spin`` and ``probe``) ``{"result": {...}}`` when it ends: after
``--seconds`` at most, or at SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import json
import os
import resource
import signal
import socket
import struct
import time
from collections import Counter
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

HOST = "127.0.0.1"
READY_BOUND = 30.0  # s a kind takes at most to bring its load up before it says ready
CONNECT_TIMEOUT = 10.0  # s for a connection or a handshake
PROBE_TIMEOUT = 5.0  # s a Modbus probe waits for its answer
QUIET_RCVBUF = 4096  # bytes: the receive buffer of a page that never reads


def say(doc: dict[str, Any]) -> None:
    print(json.dumps(doc), flush=True)


def raise_nofile() -> None:
    """The soft descriptor limit up to the hard one (a thousand sockets and more)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))


def peer(i: int, peers: int) -> str:
    """The loopback source address of connection ``i``."""
    return f"127.0.0.{2 + i % peers}" if peers > 1 else HOST


@dataclass
class Tally:
    """What a load saw, printed as its result."""

    attempted: int = 0
    opened: int = 0
    open_now: int = 0
    failed: int = 0
    closed_by_gateway: int = 0
    answers: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)
    messages: int = 0
    requests: int = 0
    quiet_opened: int = 0
    open_at_stop: int = 0  # connections open when the stop came
    ready_at: float | None = None

    def result(self) -> dict[str, Any]:
        doc: dict[str, Any] = {
            k: v for k, v in vars(self).items() if k not in ("answers", "errors", "ready_at")
        }
        doc["answers"] = dict(self.answers)
        doc["errors"] = dict(self.errors)
        if self.ready_at is not None:
            span = max(time.monotonic() - self.ready_at, 1e-9)
            doc["requests_per_s_since_ready"] = round(self.requests / span, 2)
        return doc


class Run:
    """One asyncio kind: its stop (SIGTERM or ``--seconds``), its readiness, its tally."""

    def __init__(self, seconds: float, expected: int = 0) -> None:
        self.stop = asyncio.Event()
        self.ready = asyncio.Event()
        self.tally = Tally()
        self.seconds = seconds
        self.expected = expected  # connections to try before it is ready (0: not counted)
        self.tasks: list[asyncio.Task[None]] = []

    def tried(self) -> None:
        """One more connection has its outcome (open, refused or failed)."""
        self.tally.attempted += 1
        if self.tally.attempted >= self.expected:
            self.ready.set()

    def spawn(self, coro: Awaitable[None]) -> None:
        self.tasks.append(asyncio.ensure_future(coro))

    def _stopping(self) -> None:
        if not self.stop.is_set():
            self.tally.open_at_stop = self.tally.open_now
            self.stop.set()

    async def serve(self) -> dict[str, Any]:
        """Until the stop: say ready once up (bounded), then end every task."""
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGTERM, self._stopping)
        deadline = loop.time() + self.seconds
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.ready.wait(), min(READY_BOUND, self.seconds))
        self.tally.ready_at = time.monotonic()
        self.tally.requests = 0
        say({"ready": self.ready.is_set(), "open": self.tally.open_now})
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.stop.wait(), max(0.0, deadline - loop.time()))
        self._stopping()
        result = self.tally.result()
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        return result


def _error(tally: Tally, exc: BaseException) -> None:
    tally.failed += 1
    tally.errors[type(exc).__name__] += 1


# ---------------------------------------------------------------- pages


def ws_handshake(port: int) -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (
        f"GET /ws HTTP/1.1\r\nHost: {HOST}:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
    ).encode()


async def _connect(
    address: str, port: int, rcvbuf: int | None = None
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """A connection to the gateway from ``address``, within CONNECT_TIMEOUT."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        if rcvbuf is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        sock.bind((address, 0))
        sock.setblocking(False)
        loop = asyncio.get_running_loop()
        await asyncio.wait_for(loop.sock_connect(sock, (HOST, port)), CONNECT_TIMEOUT)
        return await asyncio.open_connection(sock=sock)
    except BaseException:
        sock.close()
        raise


async def _quiet_page(run: Run, port: int, address: str, gate: asyncio.Semaphore) -> None:
    """A page that reads the handshake's answer, then nothing."""
    tally = run.tally
    async with gate:
        try:
            reader, writer = await _connect(address, port, QUIET_RCVBUF)
            writer.write(ws_handshake(port))
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), CONNECT_TIMEOUT)
        except (OSError, TimeoutError, asyncio.IncompleteReadError) as exc:
            _error(tally, exc)
            return
        finally:
            run.tried()
    status = head.split(b" ", 2)[1].decode(errors="replace")
    tally.answers[status] += 1
    try:
        if status == "101":
            tally.opened += 1
            tally.quiet_opened += 1
            tally.open_now += 1
            transport: Any = writer.transport
            transport.pause_reading()
            await run.stop.wait()
            tally.open_now -= 1
    finally:
        writer.close()


async def _reading_page(run: Run, url: str, session: Any, gate: asyncio.Semaphore) -> None:
    """A page that reads every message until the gateway closes it or the run ends."""
    import aiohttp

    tally = run.tally
    async with gate:
        try:
            ws = await session.ws_connect(url, timeout=aiohttp.ClientWSTimeout(ws_close=2.0))
        except aiohttp.WSServerHandshakeError as exc:
            tally.answers[str(exc.status)] += 1
            return
        except (aiohttp.ClientError, OSError, TimeoutError) as exc:
            _error(tally, exc)
            return
        finally:
            run.tried()
    tally.answers["101"] += 1
    tally.opened += 1
    tally.open_now += 1
    try:
        async for msg in ws:
            if msg.type is aiohttp.WSMsgType.TEXT:
                tally.messages += 1
        tally.closed_by_gateway += 1
    finally:
        tally.open_now -= 1
        await ws.close()


async def _pages(args: argparse.Namespace) -> dict[str, Any]:
    import aiohttp

    run = Run(args.seconds, args.count)
    gate = asyncio.Semaphore(args.in_flight)
    url = f"http://{HOST}:{args.port}/ws"
    sessions = {
        address: aiohttp.ClientSession(
            connector=aiohttp.TCPConnector(local_addr=(address, 0), limit=0),
            timeout=aiohttp.ClientTimeout(total=None, connect=CONNECT_TIMEOUT),
        )
        for address in {peer(i, args.peers) for i in range(args.count)}
    }
    attempts = []
    spacing = max(1, args.count // args.quiet) if args.quiet else 0
    for i in range(args.count):
        address = peer(i, args.peers)
        if spacing and i % spacing == 0 and i // spacing < args.quiet:
            attempts.append(_quiet_page(run, args.port, address, gate))
        else:
            attempts.append(_reading_page(run, url, sessions[address], gate))
    for attempt in attempts:
        run.spawn(attempt)
    try:
        return await run.serve()
    finally:
        for session in sessions.values():
            await session.close()


# ---------------------------------------------------------------- HTTP request loops


async def _request_loop(
    run: Run, request: Callable[[], Awaitable[int]], first: asyncio.Event
) -> None:
    """``request()`` again and again (its status counted) until the run ends."""
    tally = run.tally
    while True:
        try:
            status = await request()
        except Exception as exc:  # refused, reset, timed out: counted, then again
            _error(tally, exc)
            await asyncio.sleep(0.05)
            continue
        tally.answers[str(status)] += 1
        tally.requests += 1
        first.set()


async def _scrape(args: argparse.Namespace) -> dict[str, Any]:
    import aiohttp

    run = Run(args.seconds)
    url = f"http://{HOST}:{args.port}/metrics"
    timeout = aiohttp.ClientTimeout(total=CONNECT_TIMEOUT)
    async with aiohttp.ClientSession(
        connector=aiohttp.TCPConnector(limit=args.workers), timeout=timeout
    ) as session:

        async def one() -> int:
            async with session.get(url) as r:
                await r.read()
                return r.status

        for _ in range(args.workers):
            run.spawn(_request_loop(run, one, run.ready))
        return await run.serve()


async def _tokens(args: argparse.Namespace) -> dict[str, Any]:
    import aiohttp

    run = Run(args.seconds)
    url = f"http://{HOST}:{args.port}/api/drives/{args.drive}/command"
    headers = {"Authorization": f"Bearer {base64.urlsafe_b64encode(os.urandom(24)).decode()}"}
    body = {"action": "stop"}
    timeout = aiohttp.ClientTimeout(total=CONNECT_TIMEOUT)
    async with aiohttp.ClientSession(
        connector=aiohttp.TCPConnector(limit=1), timeout=timeout
    ) as session:

        async def one() -> int:
            async with session.post(url, json=body, headers=headers) as r:
                await r.read()
                return r.status

        run.spawn(_request_loop(run, one, run.ready))
        return await run.serve()


# ---------------------------------------------------------------- slow connections


async def _slow_one(
    run: Run, port: int, address: str, gate: asyncio.Semaphore, held: set[asyncio.StreamWriter]
) -> None:
    tally = run.tally
    async with gate:
        try:
            reader, writer = await _connect(address, port)
            writer.write(b"GET / HTTP/1.1\r\n")
        except (OSError, TimeoutError) as exc:
            _error(tally, exc)
            return
        finally:
            run.tried()
    tally.opened += 1
    tally.open_now += 1
    held.add(writer)
    try:
        data = await reader.read(1024)  # the gateway's answer (408...) or its close
        tally.closed_by_gateway += 1
        status = data.split(b" ", 2)[1].decode(errors="replace") if data.count(b" ") else "eof"
        tally.answers[status] += 1
    except OSError as exc:
        tally.closed_by_gateway += 1
        tally.errors[type(exc).__name__] += 1
    finally:
        held.discard(writer)
        tally.open_now -= 1
        writer.close()


async def _trickle(held: set[asyncio.StreamWriter], every: float) -> None:
    """One header byte to every open connection, every ``every`` s."""
    while True:
        await asyncio.sleep(every)
        for writer in list(held):
            with contextlib.suppress(OSError, RuntimeError):
                writer.write(b"x")


async def _slow(args: argparse.Namespace) -> dict[str, Any]:
    run = Run(args.seconds, args.count)
    gate = asyncio.Semaphore(args.in_flight)
    held: set[asyncio.StreamWriter] = set()
    for i in range(args.count):
        run.spawn(_slow_one(run, args.port, peer(i, args.peers), gate, held))
    run.spawn(_trickle(held, args.every))
    return await run.serve()


# ---------------------------------------------------------------- spin and probe


def _spin(args: argparse.Namespace) -> None:
    say({"ready": True})
    end = time.monotonic() + args.seconds
    n = 0
    while True:
        n += 1
        if n % 100_000 == 0 and time.monotonic() > end:
            return


MBAP = struct.Struct(">HHHB")  # transaction, protocol 0, length, unit


def _read_exact(sock: socket.socket, n: int, deadline: float) -> bytes:
    data = b""
    while len(data) < n:
        sock.settimeout(max(0.001, deadline - time.monotonic()))
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionError("closed by the gateway")
        data += chunk
    return data


def probe_once(port: int, unit: int, tid: int) -> float:
    """A new client: connect, read holding registers 0-1 of ``unit``, the seconds it took
    (an exception answer counts: it is an answer)."""
    began = time.monotonic()
    deadline = began + PROBE_TIMEOUT
    with socket.create_connection((HOST, port), timeout=PROBE_TIMEOUT) as sock:
        pdu = struct.pack(">BHH", 3, 0, 2)
        sock.sendall(MBAP.pack(tid, 0, len(pdu) + 1, unit) + pdu)
        _, _, length, _ = MBAP.unpack(_read_exact(sock, MBAP.size, deadline))
        _read_exact(sock, length - 1, deadline)
    return time.monotonic() - began


def _probe(args: argparse.Namespace) -> None:
    say({"ready": True})
    end = time.monotonic() + args.seconds
    tid = 0
    while (began := time.monotonic()) < end:
        tid = (tid + 1) & 0xFFFF
        try:
            say({"t": began, "s": probe_once(args.port, args.unit, tid)})
        except OSError as exc:
            say({"t": began, "s": None, "error": f"{type(exc).__name__}: {exc}"})
        time.sleep(max(0.0, began + args.every - time.monotonic()))


# ---------------------------------------------------------------- command line

ASYNC_KINDS: dict[str, Callable[[argparse.Namespace], Coroutine[Any, Any, dict[str, Any]]]] = {
    "pages": _pages,
    "scrape": _scrape,
    "slow": _slow,
    "tokens": _tokens,
}
PLAIN_KINDS: dict[str, Callable[[argparse.Namespace], None]] = {"spin": _spin, "probe": _probe}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.loads.clients")
    p.add_argument("kind", choices=[*ASYNC_KINDS, *PLAIN_KINDS])
    p.add_argument("--port", type=int, default=0, help="the gateway's web or Modbus port")
    p.add_argument("--seconds", type=float, required=True, help="the longest it runs")
    p.add_argument("--count", type=int, default=1000, help="pages or slow connections")
    p.add_argument("--quiet", type=int, default=100, help="pages that never read")
    p.add_argument("--peers", type=int, default=40, help="loopback source addresses")
    p.add_argument("--in-flight", type=int, default=100, help="connections opened at once")
    p.add_argument("--workers", type=int, default=4, help="scrapers at once")
    p.add_argument("--drive", default="cfw11", help="the drive the wrong tokens command")
    p.add_argument("--every", type=float, default=5.0, help="s between slow bytes or probes")
    p.add_argument("--unit", type=int, default=1, help="the Modbus unit probed")
    return p


def main() -> None:
    args = parser().parse_args()
    raise_nofile()
    if args.kind in PLAIN_KINDS:
        PLAIN_KINDS[args.kind](args)
        return
    say({"result": asyncio.run(ASYNC_KINDS[args.kind](args))})


if __name__ == "__main__":
    main()
