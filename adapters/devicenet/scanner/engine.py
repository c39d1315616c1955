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

The :class:`Scanner` is the line: its own Duplicate MAC ID check, the events in, the
deadlines and the public API. Its parts (docs/architecture.md, "DeviceNet scanner"):
:class:`~adapters.devicenet.scanner.machine.NodeMachine` (per-node state machine),
:class:`~adapters.devicenet.scanner.scheduler.Scheduler` (poll cycle, explicit and
bring-up windows), :class:`~adapters.devicenet.scanner.jobs.ExplicitJobs` (explicit
message job queue), sharing a :class:`~adapters.devicenet.scanner.context.LineContext`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from enum import Enum
from typing import Any

from adapters.can.events import BadFrame, BusErrorIn, FrameIn, LinkDown, NodeUnavailable, TxFailed
from adapters.can.health import LineHealth, health_after
from adapters.devicenet.codec.dupmac import DUPMAC_LENGTH, DupMacCheck, DupMacKind, is_request
from adapters.devicenet.codec.explicit import Request
from adapters.devicenet.codec.fragment import UNFRAGMENTED_MAX
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import PredefinedId, PredefinedMessage, match_predefined
from adapters.devicenet.codec.objects import INACTIVITY_EPR_FACTOR
from adapters.devicenet.errors import DeviceNetDecodeError, InvalidCanId
from adapters.devicenet.scanner.context import LineContext, ms
from adapters.devicenet.scanner.events import (
    Action,
    Event,
    InputData,
    IoKind,
    LineFault,
    LineOnline,
    NodeConfig,
    ReportKind,
    ScannerConfig,
)
from adapters.devicenet.scanner.jobs import ExplicitJobs
from adapters.devicenet.scanner.machine import INPUTS_REFRESH, NodeMachine
from adapters.devicenet.scanner.node import Node, Phase
from adapters.devicenet.scanner.ownmac import OwnMacDefence
from adapters.devicenet.scanner.scheduler import Scheduler
from adapters.devicenet.scanner.timers import SteadyTimers
from adapters.link.canerror import LineCondition
from gateway.errors import FrameEncodeError


class LinePhase(Enum):
    START = "starting"
    CHECK_1 = "duplicate MAC check (1)"
    CHECK_2 = "duplicate MAC check (2)"
    ONLINE = "online"
    MAC_TAKEN = "MAC ID taken"


_CHECKING = (LinePhase.START, LinePhase.CHECK_1, LinePhase.CHECK_2)


