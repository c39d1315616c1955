"""The scanner's explicit-message job queue: the requests for each node's explicit
connection, from outside (a token, answered with an ExplicitResult) or from the node's
own bring-up and keep-alive (a callback).

One request in flight per node (Group 2 Only, fact sheet 2.4), at most
``explicit_window`` on the line (the scheduler); requests and responses longer than a
frame are fragmented and acknowledged (2.8); a request not answered within
``explicit_timeout`` ends as timed out.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

from adapters.devicenet.codec.explicit import (
    AllocateResponse,
    ErrorResponse,
    ExplicitMessage,
    Request,
    Response,
    SuccessResponse,
)
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    ExplicitSender,
    FragmentAck,
    Unfragmented,
    decode_explicit_frame,
)
from adapters.devicenet.codec.ids import PredefinedMessage
from adapters.devicenet.errors import DeviceNetDecodeError, FragmentationError
from adapters.devicenet.scanner.context import LineContext
from adapters.devicenet.scanner.events import ExplicitResult
from adapters.devicenet.scanner.node import EXPLICIT_PHASES, Node, Pending, Transaction
from adapters.devicenet.scanner.scheduler import Scheduler
from gateway.errors import FrameEncodeError

MAC_MASK = 0x3F
_RESPONSES = (SuccessResponse, AllocateResponse, ErrorResponse)

UnconnectedReply = Callable[[Node, float, Response], None]
Missed = Callable[[Node, float], None]


class ExplicitJobs:
    """Queued explicit requests per node, the one in flight, and how each one ends."""

    def __init__(self, ctx: LineContext, schedule: Scheduler) -> None:
        self.ctx = ctx
        self.schedule = schedule
        self._tokens = itertools.count(1)
        # where a reply to an Allocate/Release on the unconnected port goes (the node
        # state machine sets it): it comes back on the explicit response message
        self.on_unconnected_reply: UnconnectedReply = _unexpected
        # a request that timed out (the node state machine decides what that means)
        self.on_missed: Missed = _missed

    def submit(self, node: Node, body: Request) -> int:
        """Queue an external request; its :class:`ExplicitResult` carries the token."""
        token = next(self._tokens)
        node.queue.append(Pending(body, token=token))
        self.ctx.wake()
        return token

    def tick(self, node: Node, now: float) -> None:
        """The request in flight timing out, reassembly timers, and the next request."""
        current = node.current
        if current is not None and now >= current.deadline:
            self.end(node)
            node.reassembler.reset()
            node.figures.explicit_timeouts += 1
            timeout = self.ctx.config.explicit_timeout
            text = f"no response within {timeout:g} s"
            self.complete(node, now, current.pending, None, text, timed_out=True)
            node.explicit_misses += 1
            self.on_missed(node, now)
        for reassembler in (node.reassembler, node.io_reassembler):
            if reassembler.deadline is not None and now >= reassembler.deadline:
                try:
                    reassembler.tick(now)
                except FragmentationError:
                    node.figures.bad_frames += 1
        if (
            node.current is None
            and node.queue
            and self.schedule.explicit_turn(node)
            and self.ctx.tx_ok(now)
        ):
            self._start(node, now, node.queue.popleft())

    def end(self, node: Node) -> None:
        """The node's explicit request is over; a node waiting for the window may go."""
        node.current = None
        self.schedule.explicit_ended(node.mac)

    def _start(self, node: Node, now: float, pending: Pending) -> None:
        ctx = self.ctx
        message = ExplicitMessage(ctx.config.mac, node.next_xid(), pending.body)
        try:
            sender = ExplicitSender(message.encode(), ack_timeout=ctx.config.explicit_timeout)
        except FrameEncodeError as exc:
            self.complete(node, now, pending, None, f"cannot encode the request: {exc}")
            return
        ctx.send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, sender.start(now))
        node.current = Transaction(pending, message, sender, now, now + ctx.config.explicit_timeout)
        self.schedule.explicit_started(node.mac)
        node.last_explicit = now

    # ------------------------------------------------------------ responses

    def on_frame(self, node: Node, now: float, data: bytes) -> None:
        """A frame on the node's explicit response message."""
        if not data or data[0] & MAC_MASK != self.ctx.config.mac:
            self.ctx.figures.foreign_frames += 1  # a response to another master
            return
        try:
            frame = decode_explicit_frame(data)
        except DeviceNetDecodeError:
            node.figures.bad_frames += 1
            return
        if isinstance(frame, FragmentAck):
            self._on_fragment_ack(node, now, frame)
        elif isinstance(frame, Unfragmented):
            self._on_message(node, now, frame.message)
        elif node.phase in EXPLICIT_PHASES:
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
            self.end(node)
            self.complete(node, now, current.pending, None, f"fragment refused: {exc}")
            return
        if nxt is not None:
            self.ctx.send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, nxt)
            current.deadline = now + self.ctx.config.explicit_timeout

    def _on_fragment(self, node: Node, now: float, fragment: ExplicitFragment) -> None:
        try:
            step = node.reassembler.feed(now, fragment)
        except FragmentationError:
            node.figures.bad_frames += 1
            return
        if step.ack is not None:
            self.ctx.send(node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, step.ack.encode())
        if node.current is not None:
            node.current.deadline = now + self.ctx.config.explicit_timeout
        if step.message is not None:
            self._on_message(node, now, step.message)

    def _on_message(self, node: Node, now: float, raw: bytes) -> None:
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
            self.on_unconnected_reply(node, now, body)
            return
        current = node.current
        if current is None or not message.answers(current.message):
            node.figures.stale_responses += 1
            return
        self.end(node)
        node.explicit_misses = 0
        node.figures.explicit_rtt_last = now - current.started
        self.complete(node, now, current.pending, body, None)

    # ------------------------------------------------------------ endings

    def complete(
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
            self.ctx.out.append(ExplicitResult(pending.token, node.mac, response, error, timed_out))

    def fail(self, node: Node, why: str) -> None:
        """Every request of the node ends unanswered (the node or the scanner left)."""
        pendings = list(node.queue)
        node.queue.clear()
        if node.current is not None:
            pendings.insert(0, node.current.pending)
            self.end(node)
        node.reassembler.reset()
        for pending in pendings:
            if pending.token is not None:
                self.ctx.out.append(ExplicitResult(pending.token, node.mac, None, why))


def _unexpected(_node: Node, _now: float, _body: Response) -> None:
    return None


def _missed(_node: Node, _now: float) -> None:
    """No reaction to a timed-out request until the node state machine sets one."""
