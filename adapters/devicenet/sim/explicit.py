"""The simulated node's explicit messages, sans-IO: requests taken whole or reassembled from
fragments (each fragment acknowledged), replies sent whole or fragmented as the master
acknowledges (fact sheet 2.8), a malformed request answered with the general status its
decoder named, and replies lost as the fault injector says. The node decides what a
request means (:class:`~adapters.devicenet.sim.node.Cfw08Node`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from adapters.devicenet.codec.explicit import ErrorResponse, ExplicitMessage, Response
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    ExplicitReassembler,
    ExplicitSender,
    FragmentAck,
    decode_explicit_frame,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.errors import DeviceNetDecodeError, ExplicitDecodeError
from gateway.sim import FaultInjector


class Figures(Protocol):
    dropped: int  # replies (and I/O answers) lost on purpose


class ExplicitPort:
    """The explicit messages of one node (see the module docstring)."""

    def __init__(
        self, frame: Callable[[bytes], CanFrame], faults: FaultInjector, figures: Figures
    ) -> None:
        """``frame``: the node's explicit response frame with these data."""
        self.frame = frame
        self.faults = faults
        self.figures = figures
        self._reassembler = ExplicitReassembler()
        self._sender: ExplicitSender | None = None

    def receive(self, now: float, data: bytes, out: list[CanFrame]) -> bytes | None:
        """A frame of the explicit connection: the request it completes (its bytes), or
        None (an acknowledge, a fragment of a request not complete yet, a bad frame)."""
        try:
            frame = decode_explicit_frame(data)
        except DeviceNetDecodeError:
            return None
        if isinstance(frame, FragmentAck):
            self._acknowledged(now, frame, out)
            return None
        if isinstance(frame, ExplicitFragment):
            return self._fragment(now, frame, out)
        return frame.message

    def _acknowledged(self, now: float, ack: FragmentAck, out: list[CanFrame]) -> None:
        sender = self._sender
        if sender is None:
            return
        try:
            nxt = sender.on_ack(now, ack)
        except DeviceNetDecodeError:
            self._sender = None
            return
        if nxt is not None:
            out.append(self.frame(nxt))
        if sender.done:
            self._sender = None

    def _fragment(
        self, now: float, fragment: ExplicitFragment, out: list[CanFrame]
    ) -> bytes | None:
        try:
            step = self._reassembler.feed(now, fragment)
        except DeviceNetDecodeError:
            return None
        if step.ack is not None:
            out.append(self.frame(step.ack.encode()))
        return step.message

    def refuse(self, exc: ExplicitDecodeError, out: list[CanFrame]) -> None:
        """A malformed request gets the general status its decoder named (0x13, 0x15...)."""
        if exc.general_status is None or exc.mac is None or exc.xid is None:
            return
        reply = ExplicitMessage(exc.mac, exc.xid, ErrorResponse(exc.general_status))
        out.append(self.frame(reply.encode()))

    def reply(
        self, now: float, out: list[CanFrame], request: ExplicitMessage, body: Response
    ) -> None:
        if self.faults.drop():
            self.figures.dropped += 1
            return
        raw = request.reply(body).encode()
        sender = ExplicitSender(raw)
        first = sender.start(now)
        if sender.fragmented:
            self._sender = sender  # the rest goes out as the master acknowledges (2.8)
        out.append(self.frame(first))

    def deadline(self) -> float | None:
        """The earliest of the reassembly's and the fragmented reply's timeouts."""
        times = [self._reassembler.deadline]
        if self._sender is not None:
            times.append(self._sender.deadline)
        due = [t for t in times if t is not None]
        return min(due) if due else None

    def expire(self, now: float) -> None:
        """A request or a reply not completed in time is dropped."""
        if self._reassembler.deadline is not None and now >= self._reassembler.deadline:
            self._reassembler.reset()
        if self._sender is not None and self._sender.deadline and now >= self._sender.deadline:
            self._sender = None

    def reset(self) -> None:
        """The explicit connection is gone: nothing under way."""
        self._reassembler.reset()
        self._sender = None