class Scanner:
    """One DeviceNet line seen from its scanner (master)."""

    def __init__(self, config: ScannerConfig, nodes: Iterable[NodeConfig]) -> None:
        self.config = config
        self.nodes: dict[int, Node] = {}
        for cfg in nodes:
            if cfg.mac in self.nodes or cfg.mac == config.mac:
                raise ValueError(f"MAC ID {cfg.mac} used twice on the line")
            self.nodes[cfg.mac] = Node(cfg, backoff=config.retry_min)
        self._ctx = ctx = LineContext(config, self.nodes)
        self.line = ctx.figures
        self.phase = LinePhase.START
        self.health = LineHealth.OK
        self._line_deadline = 0.0
        self._link_down_reported = False  # until a frame is received again
        self._no_ack_reported = False
        self._ids: dict[int, PredefinedId | None] = {}
        self._claims: dict[int, DupMacCheck] = {}
        self._own_mac = OwnMacDefence(config.mac)  # requests for the scanner's MAC, online
        self.schedule = Scheduler(ctx)
        self.jobs = ExplicitJobs(ctx, self.schedule)
        self.machine = NodeMachine(ctx, self.schedule, self.jobs)
        self._ticks = self.machine.ticks
        self._timers = SteadyTimers(self.nodes, self.machine.steady, self.machine.idle_time)
        self.lazy_timers = True  # False: every timer step is a full pass (tests compare)
        # for hold_until: fixed by the scan list
        self._all_polled = all(n.cfg.io is IoKind.POLLED for n in self.nodes.values())
        # the steady lane (docs/decisions/0097): a polled node's poll response by its identifier
        self.lane = True  # False: every frame through the full step (tests compare)
        self._poll_replies = {
            PredefinedId(PredefinedMessage.SLAVE_POLL_RESPONSE, n.mac).arbitration_id: n
            for n in self.nodes.values()
            if n.cfg.io is IoKind.POLLED and n.cfg.produced_size <= UNFRAGMENTED_MAX
        }
        self._frame_handlers: dict[PredefinedMessage, Callable[[Node, float, bytes], None]] = {
            PredefinedMessage.SLAVE_POLL_RESPONSE: self.machine.on_poll_response,
            PredefinedMessage.SLAVE_COS_CYCLIC: self.machine.on_production,
            PredefinedMessage.SLAVE_EXPLICIT_RESPONSE: self.jobs.on_frame,
        }

    # ------------------------------------------------------------ public API

    def step(self, now: float, event: Event | None = None) -> list[Action]:
        """Take one event, or none: the timers, and return what to do.

        An event step does what the event calls for (the node it concerns, the poll
        window); every timer runs on ``step(now)``, due at :meth:`next_deadline`.
        """
        ctx, schedule = self._ctx, self.schedule
        if type(event) is FrameIn and self.lane:
            node = self._poll_replies.get(event.frame.arbitration_id)
            if node is not None and node.quiet and self._steady_reply(node, now, event.frame):
                return ctx.take()
        if event is None:
            if self._own_mac.due_at is not None:
                self._own_mac_due(now)
            if self._lazy_step(now):
                self._tick_due(now)
                self._recompute_due()
            else:
                self._tick(now)
                self._recompute()
        else:
            ctx.touched = None
            before = schedule.bringing = schedule.bringups()
            self._on_event(now, event)
            self._after_event(now, event)
            if before >= self.config.bringup_window > schedule.bringups():
                ctx.wake()  # a bring-up ended: a waiting node may start its own
        return ctx.take()

    def next_deadline(self) -> float | None:
        """When :meth:`step` must be called again at the latest (None: only on events).

        Kept up to date as events, requests and outputs come in; O(1).
        """
        return self._ctx.soonest

    def hold_until(self, now: float) -> float | None:
        """Received frames need not be handled before this time (the CAN driver's
        receive hold, :meth:`adapters.link.candriver.CanProtocol.hold_until`); None: each
        frame is handled as it comes.

        Only on a steady line: online, not leaving, health ok, no send hold, every node
        in the scan list online and polled with no explicit request queued, none in
        flight and none in bring-up; then until the first half of the poll window can
        have been answered, at most ``HOLD_MAX`` (:meth:`Scheduler.hold_until`). Every
        deadline of the engine still ends a hold (the driver bounds it by
        :meth:`next_deadline`)."""
        ctx, schedule = self._ctx, self.schedule
        if (
            not self._all_polled
            or schedule.online != len(self.nodes)
            or self.phase is not LinePhase.ONLINE
            or ctx.leaving
            or self.health is not LineHealth.OK
            or now < ctx.tx_hold_until
            or schedule.in_bringup
            or schedule.explicit_busy
            or any(schedule.queues)
        ):
            return None
        return schedule.hold_until(now)

    def quiet_inputs(self, mac: int, quiet: bool) -> None:
        """Whether the caller is quiet about a node: its outputs and readings depend on
        nothing but its inputs and what it is told otherwise, so an unchanged input need
        not be reported but every :data:`~adapters.devicenet.scanner.machine.INPUTS_REFRESH`
        s (docs/decisions/0097). Only an online node is quiet; any change of its phase
        ends it."""
        node = self.nodes[mac]
        node.quiet = quiet and node.phase is Phase.ONLINE

    def set_output(self, mac: int, data: bytes | None) -> None:
        """The output data for a node's next production; None = idle (zero-length)."""
        node = self.nodes[mac]
        raw = b"" if data is None else bytes(data)
        if raw and len(raw) != node.cfg.consumed_size:
            raise FrameEncodeError(
                f"node {mac} consumes {node.cfg.consumed_size} bytes, not {len(raw)}"
            )
        if raw != node.output and node.cfg.io is IoKind.COS:
            self._ctx.wake()  # a change of state goes out at once
        node.output = raw  # (a change-of-state node is never steady: every timer step ticks it)

    def submit(self, mac: int, body: Request) -> int:
        """Queue an explicit request; its :class:`ExplicitResult` carries the token."""
        node = self.nodes.get(mac)
        if node is None:
            raise NodeUnavailable(f"node {mac} is not in the scan list")
        if node.phase is not Phase.ONLINE or self._ctx.leaving:
            raise NodeUnavailable(f"node {mac} is {node.phase.value}")
        token = self.jobs.submit(node, body)
        self._timers.track(node)  # not steady now: every timer step ticks it
        return token

    def leave(self, now: float) -> list[Action]:
        """Shutdown: Release every allocated node (fact sheet 2.10 step 8)."""
        self._ctx.leaving = True
        self.schedule.stop()  # polls are over: their timeouts no longer matter
        self.machine.leave(now)
        self._recompute()
        return self._ctx.take()

    @property
    def online(self) -> bool:
        """Whether the scanner passed its Duplicate MAC ID check."""
        return self.phase is LinePhase.ONLINE

    @property
    def left(self) -> bool:
        return all(n.phase is Phase.RELEASED for n in self.nodes.values())

    def explicit_turns_ahead(self) -> int:
        """How many turns of the line's explicit window the requests queued or in flight
        (all nodes) take: a request submitted now starts within that many."""
        # (a node's request in flight is one in the window: ExplicitJobs starts and ends both)
        backlog = sum(map(len, self.schedule.queues)) + len(self.schedule.explicit_busy)
        return -(-backlog // self._ctx.config.explicit_window)

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
            "cycle_time_ms": ms(f.cycle_last),
            "cycle_time_avg_ms": ms(avg),
            "cycle_time_max_ms": ms(f.cycle_max if f.cycles else None),
            "bus_conditions": dict(f.conditions),
            "duplicate_macs": {str(k): v for k, v in f.duplicate_macs.items()},
            "own_mac_claims": self._own_mac.claims,
            "own_mac_claims_unanswered": self._own_mac.unanswered,
            "online": len(self.online_macs()),
        }

    def node_diagnostics(self, mac: int) -> dict[str, Any]:
        node = self.nodes[mac]
        return {
            "mac": mac,
            "state": node.phase.value,
            "io": node.cfg.io.value,
            "ack": node.cfg.ack,
            "epr_ms": ms(node.epr) if node.epr else None,
            "vendor_id": node.vendor_id,
            "product_code": node.product_code,
            "product_name": node.product_name,
            **node.figures.to_json(),
        }

    def average_cycle(self) -> float | None:
        return self.line.cycle_sum / self.line.cycles if self.line.cycles else None

    # ------------------------------------------------------------ the steady lane

    def _steady_reply(self, node: Node, now: float, frame: CanFrame) -> bool:
        """A quiet node's poll response equal to its last inputs reported, taken by its bytes
        (docs/decisions/0097): what the full step does for it (the figures, the poll
        answered, the inputs reported when their refresh is due, the node's deadlines, the
        next polls), without matching and dispatching the frame or ticking the node, whose
        tick does nothing then. False, nothing done: the full step takes it (the inputs
        changed, a second answer to one poll, a node with more under way than its polls,
        a keep-alive due)."""
        ctx, config = self._ctx, self.config
        data = frame.data
        if (
            data != node.last_inputs
            or not node.poll_open
            or self.phase is not LinePhase.ONLINE
            or ctx.leaving
            or node.unconnected is not None
            or node.current is not None
            or node.queue
            or node.reassembler.deadline is not None
            or node.epr <= 0.0
            or now >= node.last_explicit + config.explicit_epr / 2
        ):
            return False
        schedule = self.schedule
        ctx.touched = node
        schedule.bringing = schedule.in_bringup
        ctx.tx_backoff = config.tx_backoff_min
        self._no_ack_reported = self._link_down_reported = False
        self.line.frames_rx += 1
        figures = node.figures
        figures.frames_rx += 1
        node.last_rx = now
        sent = schedule.in_flight.pop(node.mac, None)
        if sent is not None:
            figures.rtt(now - sent)
        node.poll_open = False
        if now >= node.inputs_due:  # the refresh of the unchanged inputs
            node.last_inputs, node.inputs_due = data, now + INPUTS_REFRESH
            ctx.out.append(InputData(node.mac, data))
        inactive = now + INACTIVITY_EPR_FACTOR * node.epr
        keep_alive = node.last_explicit + config.explicit_epr / 2
        ctx.fold((min(inactive, ctx.gated(keep_alive)),))
        self._timers.track_steady(node, inactive if inactive < keep_alive else keep_alive)
        schedule.after_frame(now)
        return True

    # ------------------------------------------------------------ deadlines

    def _recompute(self) -> None:
        ctx = self._ctx
        ctx.soonest = self._all_deadlines()
        if self.phase is LinePhase.ONLINE:
            self._timers.rebuild()

    def _lazy_step(self, now: float) -> bool:
        """Whether a timer step may look only at the nodes due or busy
        (:class:`SteadyTimers`): an online line, not leaving, no send hold."""
        ctx = self._ctx
        return (
            self.lazy_timers
            and self.phase is LinePhase.ONLINE
            and not ctx.leaving
            and now >= ctx.tx_hold_until
        )

    def _tick_due(self, now: float) -> None:
        """:meth:`_tick` for the nodes :meth:`SteadyTimers.due` gives (the others' ticks
        do nothing now)."""
        schedule = self.schedule
        schedule.bringing = schedule.bringups()
        ticks, idle, track = self._ticks, self.machine.idle_until, self._timers.track
        for node in self._timers.due(now):
            if not idle(node, now):
                ticks[node.phase](node, now)
            track(node)
        schedule.polls(now)

    def _recompute_due(self) -> None:
        """:meth:`_recompute` from the nodes not steady and the steady nodes' earliest
        idle time (a steady node's deadlines, :meth:`NodeMachine.soonest`, are its idle
        time when no send hold is on)."""
        schedule = self.schedule
        schedule.bringing = schedule.bringups()
        times = schedule.deadlines()
        soonest = self.machine.soonest
        for node in self._timers.unsteady_nodes():
            t = soonest(node)
            if t is not None:
                times.append(t)
        steady = self._timers.soonest()
        if steady is not None:
            times.append(steady)
        if self._own_mac.due_at is not None:
            times.append(self._own_mac.due_at)
        self._ctx.soonest = min(times) if times else None

    def _all_deadlines(self) -> float | None:
        self.schedule.bringing = self.schedule.bringups()
        times: list[float] = []
        if self.phase in _CHECKING:
            times.append(self._line_deadline)
        if self.phase is not LinePhase.ONLINE:
            return min(times) if times else None
        times.extend(self.schedule.deadlines())
        if self._own_mac.due_at is not None:
            times.append(self._own_mac.due_at)
        soonest = self.machine.soonest
        for node in self.nodes.values():
            t = soonest(node)
            if t is not None:
                times.append(t)
        return min(times) if times else None

    def _tick(self, now: float) -> None:
        if self.phase is not LinePhase.ONLINE:
            self._tick_line(now)
        if not self.online:
            return
        self.schedule.bringing = self.schedule.bringups()
        ticks = self._ticks
        idle = self.machine.idle_until
        for node in self.nodes.values():
            if not idle(node, now):  # a steady node with nothing due: its tick is a no-op
                ticks[node.phase](node, now)
        if not self._ctx.leaving:
            self.schedule.polls(now)

    def _after_event(self, now: float, event: Event) -> None:
        if not self.online or not isinstance(event, FrameIn):
            self._recompute()  # rare: line checks, bus errors, send failures
            return
        ctx = self._ctx
        node = ctx.touched
        if node is not None:
            self._ticks[node.phase](node, now)
            soonest = self.machine.soonest(node)
            if soonest is not None:
                ctx.fold((soonest,))
            self._timers.track(node)
        if not ctx.leaving:
            self.schedule.after_frame(now)

    # ------------------------------------------------------------ events

    def _on_event(self, now: float, event: Event) -> None:
        if isinstance(event, FrameIn):
            self._ctx.tx_backoff = self.config.tx_backoff_min
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
            if found.mac == self.config.mac and self.phase is LinePhase.ONLINE:
                self._on_own_mac_request(now, frame.data)
                return
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
        self._ctx.touched = node
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
            self._ctx.report(None, ReportKind.BUS, f"line: {names} (health {self.health.value})")
        recovered = before is LineHealth.BUS_OFF and self.health is not LineHealth.BUS_OFF
        if LineCondition.RESTARTED in conditions or recovered:
            self.machine.resume(now)  # every node without waiting its back-off

    def _on_tx_failed(self, now: float, event: TxFailed) -> None:
        ctx = self._ctx
        ctx.last_tx_failure = now
        self.line.tx_failures += 1
        self.line.tx_dropped += event.dropped
        self.line.last_tx_failure = event.reason
        if ctx.tx_backoff == self.config.tx_backoff_min:
            ctx.report(
                None,
                ReportKind.BUS,
                f"cannot send ({event.reason}): backing off {ctx.tx_backoff:g} s",
            )
        ctx.tx_hold_until = now + ctx.tx_backoff
        ctx.tx_backoff = min(2 * ctx.tx_backoff, self.config.tx_backoff_max)

    def _on_link_down(self, now: float, reason: str) -> None:
        """The interface is down: every connection is gone now, not after 4 x EPR. The
        nodes wait to be allocated again; the send hold paces the attempts."""
        self.line.link_down += 1
        if not self._link_down_reported:
            self._link_down_reported = True
            self._ctx.report(None, ReportKind.BUS, f"CAN interface down ({reason})")
        if not self.online or self._ctx.leaving:
            return
        self.machine.link_down(now, reason)

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
            self.machine.on_claim(now, check.mac)
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
            self._ctx.report(mac, ReportKind.DUPLICATE_MAC, text)

    def _on_own_mac_claimed(self, check: DupMacCheck) -> None:
        """A check message for the scanner's MAC while it runs its own check."""
        if self.phase in _CHECKING:
            self.phase = LinePhase.MAC_TAKEN
            text = (
                f"scanner MAC ID {self.config.mac} is taken on the line "
                f"({self._claimant(check)}): not going online"
            )
            self._ctx.report(None, ReportKind.DUPLICATE_MAC, text)
            self._ctx.out.append(LineFault(text))

    def _claimant(self, check: DupMacCheck) -> str:
        who = f"vendor 0x{check.vendor_id:04X} serial {check.serial_number}"
        if (check.vendor_id, check.serial_number) == (
            self.config.vendor_id,
            self.config.serial_number,
        ):
            who += ", this scanner's own identity: another instance of this gateway"
        return who

    def _on_own_mac_request(self, now: float, data: bytes) -> None:
        """A check message for the scanner's MAC once it is online: a request is answered
        at most once per ``ownmac.ANSWER_EVERY`` and reported at most once per
        ``ownmac.REPORT_EVERY`` with the count (:class:`OwnMacDefence`); the others cost
        a comparison and two counters. A response for it is nobody's to take notice of; a
        frame of another length is a bad frame, as before the line went online."""
        if not is_request(data):
            if len(data) != DUPMAC_LENGTH:
                self.line.bad_frames += 1
            return
        defence = self._own_mac
        answer, report = defence.claim(now, data)
        if answer:
            self._ctx.emit(self._dupmac_frame(DupMacKind.RESPONSE))
        if report:
            self._own_mac_report(now)
        elif defence.due_at is not None:
            self._ctx.fold((defence.due_at,))

    def _own_mac_report(self, now: float) -> None:
        """The report of the requests for the scanner's MAC since the last one."""
        check = DupMacCheck.decode_data(self.config.mac, self._own_mac.last)
        report = self._own_mac.report(now, self._claimant(check))
        self._ctx.report(None, ReportKind.DUPLICATE_MAC, report.text, **report.data)

    def _own_mac_due(self, now: float) -> None:
        """The requests for the scanner's MAC no report counted yet, once their time came."""
        due = self._own_mac.due_at
        if due is not None and now >= due:
            self._own_mac_report(now)

    def _tick_line(self, now: float) -> None:
        ctx, timeout = self._ctx, self.config.dupmac_timeout
        if self.phase is LinePhase.START:
            ctx.emit(self._dupmac_frame(DupMacKind.REQUEST))
            self.phase, self._line_deadline = LinePhase.CHECK_1, now + timeout
        elif self.phase is LinePhase.CHECK_1 and now >= self._line_deadline:
            ctx.emit(self._dupmac_frame(DupMacKind.REQUEST))
            self.phase, self._line_deadline = LinePhase.CHECK_2, now + timeout
        elif self.phase is LinePhase.CHECK_2 and now >= self._line_deadline:
            self.phase = LinePhase.ONLINE
            ctx.out.append(LineOnline())
            for node in self.nodes.values():
                node.retry_at = now
