"""The scanner's per-node state machine: allocation, connection set-up, I/O and loss.

A handler table acts on each :class:`Phase` at every timer step. Allocate and Release go
on the unconnected port (G2 message 6, fact sheet 2.5), one per ``request_spacing``;
the bring-up reads the Identity object (2.12), checks the I/O sizes (2.9 attributes 7
and 8) and sets the EPRs (2.9 attribute 9) through the explicit job queue; once online,
the node's I/O comes in as poll responses or COS/cyclic productions (our own
production acknowledged, 2.8 fragments reassembled), and inactivity at 4 x EPR (2.9)
takes it offline. A node that fails is tried again with a growing back-off, at once
when its own Duplicate MAC ID check shows it starting up (2.3).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from adapters.devicenet.codec.cip import (
    DEVICENET_ADDITIONAL_CODE_TEXT,
    NO_ADDITIONAL_CODE,
    AllocationRejection,
    CipClass,
    allocation_rejection,
)
from adapters.devicenet.codec.datatypes import (
    CipType,
    decode_short_string,
    decode_value,
    encode_value,
)
from adapters.devicenet.codec.explicit import (
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
    error_text,
)
from adapters.devicenet.codec.fragment import UNFRAGMENTED_MAX
from adapters.devicenet.codec.ids import PredefinedMessage
from adapters.devicenet.codec.objects import (
    INACTIVITY_EPR_FACTOR,
    AllocationChoice,
    ConnectionAttribute,
    ConnectionInstance,
    IdentityAttribute,
)
from adapters.devicenet.errors import (
    DataTypeDecodeError,
    DeviceNetDecodeError,
    FragmentationError,
)
from adapters.devicenet.scanner.context import LineContext
from adapters.devicenet.scanner.events import (
    InputData,
    IoConflict,
    IoKind,
    NodeDown,
    NodeIdentity,
    NodeUp,
    ReportKind,
)
from adapters.devicenet.scanner.jobs import ExplicitJobs
from adapters.devicenet.scanner.node import (
    EXPLICIT_PHASES,
    Node,
    Pending,
    Phase,
    Purpose,
    Unconnected,
)
from adapters.devicenet.scanner.scheduler import Scheduler

Check = Callable[[Node, bytes], str | None]


@dataclass(frozen=True, slots=True)
class _Step:
    label: str
    request: Request
    check: Check


# Phases in which a node's own Duplicate MAC ID check means "allocate it when it is done".
_CLAIM_PHASES = (Phase.WAITING, Phase.REFUSED, Phase.ALLOCATING, Phase.CONFIGURING)
CLAIM_MARGIN = 0.1  # of a check period, after the node's check is expected to end
EXPLICIT_LOST_AFTER = 2  # explicit requests in a row unanswered: allocate explicit again
INPUTS_REFRESH = 1.0  # s: unchanged inputs of a quiet node reported at least this often (0102)


class NodeMachine:
    """Every configured node's way from waiting to online and back."""

    def __init__(self, ctx: LineContext, schedule: Scheduler, jobs: ExplicitJobs) -> None:
        self.ctx = ctx
        self.schedule = schedule
        self.jobs = jobs
        jobs.on_unconnected_reply = self._on_unconnected_reply
        jobs.on_missed = self._explicit_missed
        # the node's timers, as its phase has them: ticks[node.phase](node, now)
        self.ticks: dict[Phase, Callable[[Node, float], None]] = {
            Phase.WAITING: self._tick_waiting,
            Phase.ALLOCATING: self._tick_unconnected,
            Phase.RELEASING: self._tick_unconnected,
            Phase.LEAVING: self._tick_unconnected,
            Phase.CONFIGURING: self.jobs.tick,
            Phase.ONLINE: self._tick_online,
            Phase.REFUSED: self._tick_refused,
            Phase.RELEASED: _nothing,
        }

    @staticmethod
    def steady(node: Node) -> bool:
        """Online, polled, and nothing under way but its polls: its only timers are the
        inactivity and the keep-alive (what :meth:`deadlines` gives it then)."""
        return (
            node.phase is Phase.ONLINE
            and node.cfg.io is IoKind.POLLED
            and node.unconnected is None
            and node.current is None
            and not node.queue
            and node.reassembler.deadline is None
            and node.io_reassembler.deadline is None
        )

    def soonest(self, node: Node) -> float | None:
        """``min(deadlines(node))``, or None: a steady node's two timers without the list
        (the scanner takes it for every node on each timer step)."""
        if self.steady(node):
            ctx = self.ctx
            return min(
                node.last_rx + INACTIVITY_EPR_FACTOR * node.epr,
                ctx.gated(node.last_explicit + ctx.config.explicit_epr / 2),
            )
        times = self.deadlines(node)
        return min(times) if times else None

    def idle_until(self, node: Node, now: float) -> bool:
        """A steady node whose tick at ``now`` would do nothing: neither its inactivity
        nor its keep-alive (ungated: the tick queues it whatever the send hold) has come."""
        return self.steady(node) and now < self.idle_time(node)

    def idle_time(self, node: Node) -> float:
        """When a steady node's tick first does something: the earlier of its inactivity
        and its keep-alive, ungated (:meth:`idle_until`)."""
        inactive = node.last_rx + INACTIVITY_EPR_FACTOR * node.epr
        keep_alive = node.last_explicit + self.ctx.config.explicit_epr / 2
        return inactive if inactive < keep_alive else keep_alive

    def deadlines(self, node: Node) -> list[float]:
        """The node's timers; those that lead to a send are gated by the send hold."""
        ctx = self.ctx
        out: list[float] = []
        gated = ctx.gated
        waiting = node.phase in (Phase.WAITING, Phase.REFUSED) and not ctx.leaving
        if waiting and self.schedule.bringup_free():
            out.append(gated(max(node.retry_at, ctx.request_slot)))
        if node.unconnected is not None:
            out.append(node.unconnected.deadline)
        elif node.phase is Phase.LEAVING:
            out.append(gated(ctx.request_slot))
        if node.current is not None:
            out.append(node.current.deadline)
        elif node.queue and node.phase in EXPLICIT_PHASES and self.schedule.explicit_turn(node):
            out.append(gated(0.0))
        deadline = node.reassembler.deadline
        if deadline is not None:
            out.append(deadline)
        if node.phase is Phase.ONLINE and node.io_reassembler.deadline is not None:
            out.append(node.io_reassembler.deadline)
        if node.phase is Phase.ONLINE:
            out.append(node.last_rx + INACTIVITY_EPR_FACTOR * node.epr)
            if not node.queue and node.current is None:  # a keep-alive only when idle
                out.append(gated(node.last_explicit + ctx.config.explicit_epr / 2))
            if node.cfg.io is not IoKind.POLLED:
                out.append(gated(node.last_output_sent + node.epr))
                if node.cfg.io is IoKind.COS and node.output != node.sent_output:
                    out.append(gated(0.0))
                if node.ack_deadline is not None:
                    out.append(node.ack_deadline)
        return out

    # ------------------------------------------------------------ line-wide

    def leave(self, now: float) -> None:
        """Shutdown: every allocated node gets its Release in turn (request_spacing)."""
        for node in self.ctx.nodes.values():
            self.jobs.fail(node, "scanner leaving the line")
            if node.phase in (Phase.CONFIGURING, Phase.ONLINE, Phase.ALLOCATING, Phase.RELEASING):
                node.unconnected = None  # an Allocate in flight is abandoned
                self.schedule.enter(node, Phase.LEAVING)  # its Release goes out in turn
            elif node.phase is not Phase.LEAVING:
                self.schedule.enter(node, Phase.RELEASED)
        for node in self.ctx.nodes.values():
            if node.phase is Phase.LEAVING:
                self._tick_unconnected(node, now)

    def resume(self, now: float) -> None:
        """The line is back (restarted, or out of bus-off): every node resumes without
        waiting for its back-off."""
        for node in self.ctx.nodes.values():
            node.backoff = self.ctx.config.retry_min
            if node.phase in (Phase.WAITING, Phase.REFUSED):
                node.retry_at = now

    def link_down(self, now: float, reason: str) -> None:
        """The interface is down: every connection is gone now, not after 4 x EPR."""
        for node in self.ctx.nodes.values():
            if node.phase in (Phase.ONLINE, Phase.CONFIGURING):
                self.node_down(node, now, f"CAN interface down ({reason})")
                node.retry_at = now
                node.backoff = self.ctx.config.retry_min
            elif node.phase is Phase.ALLOCATING:
                self._retry_later(node, now)

    def on_claim(self, now: float, mac: int) -> None:
        """A Duplicate MAC ID request for a configured node's MAC: the node has just
        started (power-up, reset, bus-off recovery) and answers an Allocate once its
        check is over (fact sheet 2.3: two requests, 1 s apart). A node that is not
        online with us is then allocated at once, whatever its back-off.

        An online node's MAC claimed is left alone: either another device claims it
        (the node answers, and the duplicate is reported) or the node restarted, and
        its inactivity says so within 4 x EPR.
        """
        ctx = self.ctx
        node = ctx.nodes.get(mac)
        if node is None or ctx.leaving or node.phase not in _CLAIM_PHASES:
            return
        period = ctx.config.dupmac_timeout
        if now >= node.checking_until:  # a new check: it ends two periods after its start
            node.checking_until = now + 2 * period
        else:  # its second request: one period to go
            node.checking_until = max(node.checking_until, now + period)
        node.backoff = ctx.config.retry_min
        if node.phase in (Phase.WAITING, Phase.REFUSED):
            node.retry_at = node.checking_until + CLAIM_MARGIN * period
            ctx.touched = node

    # ------------------------------------------------------------ phase ticks

    def _tick_waiting(self, node: Node, now: float) -> None:
        ctx = self.ctx
        if ctx.leaving or now < node.retry_at or now < ctx.request_slot:
            return
        if self.schedule.bringup_free() and ctx.tx_ok(now):
            self._start_allocate(node, now)

    def _tick_refused(self, node: Node, now: float) -> None:
        if node.unconnected is not None and now >= node.unconnected.deadline:
            node.unconnected = None
        self._tick_waiting(node, now)

    def _tick_unconnected(self, node: Node, now: float) -> None:
        pending = node.unconnected
        if pending is None and node.phase is Phase.LEAVING:  # its Release is due
            if now >= self.ctx.request_slot and self.ctx.tx_ok(now):
                self._start_release(node, now, Purpose.RELEASE)
            return
        if pending is None or now < pending.deadline:
            return
        node.unconnected = None
        if pending.purpose is Purpose.RELEASE:
            self.schedule.enter(node, Phase.RELEASED)
            return
        if node.problem(f"no answer to {pending.purpose.value}"):
            self.ctx.report(
                node.mac,
                ReportKind.TIMEOUT,
                f"node {node.mac}: no answer to {pending.purpose.value}",
            )
        self._retry_later(node, now)

    def _tick_online(self, node: Node, now: float) -> None:
        if now >= node.last_rx + INACTIVITY_EPR_FACTOR * node.epr:
            window = INACTIVITY_EPR_FACTOR * node.epr
            self.node_down(node, now, f"no data for {window:g} s (4 x EPR)")
            node.retry_at = now
            self._tick_waiting(node, now)  # allocate it again as soon as it answers
            return
        if node.unconnected is not None and now >= node.unconnected.deadline:
            node.unconnected = None  # an explicit re-allocation unanswered: the next miss retries
        idle = not node.queue and node.current is None
        if idle and now >= node.last_explicit + self.ctx.config.explicit_epr / 2:
            # keep the explicit connection alive: read the Identity status
            get = GetAttributeSingle(CipClass.IDENTITY, 1, IdentityAttribute.STATUS)
            node.queue.append(Pending(get, on_done=_ignore, label="keep-alive"))
        self.jobs.tick(node, now)
        if node.cfg.io is not IoKind.POLLED:
            self._tick_production(node, now)

    # ------------------------------------------------------------ allocation (2.5)

    def _start_allocate(self, node: Node, now: float) -> None:
        if node.figures.allocations or node.figures.last_problem is not None:
            node.figures.retries += 1
        node.attempt_started = now
        self.schedule.bringing += 1
        c = self.ctx.config
        body = AllocateConnectionSet(node.cfg.choice, c.mac)
        self._start_unconnected(node, now, body, Purpose.ALLOCATE, c.allocate_timeout)
        self.schedule.enter(node, Phase.ALLOCATING)

    def _start_release(self, node: Node, now: float, purpose: Purpose) -> None:
        body = ReleaseConnectionSet(node.cfg.choice)
        self._start_unconnected(node, now, body, purpose, self.ctx.config.explicit_timeout)
        self.schedule.enter(node, _RELEASE_PHASE[purpose])

    def _start_unconnected(
        self,
        node: Node,
        now: float,
        body: AllocateConnectionSet | ReleaseConnectionSet,
        purpose: Purpose,
        timeout: float,
    ) -> None:
        ctx = self.ctx
        message = ExplicitMessage(ctx.config.mac, node.next_xid(), body)
        ctx.send(node, PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST, message.encode())
        node.unconnected = Unconnected(message, purpose, now + timeout)
        ctx.request_slot = now + ctx.config.request_spacing

    def _on_unconnected_reply(self, node: Node, now: float, body: Response) -> None:
        pending = node.unconnected
        node.unconnected = None
        if pending is None:
            return
        if pending.purpose is Purpose.EXPLICIT_AGAIN:
            self._on_explicit_again(node, body)
        elif pending.purpose is Purpose.RELEASE:
            self.schedule.enter(node, Phase.RELEASED)
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

    def _explicit_missed(self, node: Node, now: float) -> None:
        """Explicit requests to an online node go unanswered while its polls are answered:
        its explicit connection has most likely been deleted (auto delete after 4 x EPR
        of silence, fact sheet 2.9), e.g. after the requests waited too long for the
        window on a slow machine. Allocate it again on its own (the node is ours: the
        I/O connection stays) instead of leaving the node without parameter access."""
        if node.phase is not Phase.ONLINE or node.unconnected is not None:
            return
        if node.explicit_misses < EXPLICIT_LOST_AFTER or not self.ctx.tx_ok(now):
            return
        text = (
            f"node {node.mac}: {node.explicit_misses} explicit requests unanswered: "
            "allocating its explicit connection again"
        )
        if node.problem(text):
            self.ctx.report(node.mac, ReportKind.TIMEOUT, text)
        body = AllocateConnectionSet(AllocationChoice.EXPLICIT, self.ctx.config.mac)
        timeout = self.ctx.config.allocate_timeout
        self._start_unconnected(node, now, body, Purpose.EXPLICIT_AGAIN, timeout)

    def _on_explicit_again(self, node: Node, body: Response) -> None:
        """The reply to an explicit re-allocation: allocated (set its EPR first), or
        already allocated (it was alive, only slow); anything else waits for the next miss."""
        if isinstance(body, AllocateResponse):
            node.explicit_misses = 0
            node.figures.explicit_reallocations += 1
            set_epr = self._set_explicit_epr()
            node.queue.appendleft(Pending(set_epr, on_done=_ignore, label="explicit EPR"))
        elif isinstance(body, ErrorResponse):
            rejection = allocation_rejection(body.general_status, body.additional_code)
            if rejection is AllocationRejection.ALREADY_ALLOCATED:
                node.explicit_misses = 0

    def _on_allocated(self, node: Node, now: float, body: AllocateResponse) -> None:
        if body.body_format not in (None, BodyFormat.CLASS8_INSTANCE8):
            self._bringup_failed(
                node, now, f"node uses message body format {body.message_body_format} (8/8 only)"
            )
            return
        node.figures.allocations += 1
        node.released_before_allocate = False
        self.schedule.enter(node, Phase.CONFIGURING)
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
            self.ctx.report(
                node.mac,
                ReportKind.ALLOCATION,
                text,
                general_status=err.general_status,
                additional_code=err.additional_code,
            )
        self._retry_later(node, now)

    def _retry_later(self, node: Node, now: float) -> None:
        ctx = self.ctx
        node.unconnected = None
        node.released_before_allocate = False
        self.schedule.enter(node, Phase.WAITING)
        failed = ctx.last_tx_failure
        if failed is not None and failed >= node.attempt_started:
            # The line could not send during this attempt (buffer full, bus-off, link
            # down): not the node's fault, so its back-off does not grow; the send hold
            # already paces the attempts.
            node.backoff = ctx.config.retry_min
        node.retry_at = now + node.backoff
        node.backoff = min(2 * node.backoff, ctx.config.retry_max)
        if node.checking_until > now:  # it is running its Duplicate MAC ID check
            node.retry_at = node.checking_until + CLAIM_MARGIN * ctx.config.dupmac_timeout
        self.jobs.fail(node, "node not online")

    # ------------------------------------------------------------ bring-up steps

    def _setup_steps(self, node: Node) -> Iterable[_Step]:
        """The bring-up's requests in turn. The explicit connection's EPR is set first: until
        then the node deletes the connection after 4 x its default EPR of silence (2.5 s:
        10 s, fact sheet 2.9), which a bring-up waiting its turns on a busy line can pass."""
        yield _Step("explicit EPR", self._set_explicit_epr(), _accept)
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
        yield _Step("I/O EPR", SetAttributeSingle(conn, io, epr, _epr_ms(node.cfg.epr)), _set_epr)

    def _set_explicit_epr(self) -> SetAttributeSingle:
        """Set the explicit connection's EPR to ``explicit_epr`` (fact sheet 2.9)."""
        epr = ConnectionAttribute.EXPECTED_PACKET_RATE
        ms = _epr_ms(self.ctx.config.explicit_epr)
        return SetAttributeSingle(CipClass.CONNECTION, ConnectionInstance.EXPLICIT, epr, ms)

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
        self.schedule.enter(node, Phase.ONLINE)
        node.output = b""  # every bring-up starts idle: no command from before it (rule 1)
        node.backoff = self.ctx.config.retry_min
        node.last_rx = now
        node.sent_output = None
        node.last_output_sent = 0.0
        node.poll_open = False
        node.ack_deadline = None
        node.figures.last_problem = None
        identity = NodeIdentity(node.vendor_id, node.product_code, node.product_name)
        self.ctx.out.append(NodeUp(node.mac, identity, node.epr))

    def _bringup_failed(self, node: Node, now: float, text: str) -> None:
        full = f"node {node.mac}: bring-up failed: {text}"
        if node.problem(full):
            self.ctx.report(node.mac, ReportKind.PROTOCOL, full)
        self._retry_later(node, now)

    def _refuse(self, node: Node, now: float, text: str) -> None:
        """Identity or size mismatch: report, release, refuse I/O, try again later."""
        kind = ReportKind.SIZE if "size" in text else ReportKind.IDENTITY
        full = f"node {node.mac}: {text}: I/O refused"
        if node.problem(full):
            self.ctx.report(node.mac, kind, full)
        self.jobs.fail(node, "I/O refused")
        self._start_release(node, now, Purpose.RELEASE_REFUSED)
        node.retry_at = now + self.ctx.config.retry_max

    # ------------------------------------------------------------ I/O

    def on_poll_response(self, node: Node, now: float, data: bytes) -> None:
        if node.cfg.io is not IoKind.POLLED:
            if node.ack_deadline is not None:  # the acknowledge of our production
                node.figures.rtt(now - node.last_output_sent)
                node.ack_deadline = None
            return
        message = self._io_message(node, now, data)
        if message is None:
            return
        sent = self.schedule.answered(node.mac)
        if sent is not None:
            node.figures.rtt(now - sent)
        if not node.poll_open and node.phase is Phase.ONLINE:
            # One poll, one response (fact sheet 2.10 step 7): a second answer, or one
            # before any poll, comes from another station with the node's identifier.
            # Which one is the node's cannot be told: this one is not delivered, and the
            # node's readings are doubtful (the adapter's decision, issue 32 item 12).
            node.figures.io_conflicts += 1
            self.ctx.out.append(IoConflict(node.mac, message, node.figures.io_conflicts))
            return
        node.poll_open = False  # (a late answer to a timed out poll is still its answer)
        self._deliver(node, now, message)

    def on_production(self, node: Node, now: float, data: bytes) -> None:
        if node.cfg.io is IoKind.POLLED:
            node.figures.bad_frames += 1
            return
        message = self._io_message(node, now, data)
        if message is None:
            return
        if node.cfg.ack and node.phase is Phase.ONLINE:
            self.ctx.send(node, PredefinedMessage.MASTER_COS_CYCLIC_ACK, b"")
        self._deliver(node, now, message)

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

    def _deliver(self, node: Node, now: float, data: bytes) -> None:
        """A node's whole input message, as :class:`InputData` when it changed, when the
        adapter has not said it is quiet, and at least every :data:`INPUTS_REFRESH` s (a
        quiet adapter's outputs and readings depend on nothing but the inputs and what it
        is told otherwise: docs/decisions/0097)."""
        if node.phase is not Phase.ONLINE:
            return
        if len(data) != node.cfg.produced_size:
            node.figures.bad_frames += 1
            return
        if node.quiet and data == node.last_inputs and now < node.inputs_due:
            return
        node.last_inputs = data
        node.inputs_due = now + INPUTS_REFRESH
        self.ctx.out.append(InputData(node.mac, data))

    def _tick_production(self, node: Node, now: float) -> None:
        """Our change-of-state / cyclic production to the node, and its acknowledge."""
        if node.ack_deadline is not None and now >= node.ack_deadline:
            node.figures.ack_timeouts += 1
            node.ack_deadline = None
            if not node.ack_retried and self.ctx.tx_ok(now):
                node.ack_retried = True
                self._produce(node, now)
                return
        changed = node.cfg.io is IoKind.COS and node.output != node.sent_output
        if (changed or now >= node.last_output_sent + node.epr) and self.ctx.tx_ok(now):
            node.ack_retried = False
            self._produce(node, now)

    def _produce(self, node: Node, now: float) -> None:
        self.ctx.send_io(node, node.output)
        node.sent_output = node.output
        node.last_output_sent = now
        if node.cfg.ack:
            node.ack_deadline = now + self.ctx.config.response_timeout

    def node_down(self, node: Node, now: float, reason: str) -> None:
        self.jobs.fail(node, f"node went offline: {reason}")
        self.schedule.forget(node.mac)
        self.schedule.enter(node, Phase.WAITING)
        node.unconnected = None
        node.figures.offline_count += 1
        node.problem(reason)
        self.ctx.out.append(NodeDown(node.mac, reason))


# ---------------------------------------------------------------- module helpers


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
