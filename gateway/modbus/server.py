"""The pymodbus TCP server, with what ``SimDevice`` cannot express.

The register store is pymodbus's own: one ``SimDevice`` per unit, whose
``action`` callback (run before pymodbus reads or writes the registers, able to
refuse with an exception code) does the map's work. Four things happen per
connection or per request, outside any ``SimDevice``, so they live in a
subclass of pymodbus's per-connection ``ServerRequestHandler``, returned by the
documented ``callback_new_connection`` of the server:

- the allow-list, at accept (``connection_made``): other peers are aborted
  before a byte is read;
- framing (``callback_data``, which replaces pymodbus's): a bad MBAP header
  closes the connection; an unknown unit gets exception 0x0B and an unserved
  function exception 1 before pymodbus decodes anything (pymodbus would answer
  an unknown unit from the unit-0 device, serve diagnostics, and answer an
  undecodable PDU with function code 0x80); a served function whose PDU does
  not decode gets exception 3;
- who is asking: the peer address is put in a context variable for the
  duration of the request, so the ``action`` can keep per-client edges.
"""

from __future__ import annotations

import asyncio
import contextvars
import ipaddress
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusIOException
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.register_message import ReadWriteMultipleRegistersRequest
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import SimDevice
from pymodbus.transaction import TransactionManager

from gateway.errors import GatewayError
from gateway.modbus.mbap import HEADER_SIZE, MbapError, parse_header
from gateway.modbus.regs import ExceptionCode

log = logging.getLogger(__name__)

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network

CURRENT_CLIENT: contextvars.ContextVar[str] = contextvars.ContextVar("modbus_client", default="")
"""The peer address of the request being served (set around each request)."""

REFUSED_LOG_LIMIT = 256  # distinct refused addresses logged at WARNING; later ones at DEBUG


class ModbusBindError(GatewayError, OSError):
    """The server could not listen on ``modbus.bind``."""


@dataclass
class Counters:
    """What the gateway unit reports about the server (since start)."""

    connections_accepted: int = 0
    connections_refused: int = 0
    requests: int = 0
    exceptions: int = 0
    commands_accepted: int = 0
    commands_refused: int = 0
    bad_frames: int = 0


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


class GatewayRequestHandler(ServerRequestHandler):
    """One client connection (see the module docstring)."""

    def __init__(self, owner: GatewayServer, *args: Any) -> None:
        super().__init__(owner, *args)  # type: ignore[no-untyped-call]
        self.gateway = owner
        self.client = ""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        peer = transport.get_extra_info("peername")
        host = str(peer[0]) if peer else ""
        if not self.gateway.policy.admits(host):
            self.gateway.refused(host)
            self.close()  # forget this handler (the transport is not ours yet)
            transport.abort()  # type: ignore[attr-defined]
            return
        self.client = host
        self.gateway.counters.connections_accepted += 1
        super().connection_made(transport)

    def callback_data(self, data: bytes, addr: tuple[Any, ...] | None = None) -> int:
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
            except ModbusIOException:
                refusal = ExceptionCode.ILLEGAL_DATA_VALUE  # a served function, malformed PDU
            else:
                pdu = self.last_pdu
                if pdu is None:
                    return used
                refusal = self._pdu_refusal(pdu)
                if refusal is None:
                    self.loop.call_soon(self.handle_later)
                    return used
                self.last_pdu = None
        response = ExceptionResponse(
            function_code & 0x7F,
            ExcCodes(int(refusal)),
            device_id=header.unit,
            transaction=header.transaction,
        )
        self.server_send(response, addr)
        return header.frame_size

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


class GatewayServer(ModbusTcpServer):
    """pymodbus's TCP server with the gateway's connection handler."""

    def __init__(
        self,
        devices: list[SimDevice],
        *,
        host: str,
        port: int,
        policy: AccessPolicy,
        counters: Counters,
    ) -> None:
        super().__init__(devices, address=(host, port))
        self.policy = policy
        self.counters = counters
        self._refused_logged: set[str] = set()

    def callback_new_connection(self) -> GatewayRequestHandler:
        return GatewayRequestHandler(self, self.trace_packet, self.trace_pdu, self.trace_connect)

    @property
    def connections_open(self) -> int:
        return len(self.active_connections)

    def refused(self, host: str) -> None:
        self.counters.connections_refused += 1
        if host in self._refused_logged or len(self._refused_logged) >= REFUSED_LOG_LIMIT:
            log.debug("refused Modbus client %s (not in modbus.allow)", host)
            return
        self._refused_logged.add(host)
        log.warning("refused Modbus client %s (not in modbus.allow)", host)

    async def start(self) -> tuple[str, int]:
        """Listen; returns the bound address. Raises :class:`ModbusBindError`."""
        host, port = self.comm_params.source_address or ("", 0)
        if not await self.listen():
            raise ModbusBindError(f"cannot listen for Modbus TCP on {host}:{port}")
        sockets = getattr(self.transport, "sockets", None) or ()
        if sockets:
            bound = sockets[0].getsockname()
            return str(bound[0]), int(bound[1])
        return host, port

    async def stop(self) -> None:
        """Stop listening and close every connection."""
        await self.shutdown()  # type: ignore[no-untyped-call]
