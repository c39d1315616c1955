"""The Modbus TCP server's listening sockets and its accept loop.

The server listens on sockets of its own, read by ``loop.add_reader``, instead of
``loop.create_server``, for two reasons:

- admission before anything is made for a connection: each accepted socket is handed
  to the server's callback as it is (no protocol, no transport yet), so a peer outside
  ``modbus.allow`` or over a connection limit costs one ``accept`` and one ``close``;
- an accept that fails does not flood the log: asyncio's accept loop reports each
  failure for lack of descriptors (EMFILE, ENFILE) or memory (ENOBUFS, ENOMEM) with a
  traceback through the loop's exception handler, and retries within the same
  readiness up to its backlog, so a process out of descriptors logged about a hundred
  tracebacks per second per listening socket. Here a failed accept pauses this socket
  for :data:`ACCEPT_RETRY_DELAY`, and the server's ``failed`` callback counts it and
  logs at most one line per interval; the connections already open are served all the
  while (they need no new descriptor).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Callable, Sequence
from typing import Any

LISTEN_BACKLOG = 100  # connections the kernel holds before they are accepted (as asyncio's)
ACCEPT_BATCH = 64  # connections accepted per readiness before the loop's other work
ACCEPT_RETRY_DELAY = 0.1  # s a listening socket rests after a failed accept

Accepted = Callable[[socket.socket, str], None]
"""The server's callback for an accepted socket and its peer address; it owns the socket."""
Failed = Callable[[OSError], None]
"""The server's callback for an accept that failed (the socket rests, then retries)."""


async def open_listening_sockets(
    host: str, port: int, backlog: int = LISTEN_BACKLOG
) -> list[socket.socket]:
    """Non-blocking sockets listening on every address ``host`` resolves to (all
    interfaces when empty), as ``loop.create_server`` would open them: SO_REUSEADDR, and
    an IPv6 socket for IPv6 only. Raises the OSError of the first that fails."""
    infos = await _addresses(host, port)
    opened: list[socket.socket] = []
    try:
        for family, kind, proto, _, address in dict.fromkeys(infos):
            sock = socket.socket(family, kind, proto)
            opened.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            sock.bind(address)
            sock.listen(backlog)
            sock.setblocking(False)
    except BaseException:
        for sock in opened:
            sock.close()
        raise
    return opened


async def _addresses(host: str, port: int) -> list[Any]:
    """``getaddrinfo`` for listening: an address given as digits (or none, all
    interfaces) at once, a name in the loop's executor (it may ask DNS)."""
    kind, passive = socket.SOCK_STREAM, socket.AI_PASSIVE
    try:
        return socket.getaddrinfo(
            host or None, port, type=kind, flags=passive | socket.AI_NUMERICHOST
        )
    except socket.gaierror:
        pass
    loop = asyncio.get_running_loop()
    return await loop.getaddrinfo(host, port, type=kind, flags=passive)


def peer_host(address: Any) -> str:
    """The host part of an accepted socket's peer address ("" if it has none)."""
    if isinstance(address, tuple) and address:
        return str(address[0])
    return ""


class Listener:
    """Accepts on ``sockets`` and hands each connection to ``accepted`` (see the module
    docstring); what the server holds as its listening transport."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        sockets: Sequence[socket.socket],
        accepted: Accepted,
        failed: Failed,
        retry_delay: float = ACCEPT_RETRY_DELAY,
    ) -> None:
        self.loop = loop
        self.sockets = tuple(sockets)
        self.retry_delay = retry_delay
        self._accepted = accepted
        self._failed = failed
        self._resting: dict[int, asyncio.TimerHandle] = {}
        self._closed = False

    def start(self) -> None:
        """Accept from now on."""
        for sock in self.sockets:
            self._watch(sock)

    def is_closing(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop accepting and close the listening sockets (not the accepted ones)."""
        if self._closed:
            return
        self._closed = True
        for timer in self._resting.values():
            timer.cancel()
        self._resting.clear()
        for sock in self.sockets:
            with contextlib.suppress(ValueError, OSError):
                self.loop.remove_reader(sock.fileno())
            sock.close()

    def _watch(self, sock: socket.socket) -> None:
        self._resting.pop(sock.fileno(), None)
        if not self._closed:
            self.loop.add_reader(sock.fileno(), self._accept, sock)

    def _rest(self, sock: socket.socket) -> None:
        fd = sock.fileno()
        self.loop.remove_reader(fd)
        self._resting[fd] = self.loop.call_later(self.retry_delay, self._watch, sock)

    def _accept(self, sock: socket.socket) -> None:
        """Accept what is waiting, at most :data:`ACCEPT_BATCH`; on a failure rest."""
        for _ in range(ACCEPT_BATCH):
            try:
                conn, address = sock.accept()
            except (BlockingIOError, InterruptedError):
                return  # nothing more is waiting
            except ConnectionAbortedError:
                continue  # gone before it was accepted
            except OSError as exc:
                # EMFILE and the like: the socket stays readable, so it would spin
                self._rest(sock)
                self._failed(exc)
                return
            try:
                self._accepted(conn, peer_host(address))
            except BaseException:
                conn.close()
                raise
