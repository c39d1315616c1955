"""The DeviceNet scanner engine: ``step(now, event) -> actions``, nothing else.

Sans-IO and clock-free: the caller gives every received frame (and error frame, and
send failure) as an event, calls :meth:`Scanner.step` with ``event=None`` at
:meth:`Scanner.next_deadline`, and carries out the returned actions.

Sequence (fact sheet 2.10): the scanner's own Duplicate MAC ID check (2.3); per node
Allocate on G2 message 6 (2.5), the Identity object read and checked (2.12), the I/O
connection sizes checked (2.9 attributes 7 and 8), EPR set on the explicit and the
I/O connection (2.9 attribute 9), then polled I/O (G2 message 5 out, G1 0xF back) or
change-of-state/cyclic (G1 0xD in, acknowledged on G2 message 2; our production on
G2 message 5, acknowledged on G1 0xF), fragmented when longer than 8 bytes (2.8).
Inactivity at 4 x EPR (2.9) takes a node offline; it is allocated again when it
answers, at once when its own Duplicate MAC ID check shows it starting up. Allocate and
Release go out one per ``request_spacing``; while the link cannot send, every timer that
leads to a send waits for the end of the send hold. Release on shutdown (:meth:`leave`).
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from adapters.devicenet.canerror import LineCondition, LineHealth, health_after
from adapters.devicenet.cip import (
    DEVICENET_ADDITIONAL_CODE_TEXT,
    NO_ADDITIONAL_CODE,
    AllocationRejection,
    CipClass,
    allocation_rejection,
)
from adapters.devicenet.datatypes import CipType, decode_short_string, decode_value, encode_value
from adapters.devicenet.dupmac import DupMacCheck, DupMacKind
from adapters.devicenet.errors import (
    DataTypeDecodeError,
    DeviceNetDecodeError,
    FragmentationError,
    InvalidCanId,
)
from adapters.devicenet.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    BodyFormat,
    ErrorResponse,
    ExplicitMessage,
    GetAttributeSingle,
    ReleaseConnectionSet,
    Request,
    Response,
    SetAttributeSingle,
    SuccessResponse,
    error_text,
)
from adapters.devicenet.fragment import (
    UNFRAGMENTED_MAX,
    ExplicitFragment,
    ExplicitSender,
    FragmentAck,
    Unfragmented,
    decode_explicit_frame,
    fragment_io,
)
from adapters.devicenet.frame import CanFrame
from adapters.devicenet.ids import PredefinedId, PredefinedMessage, match_predefined
from adapters.devicenet.objects import (
    INACTIVITY_EPR_FACTOR,
    AllocationChoice,
    ConnectionAttribute,
    ConnectionInstance,
    IdentityAttribute,
)
from adapters.devicenet.scanner.api import (
    Action,
    BadFrame,
    BusErrorIn,
    Event,
    ExplicitResult,
    FrameIn,
    InputData,
    IoKind,
    LineFault,
    LineOnline,
    LinkDown,
    NodeConfig,
    NodeDown,
    NodeIdentity,
    NodeUnavailable,
    NodeUp,
    Report,
    ReportKind,
    ScannerConfig,
    Send,
    TxFailed,
)
from adapters.devicenet.scanner.node import Node, Pending, Phase, Purpose, Transaction, Unconnected
from gateway.errors import FrameEncodeError

MAC_MASK = 0x3F
EXPLICIT_LOST_AFTER = 2  # explicit requests in a row unanswered: allocate explicit again


class LinePhase(Enum):
    START = "starting"
    CHECK_1 = "duplicate MAC check (1)"
    CHECK_2 = "duplicate MAC check (2)"
    ONLINE = "online"
    MAC_TAKEN = "MAC ID taken"


@dataclass(slots=True)
class LineFigures:
    frames_tx: int = 0
    frames_rx: int = 0
    bad_frames: int = 0
    foreign_frames: int = 0
    unknown_nodes: int = 0
    tx_failures: int = 0
    tx_dropped: int = 0
    last_tx_failure: str | None = None
    link_down: int = 0  # times the interface was found down
    cycles: int = 0
    cycle_last: float | None = None
    cycle_sum: float = 0.0
    cycle_max: float = 0.0
    conditions: dict[str, int] = field(default_factory=dict)
    duplicate_macs: dict[int, str] = field(default_factory=dict)


Check = Callable[[Node, bytes], str | None]


@dataclass(frozen=True, slots=True)
class _Step:
    label: str
    request: Request
    check: Check


class Scanner:
    """One DeviceNet line seen from its scanner (master)."""

    def __init__(self, config: ScannerConfig, nodes: Iterable[NodeConfig]) -> None:
        self.config = config
        self.nodes: dict[int, Node] = {}
        for cfg in nodes:
            if cfg.mac in self.nodes or cfg.mac == config.mac:
                raise ValueError(f"MAC ID {cfg.mac} used twice on the line")
            self.nodes[cfg.mac] = Node(cfg, backoff=config.retry_min)
        self.line = LineFigures()
        self.phase = LinePhase.START
        self.health = LineHealth.OK
        self._line_deadline = 0.0
        self._out: list[Action] = []
        self._tokens = itertools.count(1)
        self._tx_hold_until = 0.0
        self._tx_backoff = config.tx_backoff_min
        self._last_tx_failure: float | None = None
        self._link_down_reported = False  # until a frame is received again
        self._request_slot = 0.0  # no Allocate/Release before this (request_spacing)
        self._no_ack_reported = False
        self._poll_queue: deque[int] = deque()
        self._in_flight: dict[int, float] = {}
        self._explicit_busy: set[int] = set()  # nodes with an explicit request in flight
        self._bringing = 0  # nodes in bring-up, counted at each step (bringup_window)
        self._cycle_started: float | None = None
        self._cycle_due = 0.0
        self._ids: dict[int, PredefinedId | None] = {}
        self._claims: dict[int, DupMacCheck] = {}
        self._leaving = False
        self._touched: Node | None = None
        self._soonest: float | None = 0.0
        self._frame_handlers: dict[PredefinedMessage, Callable[[Node, float, bytes], None]] = {
            PredefinedMessage.SLAVE_POLL_RESPONSE: self._on_poll_response,
            PredefinedMessage.SLAVE_COS_CYCLIC: self._on_production,
            PredefinedMessage.SLAVE_EXPLICIT_RESPONSE: self._on_explicit_frame,
        }
        self._phase_ticks: dict[Phase, Callable[[Node, float], None]] = {
            Phase.WAITING: self._tick_waiting,
            Phase.ALLOCATING: self._tick_unconnected,
            Phase.RELEASING: self._tick_unconnected,
            Phase.LEAVING: self._tick_unconnected,
            Phase.CONFIGURING: self._tick_explicit,
            Phase.ONLINE: self._tick_online,
            Phase.REFUSED: self._tick_refused,
            Phase.RELEASED: _nothing,
        }

    # ------------------------------------------------------------ public API

    def step(self, now: float, event: Event | None = None) -> list[Action]:
        """Take one event, or none: the timers, and return what to do.

        An event step does what the event calls for (the node it concerns, the poll
        window); every timer runs on ``step(now)``, due at :meth:`next_deadline`.
        """
        if event is None:
            self._tick(now)
            self._recompute()
        else:
            self._touched = None
            before = self._bringing = self._bringups()
            self._on_event(now, event)
            self._after_event(now, event)
            if before >= self.config.bringup_window > self._bringups():
                self._fold((0.0,))  # a bring-up ended: a waiting node may start its own
        out, self._out = self._out, []
        return out

    def next_deadline(self) -> float | None:
        """When :meth:`step` must be called again at the latest (None: only on events).

        Kept up to date as events, requests and outputs come in; O(1).
        """
        return self._soonest

    def _recompute(self) -> None:
        self._soonest = self._all_deadlines()

    def _fold(self, times: Iterable[float]) -> None:
        for t in times:
            if self._soonest is None or t < self._soonest:
                self._soonest = t

    def _all_deadlines(self) -> float | None:
        self._bringing = self._bringups()
        times: list[float] = []
        if self.phase in (LinePhase.START, LinePhase.CHECK_1, LinePhase.CHECK_2):
            times.append(self._line_deadline)
        if self.phase is not LinePhase.ONLINE:
            return min(times) if times else None
        times.extend(sent + self.config.response_timeout for sent in self._in_flight.values())
        if self._cycle_started is None and not self._leaving and self._any_polled_online():
            times.append(self._gated(self._cycle_due))
        for node in self.nodes.values():
            times.extend(self._node_deadlines(node))
        return min(times) if times else None

    def set_output(self, mac: int, data: bytes | None) -> None:
        """The output data for a node's next production; None = idle (zero-length)."""
        node = self.nodes[mac]
        raw = b"" if data is None else bytes(data)
        if raw and len(raw) != node.cfg.consumed_size:
            raise FrameEncodeError(
                f"node {mac} consumes {node.cfg.consumed_size} bytes, not {len(raw)}"
            )
        if raw != node.output and node.cfg.io is IoKind.COS:
            self._fold((0.0,))  # a change of state goes out at once
        node.output = raw

    def submit(self, mac: int, body: Request) -> int:
        """Queue an explicit request; its :class:`ExplicitResult` carries the token."""
        node = self.nodes.get(mac)
        if node is None:
            raise NodeUnavailable(f"node {mac} is not in the scan list")
        if node.phase is not Phase.ONLINE or self._leaving:
            raise NodeUnavailable(f"node {mac} is {node.phase.value}")
        token = next(self._tokens)
        node.queue.append(Pending(body, token=token))
        self._fold((0.0,))
        return token

    def leave(self, now: float) -> list[Action]:
        """Shutdown: Release every allocated node (fact sheet 2.10 step 8)."""
        self._leaving = True
        self._in_flight.clear()  # polls are over: their timeouts no longer matter
        for node in self.nodes.values():
            self._fail_explicit(node, "scanner leaving the line")
            if node.phase in (Phase.CONFIGURING, Phase.ONLINE, Phase.ALLOCATING, Phase.RELEASING):
                node.unconnected = None  # an Allocate in flight is abandoned
                node.phase = Phase.LEAVING  # its Release goes out in turn (request_spacing)
            elif node.phase is not Phase.LEAVING:
                node.phase = Phase.RELEASED
        for node in self.nodes.values():
            if node.phase is Phase.LEAVING:
                self._tick_unconnected(node, now)
        self._recompute()
        out, self._out = self._out, []
        return out

    @property
    def online(self) -> bool:
        """Whether the scanner passed its Duplicate MAC ID check."""
        return self.phase is LinePhase.ONLINE

    @property
    def left(self) -> bool:
        return all(n.phase is Phase.RELEASED for n in self.nodes.values())

    def online_macs(self) -> list[int]:
        return [m for m, n in self.nodes.items() if n.phase is Phase.ONLINE]

    def line_diagnostics(self) -> dict[str, Any]:
        f = self.line
        avg = f.cycle_sum / f.cycles if f.cycles else None
        return {
            "mac": self.config.mac,
            "line_state": self.phase.value,
            "health": self.health.value,
            "frames_tx": f.frames_tx,
            "frames_rx": f.frames_rx,
            "errors": f.bad_frames,
            "foreign_frames": f.foreign_frames,
            "unknown_nodes": f.unknown_nodes,
            "tx_failures": f.tx_failures,
            "tx_dropped": f.tx_dropped,
            "last_tx_failure": f.last_tx_failure,
            "link_down": f.link_down,
            "poll_cycles": f.cycles,
            "cycle_time_ms": _ms(f.cycle_last),
            "cycle_time_avg_ms": _ms(avg),
            "cycle_time_max_ms": _ms(f.cycle_max if f.cycles else None),
            "bus_conditions": dict(f.conditions),
            "duplicate_macs": {str(k): v for k, v in f.duplicate_macs.items()},
            "online": len(self.online_macs()),
        }

    def node_diagnostics(self, mac: int) -> dict[str, Any]:
        node = self.nodes[mac]
        return {
            "mac": mac,
            "state": node.phase.value,
            "io": node.cfg.io.value,
            "ack": node.cfg.ack,
            "epr_ms": _ms(node.epr) if node.epr else None,
            "vendor_id": node.vendor_id,
            "product_code": node.product_code,
            "product_name": node.product_name,
            **node.figures.to_json(),
        }

    def average_cycle(self) -> float | None:
        return self.line.cycle_sum / self.line.cycles if self.line.cycles else None

    # ------------------------------------------------------------ events

    def _on_event(self, now: float, event: Event) -> None:
        if isinstance(event, FrameIn):
            self._tx_backoff = self.config.tx_backoff_min
            self._no_ack_reported = False  # someone acknowledges frames on this line
            self._link_down_reported = False
            self._on_frame(now, event.frame)
        elif isinstance(event, BusErrorIn):
            self._on_bus_error(now, event.conditions)
        elif isinstance(event, TxFailed):
            self._on_tx_failed(now, event)
        elif isinstance(event, LinkDown):
            self._on_link_down(now, event.reason)
        elif isinstance(event, BadFrame):
            self.line.bad_frames += 1

    def _match(self, arbitration_id: int) -> PredefinedId | None:
        if arbitration_id not in self._ids:
            try:
                self._ids[arbitration_id] = match_predefined(arbitration_id)
            except InvalidCanId:
                self._ids[arbitration_id] = None
        return self._ids[arbitration_id]

    def _on_frame(self, now: float, frame: CanFrame) -> None:
        self.line.frames_rx += 1
        found = self._match(frame.arbitration_id)
        if found is None:
            self.line.foreign_frames += 1
            return
        if found.message is PredefinedMessage.DUPLICATE_MAC_CHECK:
            self._on_dupmac(now, frame)
            return
        handler = self._frame_handlers.get(found.message)
        if handler is None:
            self.line.foreign_frames += 1  # another master's frames, or bit-strobe etc.
            return
        node = self.nodes.get(found.mac)
        if node is None:
            self.line.unknown_nodes += 1
            return
        node.figures.frames_rx += 1
        node.last_rx = now
        self._touched = node
        handler(node, now, frame.data)

    def _on_bus_error(self, now: float, conditions: frozenset[LineCondition]) -> None:
        for cond in conditions:
            self.line.conditions[cond.value] = self.line.conditions.get(cond.value, 0) + 1
        before = self.health
        self.health = health_after(before, conditions)
        names = ", ".join(sorted(c.value for c in conditions)) or "unknown error"
        # No ACK comes with every retransmission of an unanswered frame: report it once
        # per series (until a frame is received or the health changes), count them all.
        no_ack = LineCondition.NO_ACK in conditions and not self._no_ack_reported
        if self.health is not before or no_ack:
            self._no_ack_reported = LineCondition.NO_ACK in conditions
            self._report(None, ReportKind.BUS, f"line: {names} (health {self.health.value})")
        recovered = before is LineHealth.BUS_OFF and self.health is not LineHealth.BUS_OFF
        if LineCondition.RESTARTED in conditions or recovered:
            for node in self.nodes.values():  # resume every node without waiting its back-off
                node.backoff = self.config.retry_min
                if node.phase in (Phase.WAITING, Phase.REFUSED):
                    node.retry_at = now

    def _on_tx_failed(self, now: float, event: TxFailed) -> None:
        self._last_tx_failure = now
        self.line.tx_failures += 1
        self.line.tx_dropped += event.dropped
        self.line.last_tx_failure = event.reason
        if self._tx_backoff == self.config.tx_backoff_min:
            self._report(
                None,
                ReportKind.BUS,
                f"cannot send ({event.reason}): backing off {self._tx_backoff:g} s",
            )
        self._tx_hold_until = now + self._tx_backoff
        self._tx_backoff = min(2 * self._tx_backoff, self.config.tx_backoff_max)

    def _on_link_down(self, now: float, reason: str) -> None:
        """The interface is down: every connection is gone now, not after 4 x EPR. The
        nodes wait to be allocated again; the send hold paces the attempts."""
        self.line.link_down += 1
        if not self._link_down_reported:
            self._link_down_reported = True
            self._report(None, ReportKind.BUS, f"CAN interface down ({reason})")
        if not self.online or self._leaving:
            return
        for node in self.nodes.values():
            if node.phase in (Phase.ONLINE, Phase.CONFIGURING):
                self._node_down(node, now, f"CAN interface down ({reason})")
                node.retry_at = now
                node.backoff = self.config.retry_min
            elif node.phase is Phase.ALLOCATING:
                self._retry_later(node, now)

    def _tx_ok(self, now: float) -> bool:
        if now < self._tx_hold_until:
            return False
        self._tx_hold_until = 0.0
        return True

    def _gated(self, t: float) -> float:
        """When something due at ``t`` can be sent: not before the send hold ends.

        Every deadline that leads to a send goes through here, so a held line is not
        stepped again until the hold ends (no busy loop while sends fail).
        """
        return t if t >= self._tx_hold_until else self._tx_hold_until

    # ------------------------------------------------------------ duplicate MAC (2.3)

    def _dupmac_frame(self, kind: DupMacKind) -> CanFrame:
        c = self.config
        return DupMacCheck(c.mac, kind, 0, c.vendor_id, c.serial_number).to_frame()

    def _on_dupmac(self, now: float, frame: CanFrame) -> None:
        try:
            check = DupMacCheck.from_frame(frame)
        except DeviceNetDecodeError:
            self.line.bad_frames += 1
            return
        if check.mac == self.config.mac:
            self._on_own_mac_claimed(check)
            return
        if check.kind is DupMacKind.REQUEST:
            self._claims[check.mac] = check
            self._on_node_claim(now, check.mac)
            return
        claim = self._claims.pop(check.mac, None)
        if claim is not None and claim.serial_number != check.serial_number:
            text = (
                f"duplicate MAC ID {check.mac} on the line: vendor 0x{claim.vendor_id:04X} "
                f"serial {claim.serial_number} claimed it while vendor 0x{check.vendor_id:04X} "
                f"serial {check.serial_number} holds it"
            )
            self.line.duplicate_macs[check.mac] = text
            mac = check.mac if check.mac in self.nodes else None
            self._report(mac, ReportKind.DUPLICATE_MAC, text)

    def _on_node_claim(self, now: float, mac: int) -> None:
        """A Duplicate MAC ID request for a configured node's MAC: the node has just
        started (power-up, reset, bus-off recovery) and answers an Allocate once its
        check is over (fact sheet 2.3: two requests, 1 s apart). A node that is not
        online with us is then allocated at once, whatever its back-off.

        An online node's MAC claimed is left alone: either another device claims it
        (the node answers, and the duplicate is reported) or the node restarted, and
        its inactivity says so within 4 x EPR.
        """
        node = self.nodes.get(mac)
        if node is None or self._leaving or node.phase not in _CLAIM_PHASES:
            return
        period = self.config.dupmac_timeout
        if now >= node.checking_until:  # a new check: it ends two periods after its start
            node.checking_until = now + 2 * period
        else:  # its second request: one period to go
            node.checking_until = max(node.checking_until, now + period)
        node.backoff = self.config.retry_min
        if node.phase in (Phase.WAITING, Phase.REFUSED):
            node.retry_at = node.checking_until + CLAIM_MARGIN * period
            self._touched = node

    def _on_own_mac_claimed(self, check: DupMacCheck) -> None:
        who = f"vendor 0x{check.vendor_id:04X} serial {check.serial_number}"
        if (check.vendor_id, check.serial_number) == (
            self.config.vendor_id,
            self.config.serial_number,
        ):
            who += ", this scanner's own identity: another instance of this gateway"
        if self.phase in (LinePhase.START, LinePhase.CHECK_1, LinePhase.CHECK_2):
            self.phase = LinePhase.MAC_TAKEN
            text = (
                f"scanner MAC ID {self.config.mac} is taken on the line ({who}): not going online"
            )
            self._report(None, ReportKind.DUPLICATE_MAC, text)
            self._out.append(LineFault(text))
        elif self.phase is LinePhase.ONLINE and check.kind is DupMacKind.REQUEST:
            self._emit(self._dupmac_frame(DupMacKind.RESPONSE))
            self._report(
                None,
                ReportKind.DUPLICATE_MAC,
                f"a device ({who}) tried to claim the scanner's MAC ID {self.config.mac}",
            )

    def _tick_line(self, now: float) -> None:
        if self.phase is LinePhase.START:
            self._emit(self._dupmac_frame(DupMacKind.REQUEST))
            self.phase, self._line_deadline = LinePhase.CHECK_1, now + self.config.dupmac_timeout
        elif self.phase is LinePhase.CHECK_1 and now >= self._line_deadline:
            self._emit(self._dupmac_frame(DupMacKind.REQUEST))
            self.phase, self._line_deadline = LinePhase.CHECK_2, now + self.config.dupmac_timeout
        elif self.phase is LinePhase.CHECK_2 and now >= self._line_deadline:
            self.phase = LinePhase.ONLINE
            self._out.append(LineOnline())
            for node in self.nodes.values():
                node.retry_at = now

    # ------------------------------------------------------------ timers

    def _tick(self, now: float) -> None:
        if self.phase is not LinePhase.ONLINE:
            self._tick_line(now)
        if not self.online:
            return
        self._bringing = self._bringups()
        for node in self.nodes.values():
            self._phase_ticks[node.phase](node, now)
        if not self._leaving:
            self._schedule_polls(now)

    def _after_event(self, now: float, event: Event) -> None:
        if not self.online or not isinstance(event, FrameIn):
            self._recompute()  # rare: line checks, bus errors, send failures
            return
        node = self._touched
        if node is not None:
            self._phase_ticks[node.phase](node, now)
            self._fold(self._node_deadlines(node))
        if not self._leaving:
            self._schedule_polls(now)
            timeout = self.config.response_timeout
            self._fold(sent + timeout for sent in self._in_flight.values())
            if self._cycle_started is None:
                self._fold((self._gated(self._cycle_due),))

    def _node_deadlines(self, node: Node) -> list[float]:
        """The node's timers; those that lead to a send are gated by the send hold."""
        out: list[float] = []
        gated = self._gated
        waiting = node.phase in (Phase.WAITING, Phase.REFUSED) and not self._leaving
        if waiting and self._bringing < self.config.bringup_window:
            out.append(gated(max(node.retry_at, self._request_slot)))
        if node.unconnected is not None:
            out.append(node.unconnected.deadline)
        elif node.phase is Phase.LEAVING:
            out.append(gated(self._request_slot))
        if node.current is not None:
            out.append(node.current.deadline)
        elif node.queue and node.phase in _EXPLICIT_PHASES and self._explicit_free():
            out.append(gated(0.0))
        deadline = node.reassembler.deadline
        if deadline is not None:
            out.append(deadline)
        if node.phase is Phase.ONLINE and node.io_reassembler.deadline is not None:
            out.append(node.io_reassembler.deadline)
        if node.phase is Phase.ONLINE:
            out.append(node.last_rx + INACTIVITY_EPR_FACTOR * node.epr)
            if not node.queue and node.current is None:  # a keep-alive only when idle
                out.append(gated(node.last_explicit + self.config.explicit_epr / 2))
            if node.cfg.io is not IoKind.POLLED:
                out.append(gated(node.last_output_sent + node.epr))
                if node.cfg.io is IoKind.COS and node.output != node.sent_output:
                    out.append(gated(0.0))
                if node.ack_deadline is not None:
                    out.append(node.ack_deadline)
        return out

    def _tick_waiting(self, node: Node, now: float) -> None:
        if self._leaving or now < node.retry_at or now < self._request_slot:
            return
        if self._bringing < self.config.bringup_window and self._tx_ok(now):
            self._start_allocate(node, now)

    def _tick_refused(self, node: Node, now: float) -> None:
        if node.unconnected is not None and now >= node.unconnected.deadline:
            node.unconnected = None
        self._tick_waiting(node, now)

    def _tick_unconnected(self, node: Node, now: float) -> None:
        pending = node.unconnected
        if pending is None and node.phase is Phase.LEAVING:  # its Release is due
            if now >= self._request_slot and self._tx_ok(now):
                self._start_release(node, now, Purpose.RELEASE)
            return
        if pending is None or now < pending.deadline:
            return
        node.unconnected = None
        if pending.purpose is Purpose.RELEASE:
            node.phase = Phase.RELEASED
            return
        if node.problem(f"no answer to {pending.purpose.value}"):
            self._report(
                node.mac,
                ReportKind.TIMEOUT,
                f"node {node.mac}: no answer to {pending.purpose.value}",
            )
        self._retry_later(node, now)

    def _tick_online(self, node: Node, now: float) -> None:
        if now >= node.last_rx + INACTIVITY_EPR_FACTOR * node.epr:
            window = INACTIVITY_EPR_FACTOR * node.epr
            self._node_down(node, now, f"no data for {window:g} s (4 x EPR)")
            node.retry_at = now
            self._tick_waiting(node, now)  # allocate it again as soon as it answers
            return
        if node.unconnected is not None and now >= node.unconnected.deadline:
            node.unconnected = None  # an explicit re-allocation unanswered: the next miss retries
        idle = not node.queue and node.current is None
        if idle and now >= node.last_explicit + self.config.explicit_epr / 2:
            # keep the explicit connection alive: read the Identity status
            get = GetAttributeSingle(CipClass.IDENTITY, 1, IdentityAttribute.STATUS)
            node.queue.append(Pending(get, on_done=_ignore, label="keep-alive"))
        self._tick_explicit(node, now)
        if node.cfg.io is not IoKind.POLLED:
            self._tick_production(node, now)

    # ------------------------------------------------------------ allocation (2.5)

    def _start_allocate(self, node: Node, now: float) -> None:
        if node.figures.allocations or node.figures.last_problem is not None:
            node.figures.retries += 1
        node.attempt_started = now
        self._bringing += 1
        c = self.config
        body = AllocateConnectionSet(node.cfg.choice, c.mac)
        self._start_unconnected(node, now, body, Purpose.ALLOCATE, c.allocate_timeout)
        node.phase = Phase.ALLOCATING

    def _start_release(self, node: Node, now: float, purpose: Purpose) -> None:
        body = ReleaseConnectionSet(node.cfg.choice)
        self._start_unconnected(node, now, body, purpose, self.config.explicit_timeout)
        node.phase = _RELEASE_PHASE[purpose]

    def _start_unconnected(
        self,
        node: Node,
        now: float,
        body: AllocateConnectionSet | ReleaseConnectionSet,
        purpose: Purpose,
        timeout: float,
    ) -> None:
        message = ExplicitMessage(self.config.mac, node.next_xid(), body)
        self._send(node, PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST, message.encode())
        node.unconnected = Unconnected(message, purpose, now + timeout)
        self._request_slot = now + self.config.request_spacing

    def _on_unconnected_reply(self, node: Node, now: float, body: Response) -> None:
        pending = node.unconnected
        node.unconnected = None
        if pending is None:
            return
        if pending.purpose is Purpose.EXPLICIT_AGAIN:
            self._on_explicit_again(node, body)
        elif pending.purpose is Purpose.RELEASE:
            node.phase = Phase.RELEASED
        elif pending.purpose is Purpose.RELEASE_THEN_ALLOCATE:
            node.released_before_allocate = True
            self._start_allocate(node, now)
        elif pending.purpose is Purpose.RELEASE_REFUSED:
            pass  # the Release that refused I/O was answered; stay refused
        elif isinstance(body, AllocateResponse):
            self._on_allocated(node, now, body)
        elif isinstance(body, ErrorResponse):
            self._on_allocate_rejected(node, now, body)
        else:
            self._bringup_failed(node, now, f"unexpected reply to Allocate: {body!r}")

    def _on_allocated(self, node: Node, now: float, body: AllocateResponse) -> None:
        if body.body_format not in (None, BodyFormat.CLASS8_INSTANCE8):
            self._bringup_failed(
                node, now, f"node uses message body format {body.message_body_format} (8/8 only)"
            )
            return
        node.figures.allocations += 1
        node.released_before_allocate = False
        node.phase = Phase.CONFIGURING
        node.reassembler.reset()
        node.io_reassembler.reset()
        node.last_explicit = now
        self._queue_setup(node, list(self._setup_steps(node)))

    def _on_allocate_rejected(self, node: Node, now: float, err: ErrorResponse) -> None:
        rejection = allocation_rejection(err.general_status, err.additional_code)
        if rejection is AllocationRejection.ALREADY_ALLOCATED and not node.released_before_allocate:
            self._start_release(node, now, Purpose.RELEASE_THEN_ALLOCATE)
            return
        choice = int(node.cfg.choice)
        texts = {
            AllocationRejection.OWNED_BY_ANOTHER_MASTER: "owned by another master",
            AllocationRejection.ALREADY_ALLOCATED: "still allocated after a Release",
            AllocationRejection.INVALID_CHOICE: (
                f"rejects allocation choice 0x{choice:02X} (check the connection setting)"
            ),
            AllocationRejection.UNSUPPORTED_CHOICE: (
                f"does not support allocation choice 0x{choice:02X} (check the connection setting)"
            ),
        }
        reason = texts.get(rejection) if rejection is not None else None
        if reason is None:  # another answer: the DeviceNet object's additional code says why
            reason = DEVICENET_ADDITIONAL_CODE_TEXT.get(err.additional_code, "error")
            if err.additional_code == NO_ADDITIONAL_CODE:
                reason = "error"
        text = f"node {node.mac}: Allocate refused: {reason} [{error_text(err)}]"
        if node.problem(text):
            self._report(
                node.mac,
                ReportKind.ALLOCATION,
                text,
                general_status=err.general_status,
                additional_code=err.additional_code,
            )
        self._retry_later(node, now)

    def _retry_later(self, node: Node, now: float) -> None:
        node.unconnected = None
        node.released_before_allocate = False
        node.phase = Phase.WAITING
        failed = self._last_tx_failure
        if failed is not None and failed >= node.attempt_started:
            # The line could not send during this attempt (buffer full, bus-off, link
            # down): not the node's fault, so its back-off does not grow; the send hold
            # already paces the attempts.
            node.backoff = self.config.retry_min
        node.retry_at = now + node.backoff
        node.backoff = min(2 * node.backoff, self.config.retry_max)
        if node.checking_until > now:  # it is running its Duplicate MAC ID check
            node.retry_at = node.checking_until + CLAIM_MARGIN * self.config.dupmac_timeout
        self._fail_explicit(node, "node not online")

    # ------------------------------------------------------------ bring-up steps

    def _setup_steps(self, node: Node) -> Iterable[_Step]:
        identity = CipClass.IDENTITY
        io = node.cfg.io_instance
        conn = CipClass.CONNECTION
        yield _Step("vendor ID", GetAttributeSingle(identity, 1, 1), _check_vendor)
        yield _Step("product code", GetAttributeSingle(identity, 1, 3), _check_product_code)
        yield _Step("product name", GetAttributeSingle(identity, 1, 7), _check_product_name)
        if node.cfg.identity.product_type is not None:
            get_type = GetAttributeSingle(identity, 1, IdentityAttribute.DEVICE_TYPE)
            yield _Step("product type", get_type, _check_product_type)
        if node.cfg.identity.revision is not None:
            get_rev = GetAttributeSingle(identity, 1, IdentityAttribute.REVISION)
            yield _Step("revision", get_rev, _check_revision)
        produced = ConnectionAttribute.PRODUCED_CONNECTION_SIZE
        consumed = ConnectionAttribute.CONSUMED_CONNECTION_SIZE
        yield _Step("produced size", GetAttributeSingle(conn, io, produced), _check_produced)
        yield _Step("consumed size", GetAttributeSingle(conn, io, consumed), _check_consumed)
        epr = ConnectionAttribute.EXPECTED_PACKET_RATE
        explicit_ms = _epr_ms(self.config.explicit_epr)
        yield _Step(
            "explicit EPR",
            SetAttributeSingle(conn, ConnectionInstance.EXPLICIT, epr, explicit_ms),
            _accept,
        )
        yield _Step("I/O EPR", SetAttributeSingle(conn, io, epr, _epr_ms(node.cfg.epr)), _set_epr)

    def _queue_setup(self, node: Node, steps: list[_Step]) -> None:
        if not steps:
            return
        step, rest = steps[0], steps[1:]

        def done(now: float, response: Response | None, error: str | None) -> None:
            self._setup_done(node, now, (step, rest), response, error)

        node.queue.append(Pending(step.request, on_done=done, label=step.label))

    def _setup_done(
        self,
        node: Node,
        now: float,
        steps: tuple[_Step, list[_Step]],
        response: Response | None,
        error: str | None,
    ) -> None:
        step, rest = steps
        if node.phase is not Phase.CONFIGURING:
            return
        if error is not None or response is None:
            self._bringup_failed(node, now, f"{step.label}: {error}")
            return
        if isinstance(response, ErrorResponse):
            self._bringup_failed(node, now, f"{step.label} refused: {error_text(response)}")
            return
        try:
            mismatch = step.check(node, response.encode_data())
        except DeviceNetDecodeError as exc:
            self._bringup_failed(node, now, f"{step.label}: bad reply ({exc.message})")
            return
        if mismatch is not None:
            self._refuse(node, now, mismatch)
        elif rest:
            self._queue_setup(node, rest)
        else:
            self._go_online(node, now)

    def _go_online(self, node: Node, now: float) -> None:
        node.phase = Phase.ONLINE
        node.output = b""  # every bring-up starts idle: no command from before it (rule 1)
        node.backoff = self.config.retry_min
        node.last_rx = now
        node.sent_output = None
        node.last_output_sent = 0.0
        node.ack_deadline = None
        node.figures.last_problem = None
        identity = NodeIdentity(node.vendor_id, node.product_code, node.product_name)
        self._out.append(NodeUp(node.mac, identity, node.epr))

    def _bringup_failed(self, node: Node, now: float, text: str) -> None:
        full = f"node {node.mac}: bring-up failed: {text}"
        if node.problem(full):
            self._report(node.mac, ReportKind.PROTOCOL, full)
        self._retry_later(node, now)

    def _refuse(self, node: Node, now: float, text: str) -> None:
        """Identity or size mismatch: report, release, refuse I/O, try again later."""
        kind = ReportKind.SIZE if "size" in text else ReportKind.IDENTITY
        full = f"node {node.mac}: {text}: I/O refused"
        if node.problem(full):
            self._report(node.mac, kind, full)
        self._fail_explicit(node, "I/O refused")
        self._start_release(node, now, Purpose.RELEASE_REFUSED)
        node.retry_at = now + self.config.retry_max

    # ------------------------------------------------------------ explicit channel

    def _tick_explicit(self, node: Node, now: float) -> None:
        current = node.current
        if current is not None and now >= current.deadline:
            self._end_transaction(node)
            node.reassembler.reset()
            node.figures.explicit_timeouts += 1
            timeout = self.config.explicit_timeout
            text = f"no response within {timeout:g} s"
            self._complete(node, now, current.pending, None, text, timed_out=True)
            self._explicit_missed(node, now)
        for reassembler in (node.reassembler, node.io_reassembler):
            if reassembler.deadline is not None and now >= reassembler.deadline:
                try:
                    reassembler.tick(now)
                except FragmentationError:
                    node.figures.bad_frames += 1
        if node.current is None and node.queue and self._explicit_free() and self._tx_ok(now):
            self._start_request(node, now, node.queue.popleft())

    def _explicit_missed(self, node: Node, now: float) -> None:
        """Explicit requests to an online node go unanswered while its polls are answered:
        its explicit connection has most likely been deleted (auto delete after 4 x EPR
        of silence, fact sheet 2.9), e.g. after the requests waited too long for the
        window on a slow machine. Allocate it again on its own (the node is ours: the
        I/O connection stays) instead of leaving the node without parameter access."""
        node.explicit_misses += 1
        if node.phase is not Phase.ONLINE or node.unconnected is not None:
            return
        if node.explicit_misses < EXPLICIT_LOST_AFTER or not self._tx_ok(now):
            return
        text = (
            f"node {node.mac}: {node.explicit_misses} explicit requests unanswered: "
            "allocating its explicit connection again"
        )
        if node.problem(text):
            self._report(node.mac, ReportKind.TIMEOUT, text)
        body = AllocateConnectionSet(AllocationChoice.EXPLICIT, self.config.mac)
        timeout = self.config.allocate_timeout
        self._start_unconnected(node, now, body, Purpose.EXPLICIT_AGAIN, timeout)

    def _on_explicit_again(self, node: Node, body: Response) -> None:
        """The reply to an explicit re-allocation: allocated (set its EPR first), or
        already allocated (it was alive, only slow); anything else waits for the next miss."""
        if isinstance(body, AllocateResponse):
            node.explicit_misses = 0
            node.figures.explicit_reallocations += 1
            epr = ConnectionAttribute.EXPECTED_PACKET_RATE
            ms = _epr_ms(self.config.explicit_epr)
            set_epr = SetAttributeSingle(CipClass.CONNECTION, ConnectionInstance.EXPLICIT, epr, ms)
            node.queue.appendleft(Pending(set_epr, on_done=_ignore, label="explicit EPR"))
        elif isinstance(body, ErrorResponse):
            rejection = allocation_rejection(body.general_status, body.additional_code)
            if rejection is AllocationRejection.ALREADY_ALLOCATED:
                node.explicit_misses = 0

    def _bringups(self) -> int:
        return sum(1 for n in self.nodes.values() if n.phase in _BRINGUP_PHASES)

    def _explicit_free(self) -> bool:
        """Whether another explicit request may go out (``explicit_window``)."""
        return len(self._explicit_busy) < self.config.explicit_window

    def _end_transaction(self, node: Node) -> None:
        """The node's explicit request is over; a node waiting for the window may go."""
        node.current = None
        full = not self._explicit_free()
        self._explicit_busy.discard(node.mac)
        if full:
            self._fold((0.0,))  # wake the next step: every waiting node is ticked

    def _start_request(self, node: Node, now: float, pending: Pending) -> None:
        message = ExplicitMessage(self.config.mac, node.next_xid(), pending.body)
        try:
            sender = ExplicitSender(message.encode(), ack_timeout=self.config.explicit_timeout)
        except FrameEncodeError as exc:
            self._complete(node, now, pending, None, f"cannot encode the request: {exc}")
            return
        self._send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, sender.start(now))
        node.current = Transaction(
            pending, message, sender, now, now + self.config.explicit_timeout
        )
        self._explicit_busy.add(node.mac)
        node.last_explicit = now

    def _on_explicit_frame(self, node: Node, now: float, data: bytes) -> None:
        if not data or data[0] & MAC_MASK != self.config.mac:
            self.line.foreign_frames += 1  # a response to another master
            return
        try:
            frame = decode_explicit_frame(data)
        except DeviceNetDecodeError:
            node.figures.bad_frames += 1
            return
        if isinstance(frame, FragmentAck):
            self._on_fragment_ack(node, now, frame)
        elif isinstance(frame, Unfragmented):
            self._on_explicit_message(node, now, frame.message)
        elif node.phase in _EXPLICIT_PHASES:
            self._on_fragment(node, now, frame)
        else:
            node.figures.stale_responses += 1  # a late fragment of a closed connection

    def _on_fragment_ack(self, node: Node, now: float, ack: FragmentAck) -> None:
        current = node.current
        if current is None:
            return
        try:
            nxt = current.sender.on_ack(now, ack)
        except FragmentationError as exc:
            self._end_transaction(node)
            self._complete(node, now, current.pending, None, f"fragment refused: {exc}")
            return
        if nxt is not None:
            self._send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, nxt)
            current.deadline = now + self.config.explicit_timeout

    def _on_fragment(self, node: Node, now: float, fragment: ExplicitFragment) -> None:
        try:
            step = node.reassembler.feed(now, fragment)
        except FragmentationError:
            node.figures.bad_frames += 1
            return
        if step.ack is not None:
            self._send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, step.ack.encode())
        if node.current is not None:
            node.current.deadline = now + self.config.explicit_timeout
        if step.message is not None:
            self._on_explicit_message(node, now, step.message)

    def _on_explicit_message(self, node: Node, now: float, raw: bytes) -> None:
        try:
            message = ExplicitMessage.decode(raw)
        except DeviceNetDecodeError:
            node.figures.bad_frames += 1
            return
        if message.is_request:
            node.figures.bad_frames += 1
            return
        body = message.body
        if not isinstance(body, _RESPONSES):
            return
        pending = node.unconnected
        if pending is not None and message.answers(pending.message):
            self._on_unconnected_reply(node, now, body)
            return
        current = node.current
        if current is None or not message.answers(current.message):
            node.figures.stale_responses += 1
            return
        self._end_transaction(node)
        node.explicit_misses = 0
        node.figures.explicit_rtt_last = now - current.started
        self._complete(node, now, current.pending, body, None)

    def _complete(
        self,
        node: Node,
        now: float,
        pending: Pending,
        response: Response | None,
        error: str | None,
        *,
        timed_out: bool = False,
    ) -> None:
        if error is not None or isinstance(response, ErrorResponse):
            node.figures.explicit_errors += 1
        else:
            node.figures.explicit_ok += 1
        if pending.on_done is not None:
            pending.on_done(now, response, error)
        if pending.token is not None:
            self._out.append(ExplicitResult(pending.token, node.mac, response, error, timed_out))

    def _fail_explicit(self, node: Node, why: str) -> None:
        pendings = list(node.queue)
        node.queue.clear()
        if node.current is not None:
            pendings.insert(0, node.current.pending)
            self._end_transaction(node)
        node.reassembler.reset()
        for pending in pendings:
            if pending.token is not None:
                self._out.append(ExplicitResult(pending.token, node.mac, None, why))

    # ------------------------------------------------------------ I/O

    def _any_polled_online(self) -> bool:
        return any(
            n.phase is Phase.ONLINE and n.cfg.io is IoKind.POLLED for n in self.nodes.values()
        )

    def _schedule_polls(self, now: float) -> None:
        timeout = self.config.response_timeout
        for mac, sent in list(self._in_flight.items()):
            if now >= sent + timeout:
                del self._in_flight[mac]
                self.nodes[mac].figures.poll_timeouts += 1
        if self._cycle_started is None and now >= self._cycle_due and self._tx_ok(now):
            self._cycle_due = now + self.config.poll_interval
            macs = [
                m
                for m, n in self.nodes.items()
                if n.phase is Phase.ONLINE and n.cfg.io is IoKind.POLLED
            ]
            if macs:
                self._cycle_started = now
                self._poll_queue = deque(macs)
        while (
            self._poll_queue and len(self._in_flight) < self.config.poll_window and self._tx_ok(now)
        ):
            node = self.nodes[self._poll_queue.popleft()]
            if node.phase is Phase.ONLINE:
                self._send_io(node, node.output)
                self._in_flight[node.mac] = now
        if self._cycle_started is not None and not self._poll_queue and not self._in_flight:
            self._cycle_done(now - self._cycle_started)
            self._cycle_started = None

    def _cycle_done(self, seconds: float) -> None:
        f = self.line
        f.cycles += 1
        f.cycle_last = seconds
        f.cycle_sum += seconds
        f.cycle_max = max(f.cycle_max, seconds)

    def _on_poll_response(self, node: Node, now: float, data: bytes) -> None:
        if node.cfg.io is not IoKind.POLLED:
            if node.ack_deadline is not None:  # the acknowledge of our production
                node.figures.rtt(now - node.last_output_sent)
                node.ack_deadline = None
            return
        message = self._io_message(node, now, data)
        if message is None:
            return
        sent = self._in_flight.pop(node.mac, None)
        if sent is not None:
            node.figures.rtt(now - sent)
        self._deliver(node, message)

    def _on_production(self, node: Node, now: float, data: bytes) -> None:
        if node.cfg.io is IoKind.POLLED:
            node.figures.bad_frames += 1
            return
        message = self._io_message(node, now, data)
        if message is None:
            return
        if node.cfg.ack and node.phase is Phase.ONLINE:
            self._send(node, PredefinedMessage.MASTER_COS_CYCLIC_ACK, b"")
        self._deliver(node, message)

    def _io_message(self, node: Node, now: float, data: bytes) -> bytes | None:
        """A whole I/O message: the frame itself, or the last of its fragments when the
        node produces more than 8 bytes (fact sheet 2.8); None while incomplete or bad."""
        if node.cfg.produced_size <= UNFRAGMENTED_MAX:
            return data
        if node.phase is not Phase.ONLINE:
            return None
        try:
            return node.io_reassembler.feed(now, data).message
        except FragmentationError:
            node.figures.bad_frames += 1
            return None

    def _send_io(self, node: Node, data: bytes) -> None:
        """Our I/O data to a node, fragmented when longer than one frame (fact sheet 2.8)."""
        if len(data) <= UNFRAGMENTED_MAX:
            self._send(node, PredefinedMessage.MASTER_POLL_COMMAND, data)
            return
        for payload in fragment_io(data):
            self._send(node, PredefinedMessage.MASTER_POLL_COMMAND, payload)

    def _deliver(self, node: Node, data: bytes) -> None:
        if node.phase is not Phase.ONLINE:
            return
        if len(data) != node.cfg.produced_size:
            node.figures.bad_frames += 1
            return
        self._out.append(InputData(node.mac, data))

    def _tick_production(self, node: Node, now: float) -> None:
        """Our change-of-state / cyclic production to the node, and its acknowledge."""
        if node.ack_deadline is not None and now >= node.ack_deadline:
            node.figures.ack_timeouts += 1
            node.ack_deadline = None
            if not node.ack_retried and self._tx_ok(now):
                node.ack_retried = True
                self._produce(node, now)
                return
        changed = node.cfg.io is IoKind.COS and node.output != node.sent_output
        if (changed or now >= node.last_output_sent + node.epr) and self._tx_ok(now):
            node.ack_retried = False
            self._produce(node, now)

    def _produce(self, node: Node, now: float) -> None:
        self._send_io(node, node.output)
        node.sent_output = node.output
        node.last_output_sent = now
        if node.cfg.ack:
            node.ack_deadline = now + self.config.response_timeout

    def _node_down(self, node: Node, now: float, reason: str) -> None:
        self._fail_explicit(node, f"node went offline: {reason}")
        self._in_flight.pop(node.mac, None)
        node.phase = Phase.WAITING
        node.unconnected = None
        node.figures.offline_count += 1
        node.problem(reason)
        self._out.append(NodeDown(node.mac, reason))

    # ------------------------------------------------------------ helpers

    def _send(self, node: Node, message: PredefinedMessage, data: bytes) -> None:
        node.figures.frames_tx += 1
        self._emit(_frame(message, node.mac, data))

    def _emit(self, frame: CanFrame) -> None:
        self.line.frames_tx += 1
        self._out.append(Send(frame))

    def _report(self, mac: int | None, kind: ReportKind, text: str, **data: object) -> None:
        self._out.append(Report(mac, kind, text, dict(data)))


