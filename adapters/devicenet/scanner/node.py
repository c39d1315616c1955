"""Per-node state of the scanner engine: phase, explicit channel, I/O timing, figures."""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from adapters.can.events import Send
from adapters.devicenet.codec.explicit import ExplicitMessage, Request, Response
from adapters.devicenet.codec.fragment import ExplicitReassembler, ExplicitSender, IoReassembler
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.scanner.events import NodeConfig


class Phase(Enum):
    """Where a node is in its bring-up (a handler table in the engine acts on each)."""

    WAITING = "waiting"  # scanner offline, or backing off until retry_at
    ALLOCATING = "allocating"  # Allocate sent on the unconnected port
    RELEASING = "releasing"  # Release sent after "already allocated", then allocate again
    CONFIGURING = "configuring"  # identity, sizes, EPR
    ONLINE = "online"  # I/O running
    REFUSED = "refused"  # identity or size mismatch: released, I/O refused, retrying slowly
    LEAVING = "leaving"  # Release sent on shutdown
    RELEASED = "released"


EXPLICIT_PHASES = (Phase.CONFIGURING, Phase.ONLINE)  # an explicit connection is open

Done = Callable[[float, Response | None, str | None], None]  # (now, response, error)

# every request numbered as it is queued: the line's explicit window serves them in this
# order, whichever node they are for (Scheduler.explicit_turn)
_QUEUED = itertools.count()


@dataclass(slots=True)
class Pending:
    """A queued explicit request: external (``token``) or internal (``on_done``)."""

    body: Request
    token: int | None = None
    on_done: Done | None = None
    label: str = ""
    order: int = field(default_factory=_QUEUED.__next__)  # when it was queued


@dataclass(slots=True)
class Transaction:
    """The explicit request in flight (one per node: Group 2 Only, fact sheet 2.4)."""

    pending: Pending
    message: ExplicitMessage
    sender: ExplicitSender
    started: float
    deadline: float


class Purpose(Enum):
    ALLOCATE = "allocate"
    RELEASE_THEN_ALLOCATE = "release before allocate"
    RELEASE = "release"
    RELEASE_REFUSED = "release (I/O refused)"
    EXPLICIT_AGAIN = "allocate explicit again"


@dataclass(slots=True)
class Unconnected:
    """An Allocate or Release on G2 message 6 awaiting its reply."""

    message: ExplicitMessage
    purpose: Purpose
    deadline: float


@dataclass(slots=True)
class NodeFigures:
    """Diagnostics of one node."""

    allocations: int = 0
    retries: int = 0
    poll_timeouts: int = 0
    explicit_timeouts: int = 0
    explicit_ok: int = 0
    explicit_errors: int = 0
    explicit_reallocations: int = 0
    ack_timeouts: int = 0
    offline_count: int = 0
    frames_tx: int = 0
    frames_rx: int = 0
    bad_frames: int = 0
    stale_responses: int = 0
    io_conflicts: int = 0  # poll responses beyond one per poll (issue 32 item 12)
    rtt_last: float | None = None
    rtt_max: float = 0.0
    rtt_sum: float = 0.0
    rtt_count: int = 0
    explicit_rtt_last: float | None = None
    last_problem: str | None = None

    def rtt(self, seconds: float) -> None:
        self.rtt_last = seconds
        self.rtt_max = max(self.rtt_max, seconds)
        self.rtt_sum += seconds
        self.rtt_count += 1

    def to_json(self) -> dict[str, Any]:
        avg = self.rtt_sum / self.rtt_count if self.rtt_count else None
        return {
            "allocations": self.allocations,
            "retries": self.retries,
            "timeouts": self.poll_timeouts + self.explicit_timeouts + self.ack_timeouts,
            "poll_timeouts": self.poll_timeouts,
            "explicit_timeouts": self.explicit_timeouts,
            "ack_timeouts": self.ack_timeouts,
            "explicit_ok": self.explicit_ok,
            "explicit_errors": self.explicit_errors,
            "explicit_reallocations": self.explicit_reallocations,
            "offline_count": self.offline_count,
            "frames_tx": self.frames_tx,
            "frames_rx": self.frames_rx,
            "errors": self.bad_frames,
            "stale_responses": self.stale_responses,
            "io_conflicts": self.io_conflicts,
            "response_time_ms": _ms(self.rtt_last),
            "response_time_avg_ms": _ms(avg),
            "response_time_max_ms": _ms(self.rtt_max if self.rtt_count else None),
            "explicit_response_time_ms": _ms(self.explicit_rtt_last),
            "last_problem": self.last_problem,
        }


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000.0, 3)


@dataclass(slots=True)
class Node:
    """Everything the engine keeps about one configured node."""

    cfg: NodeConfig
    backoff: float
    phase: Phase = Phase.WAITING
    retry_at: float = 0.0
    attempt_started: float = 0.0  # when the current allocation attempt began
    checking_until: float = 0.0  # when the node's own Duplicate MAC ID check should end
    xid: bool = False
    unconnected: Unconnected | None = None
    released_before_allocate: bool = False
    queue: deque[Pending] = field(default_factory=deque)
    current: Transaction | None = None
    reassembler: ExplicitReassembler = field(default_factory=ExplicitReassembler)
    io_reassembler: IoReassembler = field(default_factory=IoReassembler)  # over 8 bytes in
    last_explicit: float = 0.0
    explicit_misses: int = 0  # explicit requests in a row without an answer
    vendor_id: int | None = None
    product_code: int | None = None
    product_name: str | None = None
    epr: float = 0.0
    output: bytes = b""  # b"" = idle (zero-length I/O message)
    sent_output: bytes | None = None
    last_output_sent: float = 0.0
    ack_deadline: float | None = None
    ack_retried: bool = False
    poll_open: bool = False  # a poll went out and its response has not come yet
    last_rx: float = 0.0
    # the steady case (docs/decisions/0097): quiet, the adapter said that unchanged inputs
    # tell it nothing; the inputs last reported and until when unchanged ones need not be
    quiet: bool = False
    last_inputs: bytes | None = None
    inputs_due: float = 0.0
    poll: Send[CanFrame] | None = None  # the poll of ``output``, built once per output
    figures: NodeFigures = field(default_factory=NodeFigures)

    @property
    def mac(self) -> int:
        return self.cfg.mac

    def next_xid(self) -> bool:
        """Toggle XID for each new request (fact sheet 2.4 ◐)."""
        self.xid = not self.xid
        return self.xid

    def problem(self, text: str) -> bool:
        """Record a problem; True if it differs from the last one (report it then)."""
        new = text != self.figures.last_problem
        self.figures.last_problem = text
        return new
