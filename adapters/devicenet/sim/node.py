"""A simulated CFW-08 on DeviceNet: a Group 2 Only server (seed 2), sans-IO.

``step(now, frame) -> frames`` with ``next_deadline()``: the Duplicate MAC ID check
(fact sheet 2.3) and answers to others', Allocate/Release with the reference slaves'
error answers (2.5), the explicit services (:mod:`adapters.devicenet.sim.objects`)
with fragmentation both ways (2.8), polled and change-of-state/cyclic I/O with the
P710 assembly pair in force since the last reset (seed 3, 4.1.8), shown in the I/O
connections' paths (seed tables 13-14), inactivity at 4 x EPR (2.9) with the P313 action
(seed 4.1.3), and a fault reset that takes the node offline for a moment (seed 3.4).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from functools import partial

from adapters.devicenet import cfw08
from adapters.devicenet.cfw08 import ASSEMBLY_SIZE
from adapters.devicenet.codec.cip import (
    ALLOCATION_REJECTIONS,
    AllocationRejection,
    Service,
    StatusPair,
)
from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind
from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    ErrorResponse,
    ExplicitMessage,
    ReleaseConnectionSet,
    Response,
    SuccessResponse,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import (
    PredefinedId,
    PredefinedMessage,
    match_predefined,
    predefined_can_id,
)
from adapters.devicenet.codec.objects import (
    NO_MASTER,
    AllocationChoice,
    ConnectionInstance,
    assembly_path,
)
from adapters.devicenet.errors import DeviceNetDecodeError, ExplicitDecodeError, InvalidCanId
from adapters.devicenet.sim import objects
from adapters.devicenet.sim.connection import IoTrigger, SimConnection
from adapters.devicenet.sim.drive import E37_TIMEOUT, SimDrive, SimDriveConfig
from adapters.devicenet.sim.explicit import ExplicitPort
from adapters.devicenet.sim.objects import Identity
from gateway.sim import FaultInjector

P206, P700, P701, P703 = 206, 700, 701, 703
P700_DEVICENET = 2  # seed 4.1.4: 2 = DeviceNet
AC = AllocationChoice
IO_BITS = AC.POLL | AC.COS | AC.CYCLIC
UNSUPPORTED_BITS = int(AC.BIT_STROBE | AC.MULTICAST_POLL) | 0x80  # seed 2.1: poll, COS, cyclic


class SimPhase(Enum):
    OFF = "off"
    CHECKING = "duplicate MAC check"
    ONLINE = "online"
    MAC_FAULT = "MAC ID taken"  # NS solid red (seed 2.2)
    RESETTING = "resetting"  # offline during a reset (seed 3.4 note)
    BUS_OFF = "bus-off"  # E34, P070 = 5; P703 chooses automatic recovery (seed 4.1.7)
    NOT_DEVICENET = "CAN protocol not DeviceNet"  # P700 != 2 after a reset (seed 4.1.4)


@dataclass(frozen=True, slots=True)
class SimNodeConfig:
    mac: int
    p710: int = 1
    p710_stored: int | None = None  # P710 changed but not applied (SimDriveConfig)
    p313: int = 2
    max_rpm: float = 1800.0
    ramp_time: float = 2.0
    weg_speed_scale: int = 8192
    product_code: int = 8
    serial_number: int | None = None  # default 0x08000000 + MAC
    identity: Identity | None = None  # vendor, type, code, revision, name (e.g. from an EDS)
    # The I/O connections' produced/consumed size attributes (e.g. from an EDS);
    # None: the assembly's 4 bytes (seed table 11).
    io_sizes: tuple[int, int] | None = None
    dupmac_timeout: float = 1.0
    epr_tick: float = 0.01  # s: EPR is rounded up to this tick
    reset_offline: float = 0.5  # s offline after a reset
    cos_tick: float = 0.02  # s: how often a change of state is looked for
    jog_rpm: float = 150.0
    undervoltage: bool = False
    seed: int = 0

    @property
    def serial(self) -> int:
        return self.serial_number if self.serial_number is not None else 0x08000000 + self.mac


@dataclass(slots=True)
class SimFigures:
    frames_rx: int = 0
    frames_tx: int = 0
    polls: int = 0
    explicit_requests: int = 0
    allocations: int = 0
    rejections: int = 0
    resets: int = 0
    timeouts: int = 0
    dropped: int = 0
    notes: list[str] = field(default_factory=list)


_SILENT = (SimPhase.OFF, SimPhase.NOT_DEVICENET)
_IDS: dict[tuple[PredefinedMessage, int], int] = {}
_MATCHES: dict[int, PredefinedId | None] = {}


def _match(arbitration_id: int) -> PredefinedId | None:
    """The predefined-set message of an identifier (cached), None for any other."""
    if arbitration_id not in _MATCHES:
        try:
            _MATCHES[arbitration_id] = match_predefined(arbitration_id)
        except InvalidCanId:
            _MATCHES[arbitration_id] = None
    return _MATCHES[arbitration_id]


def _reject(rejection: AllocationRejection) -> ErrorResponse:
    pair: StatusPair = ALLOCATION_REJECTIONS[rejection][0]
    return ErrorResponse(pair.general_status, pair.additional_code)


class Cfw08Node:
    """One simulated CFW-08 on the line."""

    def __init__(self, config: SimNodeConfig) -> None:
        self.config = config
        self.mac = config.mac
        self.drive = SimDrive(
            SimDriveConfig(
                mac=config.mac,
                p710=config.p710,
                p710_stored=config.p710_stored,
                p313=config.p313,
                max_rpm=config.max_rpm,
                ramp_time=config.ramp_time,
                weg_speed_scale=config.weg_speed_scale,
                jog_rpm=config.jog_rpm,
                undervoltage=config.undervoltage,
            )
        )
        base = config.identity or Identity(product_code=config.product_code)
        self.identity = dataclasses.replace(base, serial_number=config.serial)
        self.store: dict[tuple[int, int], int] = {}
        self.faults = FaultInjector(seed=config.seed)
        self.figures = SimFigures()
        self.phase = SimPhase.OFF
        self._now = 0.0
        self._last_advance: float | None = None
        self._deadline = 0.0
        self._checks_sent = 0
        self.allocation = AllocationChoice(0)
        self.master = NO_MASTER
        self.connections: dict[int, SimConnection] = {}
        self._reset_requested = False
        self._fault_at: float | None = None  # when the present fault began (P206 auto-reset)
        response = partial(self._frame, PredefinedMessage.SLAVE_EXPLICIT_RESPONSE)
        self._port = ExplicitPort(response, self.faults, self.figures)
        self._cos_last = 0.0
        self._cos_data: bytes | None = None
        self._reset_connections()
        self._handlers: dict[PredefinedMessage, Callable[[float, bytes, list[CanFrame]], None]] = {
            PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST: self._on_unconnected,
            PredefinedMessage.MASTER_EXPLICIT_REQUEST: self._on_explicit,
            PredefinedMessage.MASTER_POLL_COMMAND: self._on_io,
            PredefinedMessage.MASTER_COS_CYCLIC_ACK: _take_ack,
        }

    # ------------------------------------------------------------ control (tests, CLI)

    def power_on(self, now: float) -> list[CanFrame]:
        """Power up: a fresh line state, then the Duplicate MAC ID check (fact sheet 2.3)."""
        self._now = now
        self._last_advance = now
        self._clear_allocation()
        self.drive.power_up()
        return self._boot(now)

    def reset(self, now: float) -> list[CanFrame]:
        """A reset of the drive (keypad, power blip): offline for a moment, then it starts
        again with P700, P701 and P710 applied (seed 3.4 note, 4.1.4-4.1.8)."""
        if self.phase in _SILENT:
            return []
        self._go_resetting(now)
        return []

    def power_off(self) -> None:
        self.phase = SimPhase.OFF
        self._clear_allocation()
        self.drive.motor.coast()
        self.drive.motor.speed = 0.0

    def inject_fault(self, code: int, now: float | None = None) -> None:
        """The drive trips with error ``code`` (at ``now``, default the last step)."""
        self.drive.trip(code)
        self._fault_at = self._now if now is None else now

    def keypad_reset(self, now: float) -> list[CanFrame]:
        """The keypad's reset of a faulted drive, behind the network's back: the same reset
        as the network's (seed 3.4: offline for a moment, then it starts again with its
        commands cleared). Nothing happens without a fault."""
        if self.phase in _SILENT or not self.drive.fault_reset():
            return []
        self._go_resetting(now)
        return []

    def auto_reset_due(self) -> float | None:
        """When the present fault resets by itself: P206 s after it began (0 = off; the
        CFW-08 user manual's auto-reset, not in the seed)."""
        seconds = self.drive.params.get(P206, 0)
        if self.drive.fault_code is None or self._fault_at is None or seconds <= 0:
            return None
        return self._fault_at + seconds

    def force_owner(self, master_mac: int, now: float) -> None:
        """Tests: the node is already allocated (explicit + poll) by another master."""
        self.allocation = AC.EXPLICIT | AC.POLL
        self.master = master_mac
        self.connections[ConnectionInstance.EXPLICIT].open(now)
        self.connections[ConnectionInstance.POLL].open(now)

    def bus_off(self, now: float, recover_after: float = 0.2) -> None:
        """Fault injection: the node's controller goes bus-off (E34, P070 = 5)."""
        self.phase = SimPhase.BUS_OFF
        self._clear_allocation()
        self.drive.params[70] = 5
        self.drive.comm_loss(34)
        self._deadline = now + recover_after

    def recover(self, now: float) -> list[CanFrame]:
        """Leave bus-off (a manual reset when P703 = 0)."""
        if self.phase is not SimPhase.BUS_OFF:
            return []
        self.drive.params[70] = 2
        return self._start_check(now)

    # ------------------------------------------------------------ stepping

    def step(self, now: float, frame: CanFrame | None = None) -> list[CanFrame]:
        """Take one frame (or none: timers) and return the frames to send."""
        if self.phase in _SILENT:
            return []
        self._now = now
        self._advance(now)
        out: list[CanFrame] = []
        if frame is not None:
            self.figures.frames_rx += 1
            self._on_frame(now, frame, out)
        self._timers(now, out)
        self.figures.frames_tx += len(out)
        return out

    def next_deadline(self) -> float | None:
        phase = self.phase
        if phase in (SimPhase.CHECKING, SimPhase.RESETTING):
            return self._deadline
        if phase is SimPhase.BUS_OFF:
            return self._deadline if self.drive.params[P703] == 1 else None
        if phase is not SimPhase.ONLINE:
            return None
        times = [d for c in self.connections.values() if (d := c.inactivity_deadline())]
        if (auto := self.auto_reset_due()) is not None:
            times.append(auto)
        cos = self.connections[ConnectionInstance.COS_CYCLIC]
        if cos.established and cos.epr_ms:
            times.append(self._cos_last + cos.epr_ms / 1000.0)
            if cos.trigger is IoTrigger.COS:
                times.append(self._now + self.config.cos_tick)
        if (port := self._port.deadline()) is not None:
            times.append(port)
        return min(times) if times else None

    def _advance(self, now: float) -> None:
        last = self._last_advance if self._last_advance is not None else now
        self._last_advance = now
        if now > last:
            self.drive.advance(now - last)

    # ------------------------------------------------------------ frames

    def _frame(self, message: PredefinedMessage, data: bytes) -> CanFrame:
        key = (message, self.mac)
        arbitration_id = _IDS.get(key)
        if arbitration_id is None:
            arbitration_id = _IDS[key] = predefined_can_id(message, self.mac)
        return CanFrame(arbitration_id, data)

    def _on_frame(self, now: float, frame: CanFrame, out: list[CanFrame]) -> None:
        found = _match(frame.arbitration_id)
        if found is None or found.mac != self.mac:
            return
        if found.message is PredefinedMessage.DUPLICATE_MAC_CHECK:
            self._on_dupmac(frame, out)
            return
        if self.phase is not SimPhase.ONLINE:
            return
        handler = self._handlers.get(found.message)
        if handler is not None:
            handler(now, frame.data, out)
            if self._reset_requested or self.drive.reset_requested:
                self._go_resetting(now)

    def _on_dupmac(self, frame: CanFrame, out: list[CanFrame]) -> None:
        try:
            check = DupMacCheck.from_frame(frame)
        except DeviceNetDecodeError:
            return
        if self.phase is SimPhase.CHECKING:
            self.phase = SimPhase.MAC_FAULT  # the address is taken: go to fault (2.3 step 4)
            self.figures.notes.append(f"MAC {self.mac} taken by serial {check.serial_number}")
        elif self.phase is SimPhase.ONLINE and check.kind is DupMacKind.REQUEST:
            out.append(self._dupmac(DupMacKind.RESPONSE))  # 2.3 step 5

    def _dupmac(self, kind: DupMacKind) -> CanFrame:
        vendor = self.identity.vendor_id
        return DupMacCheck(self.mac, kind, 0, vendor, self.config.serial).to_frame()

    # ------------------------------------------------------------ unconnected port (2.5)

    def _on_unconnected(self, now: float, data: bytes, out: list[CanFrame]) -> None:
        try:
            message = ExplicitMessage.decode(data)
        except ExplicitDecodeError as exc:
            self._port.refuse(exc, out)
            return
        if not message.is_request:
            return
        body = message.body
        if isinstance(body, AllocateConnectionSet):
            reply: Response = self._allocate(now, body)
        elif isinstance(body, ReleaseConnectionSet):
            reply = self._release(message.mac, body)
        else:
            reply = _reject(AllocationRejection.INVALID_GROUP_2_ONLY_REQUEST)
        self._port.reply(now, out, message, reply)

    def _allocate(self, now: float, body: AllocateConnectionSet) -> Response:
        choice = AllocationChoice(body.choice)
        bits = int(choice)
        if self.allocation and self.master != body.allocator_mac:
            return self._rejected(AllocationRejection.OWNED_BY_ANOTHER_MASTER)
        if bits & UNSUPPORTED_BITS:
            return self._rejected(AllocationRejection.UNSUPPORTED_CHOICE)
        if _bad_choice(choice, self.allocation):
            return self._rejected(AllocationRejection.INVALID_CHOICE)
        if bits & int(self.allocation) & ~int(AC.ACK_SUPPRESSION):
            return self._rejected(AllocationRejection.ALREADY_ALLOCATED)
        ack = not choice & AC.ACK_SUPPRESSION
        if choice & AC.EXPLICIT:
            self.connections[ConnectionInstance.EXPLICIT].open(now)
        if choice & AC.POLL:
            self.connections[ConnectionInstance.POLL].open(now)
        if choice & (AC.COS | AC.CYCLIC):
            trigger = IoTrigger.COS if choice & AC.COS else IoTrigger.CYCLIC
            self.connections[ConnectionInstance.COS_CYCLIC].open(now, trigger, ack)
            self._cos_data = None
        self.allocation |= choice
        self.master = body.allocator_mac
        self.figures.allocations += 1
        return AllocateResponse(0)

    def _rejected(self, rejection: AllocationRejection) -> Response:
        self.figures.rejections += 1
        return _reject(rejection)

    def _release(self, requester: int, body: ReleaseConnectionSet) -> Response:
        if self.allocation and self.master != requester:
            return self._rejected(AllocationRejection.OWNED_BY_ANOTHER_MASTER)
        choice = AllocationChoice(body.choice)
        released = {
            ConnectionInstance.EXPLICIT: AC.EXPLICIT,
            ConnectionInstance.POLL: AC.POLL,
            ConnectionInstance.COS_CYCLIC: AC.COS | AC.CYCLIC,
        }
        for instance, bits in released.items():
            if choice & bits:
                self.connections[instance].close()
        self.allocation = AllocationChoice(int(self.allocation) & ~int(choice))
        self._settle_allocation()
        return SuccessResponse(Service.RELEASE_MASTER_SLAVE_CONNECTION_SET)

    def _settle_allocation(self) -> None:
        if not int(self.allocation) & ~int(AC.ACK_SUPPRESSION):
            self.allocation = AllocationChoice(0)
            self.master = NO_MASTER

    def _clear_allocation(self) -> None:
        self.allocation = AllocationChoice(0)
        self.master = NO_MASTER
        self._reset_connections()
        self._port.reset()

    def _reset_connections(self) -> None:
        pair = self.drive.pair
        tick = max(1, round(self.config.epr_tick * 1000))
        explicit_id = predefined_can_id(PredefinedMessage.SLAVE_EXPLICIT_RESPONSE, self.mac)
        request_id = predefined_can_id(PredefinedMessage.MASTER_EXPLICIT_REQUEST, self.mac)
        poll_id = predefined_can_id(PredefinedMessage.SLAVE_POLL_RESPONSE, self.mac)
        cos_id = predefined_can_id(PredefinedMessage.SLAVE_COS_CYCLIC, self.mac)
        command_id = predefined_can_id(PredefinedMessage.MASTER_POLL_COMMAND, self.mac)
        sizes = self.config.io_sizes or (ASSEMBLY_SIZE, ASSEMBLY_SIZE)

        def clock() -> float:
            return self._now

        def io(instance: int, produced_id: int) -> SimConnection:
            return SimConnection(
                instance,
                clock,
                produced_id=produced_id,
                consumed_id=command_id,
                produced_size=sizes[0],
                consumed_size=sizes[1],
                produced_path=assembly_path(pair.input_instance),
                consumed_path=assembly_path(pair.output_instance),
                epr_tick_ms=tick,
            )

        self.connections = {
            ConnectionInstance.EXPLICIT: SimConnection(
                ConnectionInstance.EXPLICIT,
                clock,
                produced_id=explicit_id,
                consumed_id=request_id,
                produced_size=0xFFFF,
                consumed_size=0xFFFF,
                epr_tick_ms=tick,
            ),
            ConnectionInstance.POLL: io(ConnectionInstance.POLL, poll_id),
            ConnectionInstance.COS_CYCLIC: io(ConnectionInstance.COS_CYCLIC, cos_id),
        }

    # ------------------------------------------------------------ explicit connection

    def _on_explicit(self, now: float, data: bytes, out: list[CanFrame]) -> None:
        conn = self.connections[ConnectionInstance.EXPLICIT]
        if not conn.established or not data or data[0] & 0x3F != self.master:
            return
        conn.consumed(now)
        raw = self._port.receive(now, data, out)
        if raw is not None:
            self._on_request(now, raw, out)

    def _on_request(self, now: float, raw: bytes, out: list[CanFrame]) -> None:
        try:
            message = ExplicitMessage.decode(raw)
        except ExplicitDecodeError as exc:
            self._port.refuse(exc, out)
            return
        if not message.is_request:
            return
        self.figures.explicit_requests += 1
        body = message.body
        if isinstance(body, AllocateConnectionSet):
            reply: Response = self._allocate(now, body)
        elif isinstance(body, ReleaseConnectionSet):
            reply = self._release(message.mac, body)
        elif isinstance(body, SuccessResponse | AllocateResponse | ErrorResponse):
            return
        else:
            reply = objects.handle(self, body)
        self._port.reply(now, out, message, reply)

    # ------------------------------------------------------------ I/O

    def _on_io(self, now: float, data: bytes, out: list[CanFrame]) -> None:
        conn = _io_connection(self.connections)
        if conn is None:
            return
        conn.consumed(now)
        self.drive.apply_output(data)
        if self.faults.drop():
            self.figures.dropped += 1
            return
        if conn.instance == ConnectionInstance.POLL:
            self.figures.polls += 1
            out.append(self._frame(PredefinedMessage.SLAVE_POLL_RESPONSE, self.drive.input_data()))
        elif conn.acknowledged:
            out.append(self._frame(PredefinedMessage.SLAVE_POLL_RESPONSE, b""))  # COS ack

    def _produce(self, now: float, out: list[CanFrame]) -> None:
        conn = self.connections[ConnectionInstance.COS_CYCLIC]
        if not conn.established or not conn.epr_ms:
            return
        data = self.drive.input_data()
        heartbeat = now >= self._cos_last + conn.epr_ms / 1000.0
        changed = (
            conn.trigger is IoTrigger.COS
            and data != self._cos_data
            and now >= self._cos_last + conn.inhibit_ms / 1000.0
        )
        if heartbeat or changed:
            self._cos_last, self._cos_data = now, data
            out.append(self._frame(PredefinedMessage.SLAVE_COS_CYCLIC, data))

    # ------------------------------------------------------------ timers

    def _boot(self, now: float) -> list[CanFrame]:
        """Power-up or the end of a reset: the CAN parameters that need a reset take effect
        (P700 protocol, P701 address: seed 4.1.4, 4.1.5), then the Duplicate MAC ID check."""
        self.mac = self.drive.params[P701]
        self._reset_connections()
        if self.drive.params[P700] != P700_DEVICENET:
            self.phase = SimPhase.NOT_DEVICENET  # silent on the line
            return []
        return self._start_check(now)

    def _start_check(self, now: float) -> list[CanFrame]:
        self.phase = SimPhase.CHECKING
        self._checks_sent = 1
        self._deadline = now + self.config.dupmac_timeout
        return [self._dupmac(DupMacKind.REQUEST)]

    def _go_resetting(self, now: float) -> None:
        self._reset_requested = False
        self.drive.reset_requested = False
        self.figures.resets += 1
        self.phase = SimPhase.RESETTING
        self._deadline = now + self.config.reset_offline
        self._clear_allocation()

    def request_reset(self) -> None:
        """Identity Reset service (fact sheet 2.7): after the reply, offline for a moment."""
        self._reset_requested = True

    def _timers(self, now: float, out: list[CanFrame]) -> None:
        phase = self.phase
        if phase is SimPhase.CHECKING and now >= self._deadline:
            if self._checks_sent == 1:
                self._checks_sent = 2
                self._deadline = now + self.config.dupmac_timeout
                out.append(self._dupmac(DupMacKind.REQUEST))
            else:
                self.phase = SimPhase.ONLINE  # 2.3 step 3
        elif phase is SimPhase.RESETTING and now >= self._deadline:
            self.drive.power_up()
            out.extend(self._boot(now))
        elif phase is SimPhase.BUS_OFF and self.drive.params[P703] == 1 and now >= self._deadline:
            out.extend(self.recover(now))
        elif phase is SimPhase.ONLINE:
            self._online_timers(now, out)

    def _online_timers(self, now: float, out: list[CanFrame]) -> None:
        auto = self.auto_reset_due()
        if auto is not None and now >= auto:
            self.figures.notes.append(f"auto-reset of E{self.drive.fault_code:02d} (P206)")
            self.keypad_reset(now)
            return
        for conn in self.connections.values():
            deadline = conn.inactivity_deadline()
            if deadline is not None and now > deadline:
                self._timed_out(conn)
        self._port.expire(now)
        self._produce(now, out)

    def _timed_out(self, conn: SimConnection) -> None:
        self.figures.timeouts += 1
        conn.time_out()
        if conn.is_explicit:
            self.allocation = AllocationChoice(int(self.allocation) & ~int(AC.EXPLICIT))
            if not self.allocation & IO_BITS:
                self._settle_allocation()
            return
        self.figures.notes.append("E37")
        self.drive.comm_loss(E37_TIMEOUT)  # seed 2.2 E37 and the P313 action (4.1.3)

    # ------------------------------------------------------------ objects.Context

    def allocation_info(self) -> bytes:
        master = self.master if self.allocation else NO_MASTER
        return bytes((int(self.allocation) & 0xFF, master))

    def allocated(self) -> bool:
        return bool(self.allocation)

    def connection(self, instance: int) -> SimConnection:
        return self.connections[instance]

    @property
    def pair(self) -> cfw08.AssemblyPair:
        return self.drive.pair


def _bad_choice(choice: AllocationChoice, allocation: AllocationChoice) -> bool:
    """Fact sheet 2.5: zero, ACK suppression without COS/cyclic, explicit missing (neither
    asked for nor allocated already)."""
    if not int(choice):
        return True
    if choice & AC.ACK_SUPPRESSION and not choice & (AC.COS | AC.CYCLIC):
        return True
    if choice & AC.COS and choice & AC.CYCLIC:
        return True
    return not (choice & AC.EXPLICIT or allocation & AC.EXPLICIT)


def _io_connection(connections: dict[int, SimConnection]) -> SimConnection | None:
    """The I/O connection established (polled, or COS/cyclic), if any."""
    for instance in (ConnectionInstance.POLL, ConnectionInstance.COS_CYCLIC):
        conn = connections[instance]
        if conn.established:
            return conn
    return None


def _take_ack(now: float, data: bytes, out: list[CanFrame]) -> None:
    """A COS/cyclic acknowledge: taken; no retransmission in the simulator."""
    return None