# ---------------------------------------------------------------- module helpers

_FRAME_IDS: dict[tuple[PredefinedMessage, int], int] = {}


def _frame(message: PredefinedMessage, mac: int, data: bytes) -> CanFrame:
    key = (message, mac)
    arbitration_id = _FRAME_IDS.get(key)
    if arbitration_id is None:
        arbitration_id = _FRAME_IDS[key] = PredefinedId(message, mac).arbitration_id
    return CanFrame(arbitration_id, data)


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000.0, 3)


def _epr_ms(seconds: float) -> bytes:
    return encode_value(CipType.UINT, min(max(round(seconds * 1000.0), 1), 0xFFFF))


def _nothing(_node: Node, _now: float) -> None:
    return None


def _ignore(_now: float, _response: Response | None, _error: str | None) -> None:
    return None


_RELEASE_PHASE = {
    Purpose.RELEASE: Phase.LEAVING,
    Purpose.RELEASE_THEN_ALLOCATE: Phase.RELEASING,
    Purpose.RELEASE_REFUSED: Phase.REFUSED,
}
_RESPONSES = (SuccessResponse, AllocateResponse, ErrorResponse)
_EXPLICIT_PHASES = (Phase.CONFIGURING, Phase.ONLINE)  # an explicit connection is open
_BRINGUP_PHASES = (Phase.ALLOCATING, Phase.CONFIGURING)  # counted in bringup_window
# Phases in which a node's own Duplicate MAC ID check means "allocate it when it is done".
_CLAIM_PHASES = (Phase.WAITING, Phase.REFUSED, Phase.ALLOCATING, Phase.CONFIGURING)
CLAIM_MARGIN = 0.1  # of a check period, after the node's check is expected to end


