"""A TCP forwarder on 127.0.0.1 that a test can cut: every connection through it closed and
new ones refused until it is restored on the same port (a network cut between a client and
a server, both of which stay up)."""

from __future__ import annotations

import contextlib
import selectors
import socket
import threading
from types import TracebackType

from tests.support.net import free_port

CHUNK = 65536


class TcpCut:
    """``with TcpCut(upstream_port) as cut``: clients connect to ``cut.port``; ``cut.cut()``
    closes every connection and stops listening, ``cut.restore()`` listens again."""

    def __init__(self, upstream_port: int) -> None:
        self.upstream = ("127.0.0.1", upstream_port)
        self.port = free_port()
        self.accepted = 0
        self._sel = selectors.DefaultSelector()
        self._peer: dict[socket.socket, socket.socket] = {}
        self._listener: socket.socket | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tcpcut", daemon=True)

    def __enter__(self) -> TcpCut:
        self.restore()
        self._thread.start()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        self._thread.join(10)
        with self._lock:
            self._close_all()
        self._sel.close()

    # ------------------------------------------------------------------ the test's side

    def cut(self) -> None:
        with self._lock:
            self._close_all()

    def restore(self) -> None:
        with self._lock:
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(("127.0.0.1", self.port))
            listener.listen(16)
            listener.setblocking(False)
            self._listener = listener
            self._sel.register(listener, selectors.EVENT_READ)

    # ------------------------------------------------------------------ the thread

    def _close_all(self) -> None:
        if self._listener is not None:
            self._sel.unregister(self._listener)
            self._listener.close()
            self._listener = None
        for sock in list(self._peer):
            with contextlib.suppress(KeyError, ValueError):
                self._sel.unregister(sock)
            sock.close()
        self._peer.clear()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:  # held while it waits: a cut() waits for it 10 ms at most
                for key, _ in self._sel.select(timeout=0.01):
                    sock = key.fileobj
                    assert isinstance(sock, socket.socket)
                    if sock is self._listener:
                        self._accept(sock)
                    elif sock in self._peer:
                        self._pump(sock)

    def _accept(self, listener: socket.socket) -> None:
        try:
            client, _ = listener.accept()
        except OSError:
            return
        try:
            server = socket.create_connection(self.upstream, timeout=5)
        except OSError:
            client.close()
            return
        self.accepted += 1
        for sock in (client, server):
            sock.settimeout(5.0)  # a read when readable returns at once; a send may wait
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sel.register(sock, selectors.EVENT_READ)
        self._peer[client], self._peer[server] = server, client

    def _pump(self, sock: socket.socket) -> None:
        other = self._peer[sock]
        try:
            data = sock.recv(CHUNK)
            if data:
                other.sendall(data)
                return
        except OSError:  # reset, or a send that waited its timeout out
            pass
        for s in (sock, other):  # closed or failed: the pair ends
            with contextlib.suppress(KeyError, ValueError):
                self._sel.unregister(s)
            s.close()
            self._peer.pop(s, None)
