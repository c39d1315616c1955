"""The pymodbus TCP server, with what ``SimDevice`` cannot express.

The register store is pymodbus's own: one ``SimDevice`` per unit, whose
``action`` callback (run before pymodbus reads or writes the registers, able to
refuse with an exception code) does the map's work. Four things happen per
connection or per request, outside any ``SimDevice``, so they live in a
subclass of pymodbus's per-connection ``ServerRequestHandler``, returned by the
documented ``callback_new_connection`` of the server:

- admission, at accept, on the bare accepted socket (the server's own accept loop,
  :mod:`gateway.modbus.listener`): a peer outside ``modbus.allow``, a connection beyond
  ``modbus.max_connections_per_peer`` of its address or beyond ``modbus.max_connections``
  is closed before a byte is read and before a handler or transport is made for it (at
  a limit, the connection idle longest of the peer, or of all, makes room first if it
  has been idle long enough); an admitted one gets TCP keepalive, so that a client gone
  without closing (power cut) frees its place. An accept that fails (no descriptor
  left) is counted and logged once per interval, never per attempt;
- framing (``callback_data``, which replaces pymodbus's): a bad MBAP header
  closes the connection; an unknown unit gets exception 0x0B and an unserved
  function exception 1 before pymodbus decodes anything (pymodbus would answer
  an unknown unit from the unit-0 device, serve diagnostics, and answer an
  undecodable PDU with function code 0x80); a served function whose PDU does
  not decode gets exception 3; once part of a frame has arrived, the rest
  must follow within ``modbus.frame_timeout`` (a ``loop.call_later`` timer, no
  polling), else the connection is closed and counted as a bad frame;
- who is asking: the peer address is put in a context variable for the
  duration of the request, so the ``action`` can keep per-client edges;
- pipelining: a client may send requests without waiting for the replies (the
  Modbus TCP transaction id is there for it), so several may arrive in one read.
  pymodbus frames one request per read and drops a read longer than one frame;
  here every complete request is framed, queued and answered one at a time, in
  order, and reading pauses while :data:`PIPELINE_LIMIT` requests of the
  connection wait (a flood is served at the gateway's pace, never dropped).
  The handler keeps its own receive buffer: pymodbus empties ``recv_buffer``
  whenever it sends, which would throw away the start of a pipelined request
  that arrived before the reply to the one before it.

Reads of a drive's status block (function 4, or function 3 within its holding mirror)
take a short path past pymodbus (:meth:`GatewayRequestHandler._fast_read`): the reply is
built from the unit's newest encoding (the registers pymodbus's ``action`` would have
copied, byte for byte the same reply) and the replies of one read of the socket go out in
one write. Any other request, a read outside the block, or a read behind a queued request
takes pymodbus's path as before. At plant scale (ten clients polling 188 drives at 10 Hz)
pymodbus's per-request path cost about 90 % of the gateway's CPU (``make bench``,
bench_plant).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import contextvars
import errno
import ipaddress
import logging
import socket
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusIOException
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.register_message import ReadWriteMultipleRegistersRequest
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import SimDevice
from pymodbus.transaction import TransactionManager

from gateway.errors import GatewayError, StartupError
from gateway.modbus.limits import (
    OVER_LIMIT_LOG_INTERVAL,
    Admission,
    ConnectionLimits,
    PeerCounts,
    WarningRateLimit,
    admission,
)
from gateway.modbus.listener import ACCEPT_RETRY_DELAY, Listener, open_listening_sockets
from gateway.modbus.mbap import HEADER_SIZE, MbapError, parse_header
from gateway.modbus.regs import ExceptionCode

log = logging.getLogger(__name__)

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network

CURRENT_CLIENT: contextvars.ContextVar[str] = contextvars.ContextVar("modbus_client", default="")
"""The peer address of the request being served (set around each request)."""

# a read request: MBAP header, function, starting address, quantity (MB AP 6.3, 6.4)
READ_REQUEST = struct.Struct(">HHHBBHH")
READ_REPLY = struct.Struct(">HHBBB")  # its reply after the transaction id: MBAP, function, count
READ_PDU_LENGTH = 6  # the MBAP length of a read request: unit id + 5 bytes of PDU
MAX_READ_REGISTERS = 125  # MB AP 6.3, 6.4: quantity 1 to 125
READ_INPUTS, READ_HOLDINGS = 4, 3
REPLY_CACHE_LIMIT = 4096  # short-path replies kept (units x distinct reads)

REFUSED_LOG_LIMIT = 256  # distinct refused addresses logged at WARNING; later ones at DEBUG
PIPELINE_LIMIT = 64  # requests of one connection waiting to be served; more pause its reading
# TCP keepalive on every connection: a client gone without a FIN (power cut, cable pulled)
# frees its place under modbus.max_connections after about IDLE + INTERVAL * COUNT seconds
KEEPALIVE_IDLE = 60
KEEPALIVE_INTERVAL = 10
KEEPALIVE_COUNT = 3
_KEEPALIVE_OPTIONS = (
    ("TCP_KEEPIDLE", KEEPALIVE_IDLE),
    ("TCP_KEEPINTVL", KEEPALIVE_INTERVAL),
    ("TCP_KEEPCNT", KEEPALIVE_COUNT),
)


def keep_alive(sock: Any) -> None:
    """Turn TCP keepalive on for an accepted socket (the timings where the OS has them)."""
    if sock is None:
        return
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for name, value in _KEEPALIVE_OPTIONS:
            option = getattr(socket, name, None)  # Linux has all three
            if option is not None:
                sock.setsockopt(socket.IPPROTO_TCP, option, value)


class ModbusBindError(StartupError, OSError):
    """The server could not listen on ``modbus.bind``: the cause and the fix."""


_BIND_FIXES = {
    errno.EADDRINUSE: (
        "address already in use",
        "another drive-gateway instance (or another Modbus server) listens there: stop it, "
        "or choose another address with --modbus-bind HOST:PORT or [modbus] bind",
    ),
    errno.EACCES: (
        "permission denied",
        "ports below 1024 need CAP_NET_BIND_SERVICE: under systemd uncomment the unit's "
        "CapabilityBoundingSet=CAP_NET_BIND_SERVICE and AmbientCapabilities="
        "CAP_NET_BIND_SERVICE lines (config/drive-gateway.service), or use a port above "
        "1023 with --modbus-bind HOST:PORT",
    ),
    errno.EADDRNOTAVAIL: (
        "this machine has no such address",
        "choose one of its addresses (or 0.0.0.0) with --modbus-bind HOST:PORT or [modbus] bind",
    ),
}


def _drop_bind_failure(record: logging.LogRecord) -> bool:
    return not record.getMessage().startswith("Failed to start server")


def bind_error(host: str, port: int, exc: OSError | None) -> ModbusBindError:
    """The one-line reason the server cannot listen on ``host:port``, with the fix."""
    code = exc.errno if exc is not None else None
    cause, fix = _BIND_FIXES.get(
        code or 0,
        (
            (exc.strerror or str(exc)).lower() if exc is not None else "listen failed",
            "check the address with --modbus-bind HOST:PORT or [modbus] bind",
        ),
    )
    return ModbusBindError("modbus", f"cannot listen on {host}:{port}: {cause}", fix)


@dataclass
class Counters:
    """What the gateway unit reports about the server (since start)."""

    connections_accepted: int = 0
    connections_refused: int = 0
    requests: int = 0
    exceptions: int = 0
    commands_accepted: int = 0
    commands_refused: int = 0
    bad_frames: int = 0  # a bad MBAP header, or a frame not finished in time
    frame_timeouts: int = 0  # frames not finished within modbus.frame_timeout
    connections_over_limit: int = 0  # closed at accept: a connection limit was reached
    connections_over_peer_limit: int = 0  # of those: modbus.max_connections_per_peer
    accept_failures: int = 0  # accepts that failed (no descriptor or memory left)
    idle_closed: int = 0  # closed: no complete request for modbus.idle_timeout
    idle_evicted: int = 0  # the idlest closed at the limit, to make room for a new client


class AccessPolicy:
    """Which peers may connect, which units exist, which functions are served."""

    def __init__(
        self,
        allow: Sequence[IpNetwork],
        holdings: Mapping[int, frozenset[int]],
        functions: frozenset[int],
    ) -> None:
        self.allow = tuple(allow)
        self.holdings = dict(holdings)  # unit -> readable holding register addresses
        self.functions = functions

    def admits(self, host: str) -> bool:
        if not self.allow:
            return True
        try:
            ip = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return any(ip in net for net in self.allow)

    def refusal(self, unit: int, function_code: int) -> ExceptionCode | None:
        """The exception for a request the map cannot serve, or None."""
        if unit not in self.holdings:
            return ExceptionCode.GATEWAY_TARGET_FAILED
        if function_code not in self.functions:
            return ExceptionCode.ILLEGAL_FUNCTION
        return None

    def holding_read_refusal(self, unit: int, address: int, count: int) -> ExceptionCode | None:
        """Exception 2 if a holding read touches an unmapped address.

        pymodbus runs function 23 as write-then-read: its read range is checked
        first, so that a refused request has applied nothing.
        """
        readable = self.holdings.get(unit, frozenset())
        if all(a in readable for a in range(address, address + count)):
            return None
        return ExceptionCode.ILLEGAL_DATA_ADDRESS


class StatusBlock(Protocol):
    """A drive unit's status block as the map encodes it (input registers 0..n-1, also
    holding registers ``mirror`` + n), newest encoding: a new list for every encoding,
    never changed in place (:class:`FastReads` keeps replies while the list is the same)."""

    @property
    def inputs(self) -> list[int]: ...


class FastReads:
    """The units whose status-block reads take the short path, and where the mirror is.

    A reply (after its transaction id) is kept per unit and request until the unit's
    registers are replaced (every new encoding is a new list): polling clients read the
    same block again and again.
    """

    def __init__(self, blocks: Mapping[int, StatusBlock], mirror: int) -> None:
        self.blocks = blocks
        self.mirror = mirror
        self._replies: dict[tuple[int, int, int, int], tuple[list[int], bytes]] = {}

    def reply(self, unit: int, function: int, address: int, count: int) -> bytes | None:
        """The reply to a read of ``unit``'s status block after its transaction id, or None
        (no such unit, another function, or not within the block)."""
        block = self.blocks.get(unit)
        if block is None:
            return None
        registers = block.inputs
        key = (unit, function, address, count)
        cached = self._replies.get(key)
        if cached is not None and cached[0] is registers:
            return cached[1]
        if function == READ_INPUTS:
            start = address
        elif function == READ_HOLDINGS:
            start = address - self.mirror
        else:
            return None
        if start < 0 or not 1 <= count <= MAX_READ_REGISTERS or start + count > len(registers):
            return None
        body = READ_REPLY.pack(0, 3 + 2 * count, unit, function, 2 * count) + struct.pack(
            f">{count}H", *registers[start : start + count]
        )
        if len(self._replies) >= REPLY_CACHE_LIMIT:
            self._replies.clear()  # a client reading every possible range: start again
        self._replies[key] = (registers, body)
        return body


class GatewayRequestHandler(ServerRequestHandler):
    """One client connection (see the module docstring)."""

    def __init__(self, owner: GatewayServer, *args: Any) -> None:
        super().__init__(owner, *args)  # type: ignore[no-untyped-call]
        self.gateway = owner
        self.client = ""
        self._peer_open = False  # counted in the owner's peer_changed
        # requests (PDUs) and ready exception replies, in the order they came
        self._queue: collections.deque[tuple[ModbusPDU, tuple[Any, ...] | None]] = (
            collections.deque()
        )
        self._worker: asyncio.Task[None] | None = None
        self._paused = False
        self._rx = b""  # bytes of a request not complete yet (see the module docstring)
        self._out = bytearray()  # short-path replies not written yet
        self._frame_timer: asyncio.TimerHandle | None = None
        self._idle_timer: asyncio.TimerHandle | None = None
        self.last_request = self.loop.time()  # of the last complete request (or the accept)
        self._counted = False  # holds a place in the owner's per-peer count

    def admitted(self, host: str) -> None:
        """Made for an admitted connection from ``host``: it counts for the address from
        now until it is closed or lost."""
        self.client = host
        self._counted = True
        self.gateway.peers.add(host)

    def _leave(self) -> None:
        if self._counted:
            self._counted = False
            self.gateway.peers.remove(self.client)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        if self.is_closing:  # closed (server stopping) before it was connected
            transport.abort()  # type: ignore[attr-defined]
            return
        if not self.client:
            peer = transport.get_extra_info("peername")
            self.client = str(peer[0]) if peer else ""
        self.last_request = self.loop.time()
        self._peer_open = True
        self.gateway.peer_changed(self.client, True)
        self.gateway.counters.connections_accepted += 1
        super().connection_made(transport)
        self._arm_idle(self.gateway.limits.idle_timeout)

    def data_received(self, data: bytes) -> None:
        """Frame the complete requests of the stream, up to :data:`PIPELINE_LIMIT` waiting
        (pymodbus's own reader frames one per read and throws away a read longer than one
        frame); the rest stays buffered, reading paused, until the queue drains."""
        self._rx += data
        used = self.callback_data(self._rx)
        self._rx = self._rx[used:]
        self._time_frame(restart=used > 0)

    def connection_lost(self, exc: Exception | None) -> None:
        self._leave()
        if self._peer_open:
            self._peer_open = False
            self.gateway.peer_changed(self.client, False)
        super().connection_lost(exc)
        self._stop_frame_timer()
        self._queue.clear()  # nobody is left to read the replies
        if self._worker is not None:
            self._worker.cancel()

    def _arm_idle(self, delay: float) -> None:
        if self.gateway.limits.idle_timeout > 0:
            self._idle_timer = self.loop.call_later(delay, self._idle_check)

    def _idle_check(self) -> None:
        """Close the connection once no complete request came for ``modbus.idle_timeout``
        (one timer per connection, re-armed for the rest of the time, not per request)."""
        self._idle_timer = None
        if self.transport is None:
            return
        timeout = self.gateway.limits.idle_timeout
        idle = self.loop.time() - self.last_request
        if idle < timeout:
            self._arm_idle(timeout - idle)
            return
        self.gateway.counters.idle_closed += 1
        log.debug(
            "Modbus client %s: no complete request for %g s (modbus.idle_timeout); closing",
            self.client,
            timeout,
        )
        self.close()

    def idle_for(self) -> float:
        return self.loop.time() - self.last_request

    def close(self, reconnect: bool = False) -> None:
        if self._idle_timer is not None:
            self._idle_timer.cancel()
            self._idle_timer = None
        self._stop_frame_timer()
        self._rx = b""
        self._leave()
        super().close(reconnect)

    def _time_frame(self, *, restart: bool) -> None:
        """Time the frame begun in ``_rx`` from its first byte (``restart``: the bytes
        before it completed a frame). No timer while nothing is pending, or while
        reading is paused (the rest may be waiting unread in the socket)."""
        if not self._rx or self._paused or self.transport is None:
            self._stop_frame_timer()
        elif restart or self._frame_timer is None:
            self._stop_frame_timer()
            timeout = self.gateway.limits.frame_timeout
            self._frame_timer = self.loop.call_later(timeout, self._frame_timed_out)

    def _stop_frame_timer(self) -> None:
        if self._frame_timer is not None:
            self._frame_timer.cancel()
            self._frame_timer = None

    def _frame_timed_out(self) -> None:
        self._frame_timer = None
        if self.transport is None:
            return
        self.gateway.counters.bad_frames += 1
        self.gateway.counters.frame_timeouts += 1
        log.warning(
            "Modbus client %s: %d byte(s) of a frame, not the rest within"
            " modbus.frame_timeout (%g s); closing its connection",
            self.client,
            len(self._rx),
            self.gateway.limits.frame_timeout,
        )
        self.close()

    def callback_data(self, data: bytes, addr: tuple[Any, ...] | None = None) -> int:
        """Frame every complete request in ``data``, in order; returns the bytes used."""
        used = 0
        framed = 0
        # bounded: a read holding thousands of requests must not hold the event loop (and
        # the fieldbus cycles) while they are all decoded
        while used < len(data) and self.transport is not None:
            if len(self._queue) >= PIPELINE_LIMIT or framed >= PIPELINE_LIMIT:
                break
            size = self._fast_read(data, used)
            if size == 0:
                size = self._frame(data[used:], addr)
            if size == 0:
                break  # the rest of a frame is still to come
            used += size
            framed += 1
        if framed:
            self.last_request = self.loop.time()
        self._flush_out()
        if self.transport is not None and len(self._queue) >= PIPELINE_LIMIT:
            self._paused = True
            self.transport.pause_reading()  # type: ignore[attr-defined]
        elif self.transport is not None and framed >= PIPELINE_LIMIT and used < len(data):
            # a batch of short-path reads: the rest after the loop's other work
            self._paused = True
            self.transport.pause_reading()  # type: ignore[attr-defined]
            self.loop.call_soon(self._resume)
        return used

    def _fast_read(self, data: bytes, at: int) -> int:
        """Answer a status-block read at ``data[at:]`` at once (module docstring); the
        bytes used, or 0 when it is not one (pymodbus's path then frames it)."""
        fast = self.gateway.fast_reads
        if fast is None or self._queue or self._worker is not None:
            return 0
        end = at + READ_REQUEST.size
        if len(data) < end:
            return 0
        transaction, protocol, length, unit, function, address, count = READ_REQUEST.unpack_from(
            data, at
        )
        if protocol != 0 or length != READ_PDU_LENGTH:
            return 0
        body = fast.reply(unit, function, address, count)
        if body is None:
            return 0
        self.gateway.counters.requests += 1
        out = self._out
        out += transaction.to_bytes(2, "big")
        out += body
        return end - at

    def _flush_out(self) -> None:
        if self._out and self.transport is not None:
            self.transport.write(bytes(self._out))  # type: ignore[attr-defined]
        self._out.clear()

    def _frame(self, data: bytes, addr: tuple[Any, ...] | None) -> int:
        """Frame one request (replaces pymodbus's, whose error replies lose the function code)."""
        try:
            header = parse_header(data)
        except MbapError as exc:
            self.gateway.counters.bad_frames += 1
            log.warning("Modbus client %s: %s; closing its connection", self.client, exc)
            self.close()
            return len(data)
        if header is None or len(data) < header.frame_size:
            return 0  # wait for the rest of the frame
        self.gateway.counters.requests += 1
        function_code = data[HEADER_SIZE]
        refusal = self.gateway.policy.refusal(header.unit, function_code)
        if refusal is None:
            try:
                used: int = TransactionManager.callback_data(self, data, addr)
            except ModbusIOException as exc:
                refusal = ExceptionCode.ILLEGAL_DATA_VALUE  # a served function, malformed PDU
                log.debug(
                    "Modbus client %s, unit %d, function %d: exception 3, the PDU does not"
                    " decode (%s)",
                    self.client,
                    header.unit,
                    function_code,
                    exc,
                )
            else:
                pdu = self.last_pdu
                self.last_pdu = None
                if pdu is None:
                    return used
                refusal = self._pdu_refusal(pdu)
                if refusal is None:
                    self._serve(pdu, addr)
                    return used
        response = ExceptionResponse(
            function_code & 0x7F,
            ExcCodes(int(refusal)),
            device_id=header.unit,
            transaction=header.transaction,
        )
        self._serve(response, addr)
        return header.frame_size

    def _serve(self, pdu: ModbusPDU, addr: tuple[Any, ...] | None) -> None:
        """Answer a request (or send a ready exception reply) after those before it."""
        self._flush_out()  # short-path replies of the requests before it
        if isinstance(pdu, ExceptionResponse) and self._worker is None:
            self.server_send(pdu, addr)  # nothing before it: at once
            return
        self._queue.append((pdu, addr))
        if self._worker is None:
            self._worker = self.loop.create_task(self._answer_queued(), name="modbus-requests")

    async def _answer_queued(self) -> None:
        try:
            while self._queue:
                pdu, addr = self._queue.popleft()
                if isinstance(pdu, ExceptionResponse):
                    self.server_send(pdu, addr)
                else:
                    self.last_pdu, self.last_addr = pdu, addr
                    await self.handle_request()
                # a request need not suspend: let the buses and the other clients run
                # between two of a flood
                await asyncio.sleep(0)
                if self._paused and len(self._queue) < PIPELINE_LIMIT // 2:
                    self._resume()
        finally:
            self._worker = None

    def _resume(self) -> None:
        """Frame what was left buffered, then read again unless that filled the queue."""
        self._paused = False
        if self.transport is None:
            return
        self.data_received(b"")  # may pause again
        if not self._paused and self.transport is not None:
            self.transport.resume_reading()  # type: ignore[attr-defined]
            self._time_frame(restart=True)  # a frame left half read: from now

    def _pdu_refusal(self, pdu: ModbusPDU) -> ExceptionCode | None:
        if not isinstance(pdu, ReadWriteMultipleRegistersRequest):
            return None
        return self.gateway.policy.holding_read_refusal(
            pdu.dev_id, pdu.read_address, pdu.read_count
        )

    async def handle_request(self) -> None:
        token = CURRENT_CLIENT.set(self.client)
        try:
            await super().handle_request()  # type: ignore[no-untyped-call]
        finally:
            CURRENT_CLIENT.reset(token)

    def server_send(self, pdu: ModbusPDU | None, addr: tuple[Any, ...] | None) -> None:
        if isinstance(pdu, ExceptionResponse):
            self.gateway.counters.exceptions += 1
        super().server_send(pdu, addr)  # type: ignore[no-untyped-call]


_RESOURCE_REASONS = {
    errno.EMFILE: "the process has no file descriptor left (its limit: LimitNOFILE in the unit)",
    errno.ENFILE: "the system's file table is full",
    errno.ENOBUFS: "no buffer space",
    errno.ENOMEM: "no memory",
}


def accept_failure_reason(exc: OSError) -> str:
    """Why an accept failed, for the log."""
    reason = _RESOURCE_REASONS.get(exc.errno or 0)
    if reason is not None:
        return f"{reason} ({errno.errorcode[exc.errno or 0]})"
    return (exc.strerror or str(exc)).lower()


class GatewayServer(ModbusTcpServer):
    """pymodbus's TCP server with the gateway's accept loop and connection handler."""

    def __init__(
        self,
        devices: list[SimDevice],
        *,
        host: str,
        port: int,
        policy: AccessPolicy,
        counters: Counters,
        limits: ConnectionLimits,
        on_peer: Callable[[str, bool], None] | None = None,
        fast_reads: FastReads | None = None,
        on_refused: Callable[[str, str], None] | None = None,
    ) -> None:
        super().__init__(devices, address=(host, port))
        self._on_peer = on_peer
        self._on_refused = on_refused  # (the setting that refused, the peer): the audit
        self.fast_reads = fast_reads
        self.policy = policy
        self.counters = counters
        self.limits = limits
        self.peers = PeerCounts()  # admitted connections open, per address
        self._attaching: dict[asyncio.Task[None], socket.socket] = {}  # admitted, connecting
        self._refused_logged: set[str] = set()
        self._over_limit_log = WarningRateLimit(OVER_LIMIT_LOG_INTERVAL)
        self._over_peer_limit_log = WarningRateLimit(OVER_LIMIT_LOG_INTERVAL)
        self._accept_failure_log = WarningRateLimit(OVER_LIMIT_LOG_INTERVAL)
        self._failing = 0  # accepts failed since the last one that succeeded

    def callback_new_connection(self) -> GatewayRequestHandler:
        return GatewayRequestHandler(self, self.trace_packet, self.trace_pdu, self.trace_connect)

    def peer_changed(self, host: str, opened: bool) -> None:
        """A connection from ``host`` was admitted (``opened``) or is gone."""
        if self._on_peer is not None:
            self._on_peer(host, opened)

    @property
    def connections_open(self) -> int:
        return len(self.active_connections)

    # ------------------------------------------------------------ accept

    def accepted(self, conn: socket.socket, host: str) -> None:
        """The listener's callback: admit the connection or close it at once."""
        if self._failing:
            log.info(
                "Modbus server accepts connections again (%d accept(s) failed before)",
                self._failing,
            )
            self._failing = 0
        if not self.admit(host):
            conn.close()
            return
        handler = self.handle_new_connection()  # among active_connections from now
        if not isinstance(handler, GatewayRequestHandler):
            raise GatewayError(f"Modbus server: unexpected connection handler {handler!r}")
        handler.admitted(host)
        keep_alive(conn)
        task = self.loop.create_task(self._attach(handler, conn), name="modbus-accept")
        self._attaching[task] = conn
        task.add_done_callback(self._attached)

    def _attached(self, task: asyncio.Task[None]) -> None:
        self._attaching.pop(task, None)

    async def _attach(self, handler: GatewayRequestHandler, conn: socket.socket) -> None:
        """Give an admitted socket its transport (``connection_made`` follows)."""
        try:
            await self.loop.connect_accepted_socket(lambda: handler, conn)
        except (OSError, RuntimeError, ValueError) as exc:
            log.debug("Modbus client %s: connection lost while set up (%s)", handler.client, exc)
            handler.close()
            conn.close()

    def accept_failed(self, exc: OSError) -> None:
        """The listener's callback: an accept failed; counted, one WARNING per interval."""
        self.counters.accept_failures += 1
        self._failing += 1
        held = self._accept_failure_log.admit(self.loop.time())
        if held is None:
            return
        log.warning(
            "Modbus server cannot accept connections: %s; %d connection(s) open are still"
            " served, accepting again every %g s%s",
            accept_failure_reason(exc),
            self.connections_open,
            ACCEPT_RETRY_DELAY,
            f"; {held} more failed since the last warning" if held else "",
        )

    def admit(self, host: str) -> bool:
        """Whether a new connection from ``host`` may be served; a refusal is counted and
        logged. At a limit, the connection idle longest (of the peer at its own limit,
        else of all) makes room, if it has been idle ``evict_after``."""
        if not self.policy.admits(host):
            self.refused(host)
            return False
        verdict = admission(self.limits, len(self.active_connections), self.peers.of(host))
        if verdict is Admission.PEER_FULL and not self._evict_idlest(host, of_peer=True):
            self.over_peer_limit(host)
            return False
        verdict = admission(self.limits, len(self.active_connections), self.peers.of(host))
        if verdict is Admission.FULL and not self._evict_idlest(host, of_peer=False):
            self.over_limit(host)
            return False
        return True

    def _evict_idlest(self, host: str, *, of_peer: bool) -> bool:
        others = [
            c
            for c in self.active_connections.values()
            if isinstance(c, GatewayRequestHandler)
            and c.transport is not None
            and (not of_peer or c.client == host)
        ]
        if not others:
            return False
        idlest = max(others, key=lambda c: c.idle_for())
        idle = idlest.idle_for()
        if idle < self.limits.evict_after:
            return False
        self.counters.idle_evicted += 1
        limit = (
            f"modbus.max_connections_per_peer {self.limits.max_per_peer}"
            if of_peer
            else f"modbus.max_connections {self.limits.max_connections}"
        )
        log.info(
            "Modbus client %s: connection idle for %.0f s closed to make room for %s (%s open)",
            idlest.client,
            idle,
            host,
            limit,
        )
        idlest.close()
        return True

    def _tell_refused(self, setting: str, host: str) -> None:
        if self._on_refused is not None:
            self._on_refused(setting, host)

    def refused(self, host: str) -> None:
        self.counters.connections_refused += 1
        self._tell_refused("modbus.allow", host)
        if host in self._refused_logged or len(self._refused_logged) >= REFUSED_LOG_LIMIT:
            log.debug("refused Modbus client %s (not in modbus.allow)", host)
            return
        self._refused_logged.add(host)
        log.warning("refused Modbus client %s (not in modbus.allow)", host)

    def over_limit(self, host: str) -> None:
        self.counters.connections_over_limit += 1
        self._tell_refused("modbus.max_connections", host)
        limit = self.limits.max_connections
        held = self._over_limit_log.admit(self.loop.time())
        if held is None:
            log.debug("refused Modbus client %s (modbus.max_connections %d open)", host, limit)
            return
        log.warning(
            "refused Modbus client %s: modbus.max_connections (%d) connections are open%s",
            host,
            limit,
            f"; {held} more refused since the last warning" if held else "",
        )

    def over_peer_limit(self, host: str) -> None:
        self.counters.connections_over_limit += 1
        self.counters.connections_over_peer_limit += 1
        self._tell_refused("modbus.max_connections_per_peer", host)
        limit = self.limits.max_per_peer
        held = self._over_peer_limit_log.admit(self.loop.time())
        if held is None:
            log.debug(
                "refused Modbus client %s (modbus.max_connections_per_peer %d open)", host, limit
            )
            return
        log.warning(
            "refused Modbus client %s: modbus.max_connections_per_peer (%d) connections of"
            " its address are open%s",
            host,
            limit,
            f"; {held} more refused since the last warning" if held else "",
        )

    # ------------------------------------------------------------ life cycle

    async def _open_listener(self) -> Listener:
        host, port = self.comm_params.source_address or ("", 0)
        sockets = await open_listening_sockets(host, port)
        listener = Listener(self.loop, sockets, self.accepted, self.accept_failed)
        listener.start()
        return listener

    async def start(self) -> tuple[str, int]:
        """Listen; returns the bound address. Raises :class:`ModbusBindError`."""
        host, port = self.comm_params.source_address or ("", 0)
        failure: list[OSError] = []

        async def open_and_keep_the_error() -> Listener:
            try:
                return await self._open_listener()
            except OSError as exc:  # pymodbus logs it and drops it: keep it
                failure.append(exc)
                raise

        self.call_create = open_and_keep_the_error
        pymodbus_log = logging.getLogger("pymodbus.logging")
        pymodbus_log.addFilter(_drop_bind_failure)  # ModbusBindError says it, with the fix
        try:
            listening = await self.listen()
        finally:
            pymodbus_log.removeFilter(_drop_bind_failure)
        if not listening:
            raise bind_error(host, port, failure[0] if failure else None)
        sockets = getattr(self.transport, "sockets", None) or ()
        if sockets:
            bound = sockets[0].getsockname()
            return str(bound[0]), int(bound[1])
        return host, port

    async def stop(self) -> None:
        """Stop listening and close every connection."""
        await self.shutdown()  # type: ignore[no-untyped-call]
        connecting = list(self._attaching.items())
        for task, _ in connecting:
            task.cancel()
        for task, conn in connecting:
            with contextlib.suppress(asyncio.CancelledError):
                await task
            conn.close()  # a task cancelled before it ran never gave it to a transport
