"""The Modbus TCP front end: what the daemon runs as ``ModbusFrontEnd(runtime).run()``.

One pymodbus ``SimDevice`` per unit holds the registers. Its ``action`` (run by
pymodbus before every access) fills the status registers from the newest
encoding on a read, and validates a write and turns it into a hub command
before pymodbus stores it; a refusal is an exception code and nothing is
stored. A task follows ``hub.subscribe_states()`` and re-encodes a drive's
status block on every change, so a read costs a list copy.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from gateway.access.audit import AuditTrail, Kind, Result
from gateway.access.roles import Identity, Role
from gateway.config import ModbusSection
from gateway.errors import CommandRejected
from gateway.frontend import FrontEndCounters, RuntimeView
from gateway.hub import Hub
from gateway.modbus.command import ClientMemory, CommandWord, HoldingWrite, build_command
from gateway.modbus.health import (
    GATEWAY_INPUTS,
    GatewayView,
    encode_gateway_inputs,
    parse_version,
)
from gateway.modbus.limits import ConnectionLimits
from gateway.modbus.map import (
    BIT_FUNCTIONS,
    DRIVE_HOLDINGS,
    DRIVE_INPUTS,
    MIRROR_OFFSET,
    SERVED_FUNCTIONS,
    DriveView,
    HoldingView,
    decode_holding_write,
    encode_drive_inputs,
    encode_holding_readback,
)
from gateway.modbus.regs import ExceptionCode, WriteRefused, block_size
from gateway.modbus.server import (
    CURRENT_CLIENT,
    AccessPolicy,
    Counters,
    FastReads,
    GatewayServer,
)
from gateway.model import DriveCommand, DriveState, Source

log = logging.getLogger(__name__)
INTERFACE = "modbus"

Registers = list[int]
Fill = Callable[[int, Registers], None]
HOLDING_READS = (3, 22, 23)  # function codes whose read part returns holding registers


def _put(registers: Registers, start: int, address: int, words: Sequence[int]) -> None:
    """Copy ``words`` into a pymodbus block (``registers[0]`` is ``start``)."""
    i = address - start
    registers[i : i + len(words)] = words


def _bit_block() -> list[SimData]:
    # pymodbus needs a non-empty coil and discrete-input block; no bit is mapped:
    # the actions refuse every bit function with exception 2.
    return [SimData(0, datatype=DataType.BITS)]


@dataclass
class Shared:
    """What every unit of one front end shares."""

    hub: Hub
    memory: ClientMemory
    counters: Counters
    read_only: bool
    section: ModbusSection
    audit: AuditTrail


class DriveUnit:
    """One drive's unit id: its status block, its command registers."""

    def __init__(self, unit: int, drive_id: str, shared: Shared) -> None:
        self.unit = unit
        self.drive_id = drive_id
        self.shared = shared
        hub = shared.hub
        self.inputs: Registers = encode_drive_inputs(
            DriveView(hub.state(drive_id), hub.policy(drive_id))
        )
        self._fills: dict[int, Fill] = {4: self._fill_inputs}
        self._fills.update((fc, self._fill_holdings) for fc in HOLDING_READS)

    @property
    def readable_holdings(self) -> frozenset[int]:
        n = block_size(DRIVE_INPUTS)
        return frozenset(h.address for h in DRIVE_HOLDINGS) | frozenset(
            range(MIRROR_OFFSET, MIRROR_OFFSET + n)
        )

    def update(self, state: DriveState) -> None:
        self.inputs = encode_drive_inputs(DriveView(state, self.shared.hub.policy(self.drive_id)))

    def device(self) -> SimDevice:
        n = block_size(DRIVE_INPUTS)
        inputs = [SimData(0, count=n, datatype=DataType.REGISTERS)]
        holdings = [SimData(h.address, datatype=DataType.REGISTERS) for h in DRIVE_HOLDINGS]
        holdings.append(SimData(MIRROR_OFFSET, count=n, datatype=DataType.REGISTERS, readonly=True))
        return SimDevice(
            id=self.unit,
            simdata=(_bit_block(), _bit_block(), holdings, inputs),
            action=self.action,
        )

    async def action(  # noqa: PLR0917 (pymodbus SimAction calls it positionally)
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: Registers,
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus calls this before it reads (``values`` None) or writes the registers."""
        if function_code in BIT_FUNCTIONS:
            return ExcCodes.ILLEGAL_ADDRESS
        if values is None:
            fill = self._fills.get(function_code)  # 6: the echo of a write, left as written
            if fill is not None:
                fill(start_address, registers)
            return None
        code = self.write(address, [int(v) for v in values])
        return None if code is None else ExcCodes(int(code))

    def _fill_inputs(self, start: int, registers: Registers) -> None:
        _put(registers, start, 0, self.inputs)

    def _fill_holdings(self, start: int, registers: Registers) -> None:
        hub = self.shared.hub
        view = HoldingView(hub.desired(self.drive_id), hub.capabilities(self.drive_id).speed_scale)
        _put(registers, start, 0, encode_holding_readback(view))
        _put(registers, start, MIRROR_OFFSET, self.inputs)

    def write(self, address: int, values: Sequence[int]) -> ExceptionCode | None:
        """Validate and apply a holding write; the exception code if it is refused."""
        client = CURRENT_CLIENT.get()
        if not self.shared.section.may_command(client):
            self._audit_refused(client, address)
            return ExceptionCode.ILLEGAL_FUNCTION
        try:
            scale = self.shared.hub.capabilities(self.drive_id).speed_scale
            self._apply(client, decode_holding_write(address, values, scale))
        except WriteRefused as exc:
            log.debug("unit %d (%s), client %s: %s", self.unit, self.drive_id, client, exc)
            if address == 0 and values:
                self._apply_stop_bits(client, values[0])
            return exc.code
        return None

    def _audit_refused(self, client: str, address: int) -> None:
        """A write from a client without command rights: exception 1, and audited."""
        why = "modbus.read_only" if self.shared.read_only else "its [[modbus.peers]] rights"
        self.shared.audit.record(
            Kind.REFUSED,
            Result.FAILURE,
            interface=INTERFACE,
            peer=client,
            identity=Identity(client, Role.VIEWER),
            detail=f"unit {self.unit} ({self.drive_id}) register {address}: write refused "
            f"(exception 1): this client may read only ({why})",
        )

    def _audited(self, client: str, cmd: DriveCommand, result: Result, why: str = "") -> None:
        self.shared.audit.command(
            cmd,
            result,
            interface=INTERFACE,
            peer=client,
            identity=Identity(client, Role.OPERATOR),
            drive=self.drive_id,
            why=why,
        )

    def _apply_stop_bits(self, client: str, raw: int) -> None:
        """Rule 1 (docs/safety.md): a write refused for another register still applies
        the stops its command word asks for (run or jog 1 -> 0, quick or coast stop 1)."""
        try:
            word = CommandWord.from_register(raw)
        except WriteRefused:
            return  # reserved bits: not a command word at all
        hub = self.shared.hub
        last = self.shared.memory.last(client, self.unit)
        desired = hub.desired(self.drive_id)
        stop = DriveCommand(
            run=False if last.run and not word.run and desired.run else None,
            jog=False if last.jog and not word.jog and desired.jog else None,
            quick_stop=True if word.quick_stop and not desired.quick_stop else None,
            coast_stop=True if word.coast_stop and not desired.coast_stop else None,
        )
        if stop.is_empty:
            return
        self.shared.memory.remember(
            client, self.unit, replace(last, run=last.run and word.run, jog=last.jog and word.jog)
        )
        hub.submit(self.drive_id, Source.MODBUS, stop, client)
        self._audited(client, stop, Result.SUCCESS)

    def _apply(self, client: str, write: HoldingWrite) -> None:
        hub = self.shared.hub
        memory = self.shared.memory
        last = memory.last(client, self.unit)
        if write.word is not None:
            # Remembered even if the hub refuses part of it: its stop bits are always
            # applied (the hub never refuses a stop), and a refused run or jog bit held at 1
            # never becomes an edge later (rule 1: a refused run is never held for later).
            memory.remember(client, self.unit, write.word)
        if write.command:
            cmd = DriveCommand()
            try:
                cmd = build_command(last, write, hub.desired(self.drive_id))
                if cmd.is_empty:
                    hub.check(self.drive_id, Source.MODBUS, cmd, client)
                else:
                    hub.submit(self.drive_id, Source.MODBUS, cmd, client)
            except CommandRejected as exc:
                self.shared.counters.commands_refused += 1
                if not cmd.is_empty:
                    self._audited(client, cmd, Result.FAILURE, exc.reason)
                raise WriteRefused(ExceptionCode.SERVER_DEVICE_FAILURE, exc.reason) from None
            if not cmd.is_empty:
                self._audited(client, cmd, Result.SUCCESS)
            self.shared.counters.commands_accepted += 1
        hub.refresh(self.drive_id, Source.MODBUS, client)  # only the client in control


class GatewayUnit:
    """Unit 0 and ``modbus.gateway_unit``: the gateway's health, read-only."""

    def __init__(self, unit: int, view: Callable[[], GatewayView]) -> None:
        self.unit = unit
        self._view = view
        self._fills: dict[int, int] = {4: 0}
        self._fills.update((fc, MIRROR_OFFSET) for fc in HOLDING_READS)

    @property
    def readable_holdings(self) -> frozenset[int]:
        return frozenset(range(MIRROR_OFFSET, MIRROR_OFFSET + block_size(GATEWAY_INPUTS)))

    def device(self) -> SimDevice:
        n = block_size(GATEWAY_INPUTS)
        inputs = [SimData(0, count=n, datatype=DataType.REGISTERS)]
        holdings = [SimData(MIRROR_OFFSET, count=n, datatype=DataType.REGISTERS, readonly=True)]
        return SimDevice(
            id=self.unit,
            simdata=(_bit_block(), _bit_block(), holdings, inputs),
            action=self.action,
        )

    async def action(  # noqa: PLR0917 (pymodbus SimAction calls it positionally)
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: Registers,
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        if function_code in BIT_FUNCTIONS or values is not None:
            return ExcCodes.ILLEGAL_ADDRESS  # nothing of the gateway unit is writable
        at = self._fills.get(function_code)
        if at is not None:
            _put(registers, start_address, at, encode_gateway_inputs(self._view()))
        return None


class ModbusFrontEnd:
    """Serve every drive with a ``modbus_unit`` and the gateway unit until cancelled."""

    def __init__(self, runtime: RuntimeView) -> None:
        self.runtime = runtime
        self.section = runtime.config.modbus
        self.hub = runtime.hub
        self.counters = Counters()
        self.shared = Shared(
            hub=self.hub,
            memory=ClientMemory(),
            counters=self.counters,
            read_only=self.section.read_only,
            section=self.section,
            audit=runtime.audit,
        )
        self.drives: dict[str, DriveUnit] = {}
        for drive_id in self.hub.drive_ids():
            unit = self.hub.policy(drive_id).modbus_unit
            if unit is not None:
                self.drives[drive_id] = DriveUnit(unit, drive_id, self.shared)
        gateway_units = sorted({0, self.section.gateway_unit})
        self.gateway_units = [GatewayUnit(u, self.gateway_view) for u in gateway_units]
        self.address: tuple[str, int] | None = None
        self.ready = asyncio.Event()  # set while the server listens (tests, benchmarks)
        self._server: GatewayServer | None = None

    def units(self) -> list[DriveUnit | GatewayUnit]:
        return [*self.gateway_units, *self.drives.values()]

    def gateway_view(self) -> GatewayView:
        c = self.counters
        runtime = self.runtime
        restarts = sum(n for what, n in runtime.restarts.items() if what.startswith("bus "))
        return GatewayView(
            version=parse_version(runtime.version),
            uptime_s=time.monotonic() - runtime.started,
            drives=len(self.hub.drive_ids()),
            online=sum(1 for s in self.hub.states() if s.online),
            modbus_drives=len(self.drives),
            read_only=self.section.read_only,
            connections_open=self._server.connections_open if self._server else 0,
            connections_accepted=c.connections_accepted,
            connections_refused=c.connections_refused,
            requests=c.requests,
            exceptions=c.exceptions,
            commands_accepted=c.commands_accepted,
            commands_refused=c.commands_refused,
            bad_frames=c.bad_frames,
            adapter_restarts=restarts,
            frame_timeouts=c.frame_timeouts,
            connections_over_limit=c.connections_over_limit,
            connections_over_peer_limit=c.connections_over_peer_limit,
            accept_failures=c.accept_failures,
        )

    def counted(self) -> FrontEndCounters:
        c = self.counters
        return FrontEndCounters(
            requests={"request": c.requests},
            exceptions=c.exceptions,
            commands_accepted=c.commands_accepted,
            commands_refused=c.commands_refused,
            connections_accepted=c.connections_accepted,
            connections_refused=c.connections_refused,
            connections_over_limit=c.connections_over_limit,
            connections_open=self._server.connections_open if self._server else 0,
            accept_failures=c.accept_failures,
        )

    async def run(self) -> None:
        units = self.units()
        policy = AccessPolicy(
            self.section.allow, {u.unit: u.readable_holdings for u in units}, SERVED_FUNCTIONS
        )
        server = GatewayServer(
            [u.device() for u in units],
            host=self.section.host,
            port=self.section.port,
            policy=policy,
            counters=self.counters,
            limits=ConnectionLimits(
                frame_timeout=self.section.frame_timeout,
                max_connections=self.section.max_connections,
                idle_timeout=self.section.idle_timeout,
                max_per_peer=self.section.max_connections_per_peer,
            ),
            on_peer=self.shared.memory.peer,
            on_refused=self._audit_refused_connection,
            fast_reads=FastReads({u.unit: u for u in self.drives.values()}, MIRROR_OFFSET),
        )
        self.address = await server.start()
        self._server = server
        try:
            self._log_serving()
            self.ready.set()
            await self._follow_states()
        finally:
            self.ready.clear()
            self._server = None
            await server.stop()
            log.info("Modbus TCP server stopped")

    def _audit_refused_connection(self, setting: str, host: str) -> None:
        self.runtime.audit.refused_request(
            INTERFACE, setting, host, f"connection from {host} closed at accept ({setting})"
        )

    def _log_serving(self) -> None:
        host, port = self.address or (self.section.host, self.section.port)
        units = ", ".join(f"{d.unit}={d.drive_id}" for d in self.drives.values()) or "none"
        log.info(
            "Modbus TCP serving on %s:%d: drive units %s; gateway unit(s) %s%s",
            host,
            port,
            units,
            ", ".join(str(g.unit) for g in self.gateway_units),
            " (read only)" if self.section.read_only else "",
        )
        if not self.section.allow and not _is_loopback(host):
            log.warning("modbus.allow is empty: any client may connect to %s:%d", host, port)

    async def _follow_states(self) -> None:
        with self.hub.subscribe_states() as sub:
            for state in self.hub.states():
                self._on_state(state)
            while True:
                self._on_state(await sub.get())

    def _on_state(self, state: DriveState) -> None:
        unit = self.drives.get(state.id)
        if unit is not None:
            unit.update(state)


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


__all__ = ["DriveUnit", "GatewayUnit", "ModbusFrontEnd", "Shared"]