def _check_vendor(node: Node, data: bytes) -> str | None:
    node.vendor_id = decode_value(CipType.UINT, data)
    want = node.cfg.identity.vendor_id
    if want is not None and node.vendor_id != want:
        return f"identity mismatch: vendor ID 0x{node.vendor_id:04X}, expected 0x{want:04X}"
    return None


def _check_product_code(node: Node, data: bytes) -> str | None:
    node.product_code = decode_value(CipType.UINT, data)
    want = node.cfg.identity.product_code
    if want is not None and node.product_code != want:
        return f"identity mismatch: product code {node.product_code}, expected {want}"
    return None


def _check_product_name(node: Node, data: bytes) -> str | None:
    node.product_name = decode_short_string(data)
    want = node.cfg.identity.product_name
    if want is not None and node.product_name != want:
        return f"identity mismatch: product name {node.product_name!r}, expected {want!r}"
    return None


def _check_product_type(node: Node, data: bytes) -> str | None:
    found = decode_value(CipType.UINT, data)
    want = node.cfg.identity.product_type
    if want is not None and found != want:
        return f"identity mismatch: product type {found}, expected {want}"
    return None


def _check_revision(node: Node, data: bytes) -> str | None:
    if len(data) != 2:  # Identity attribute 4: STRUCT of USINT major, USINT minor
        raise DataTypeDecodeError(f"revision of {len(data)} bytes (2 expected)", data)
    major, minor = data[0], data[1]
    want = node.cfg.identity.revision
    if want is not None and (major != want[0] or minor < want[1]):
        return (
            f"identity mismatch: revision {major}.{minor}, expected {want[0]}.{want[1]} "
            f"(major {want[0]}, minor {want[1]} or later)"
        )
    return None


def _check_produced(node: Node, data: bytes) -> str | None:
    size = decode_value(CipType.UINT, data)
    if size != node.cfg.produced_size:
        return (
            f"I/O size mismatch: the node produces {size} bytes, "
            f"the assembly has {node.cfg.produced_size}"
        )
    return None


def _check_consumed(node: Node, data: bytes) -> str | None:
    size = decode_value(CipType.UINT, data)
    if size != node.cfg.consumed_size:
        return (
            f"I/O size mismatch: the node consumes {size} bytes, "
            f"the assembly has {node.cfg.consumed_size}"
        )
    return None


def _accept(_node: Node, _data: bytes) -> str | None:
    return None


def _set_epr(node: Node, data: bytes) -> str | None:
    # The Set reply carries the EPR the node actually uses (fact sheet 2.9, 2.10 step 5).
    node.epr = decode_value(CipType.UINT, data) / 1000.0 if data else node.cfg.epr
    if node.epr <= 0:
        node.epr = node.cfg.epr
    return None
