"""What goes into the scanner engine and what comes out: config, events, actions.

All frozen dataclasses and enums; times are seconds on the caller's monotonic clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from adapters.can.events import BadFrame, BusErrorIn, FrameIn, LinkDown, Send, TxFailed
from adapters.devicenet.codec.explicit import Response
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import MAX_MAC
from adapters.devicenet.codec.objects import AllocationChoice, ConnectionInstance

# ---------------------------------------------------------------- config


class IoKind(Enum):
    """The I/O connection allocated besides the explicit one (fact sheet 2.5 choice bits)."""

    POLLED = "polled"
    COS = "cos"
    CYCLIC = "cyclic"


@dataclass(frozen=True, slots=True)
class IdentityCheck:
    """Identity object values a node must show before I/O (None: not checked)."""

    vendor_id: int | None = None
    product_code: int | None = None
    product_name: str | None = None
    product_type: int | None = None  # Identity attribute 2 (e.g. from an EDS's ProdType)
    # Identity attribute 4 (major, minor): the major must be equal and the minor at least
    # this one (a compatible revision, as an EDS's MajRev/MinRev; decision, docs/devices.md)
    revision: tuple[int, int] | None = None


@dataclass(frozen=True, slots=True)
class NodeConfig:
    """One node of the scan list."""

    mac: int
    io: IoKind = IoKind.POLLED
    ack: bool = True  # COS/cyclic with acknowledgement (False: ACK suppression)
    produced_size: int = 4  # bytes the node produces (our input); over 8: fragmented (2.8)
    consumed_size: int = 4  # bytes the node consumes (our output); over 8: fragmented
    epr: float = 0.1  # s: expected packet rate of the I/O connection
    identity: IdentityCheck = IdentityCheck()

    def __post_init__(self) -> None:
        if not 0 <= self.mac <= MAX_MAC:
            raise ValueError(f"MAC ID {self.mac} out of 0..63")
        if self.epr <= 0:
            raise ValueError("the expected packet rate must be positive")
        if self.produced_size < 0 or self.consumed_size < 0:
            raise ValueError("I/O sizes cannot be negative")

    @property
    def choice(self) -> AllocationChoice:
        """Allocation choice: explicit + poll, or explicit + COS/cyclic (+ ACK suppression)."""
        choice = AllocationChoice.EXPLICIT | _IO_BIT[self.io]
        if self.io is not IoKind.POLLED and not self.ack:
            choice |= AllocationChoice.ACK_SUPPRESSION
        return choice

    @property
    def io_instance(self) -> int:
        """Connection object instance of the I/O connection (fact sheet 2.9)."""
        if self.io is IoKind.POLLED:
            return ConnectionInstance.POLL
        return ConnectionInstance.COS_CYCLIC


_IO_BIT = {
    IoKind.POLLED: AllocationChoice.POLL,
    IoKind.COS: AllocationChoice.COS,
    IoKind.CYCLIC: AllocationChoice.CYCLIC,
}


@dataclass(frozen=True, slots=True)
class ScannerConfig:
    mac: int = 0
    vendor_id: int = 0  # our Duplicate MAC ID check identity (fact sheet 2.3)
    serial_number: int = 0x44470000
    poll_interval: float = 0.05
    response_timeout: float = 0.1  # poll response or COS acknowledge
    explicit_timeout: float = 1.0  # explicit response (and each fragment ack)
    explicit_epr: float = 2.5  # s, EPR set on the explicit connection (fact sheet 2.9)
    dupmac_timeout: float = 1.0  # fact sheet 2.3: wait 1 s after each request
    allocate_timeout: float = 1.0  # fact sheet 2.10 step 2: about 1 s
    retry_min: float = 0.5
    retry_max: float = 30.0
    poll_window: int = 8  # polls in flight at once (keeps a SocketCAN tx queue short)
    # explicit requests in flight on the line at once, bounded as polls are: a request to
    # each of 63 nodes in one pass would overflow a SocketCAN transmit queue of 10
    # (ENOBUFS), and on a slow host 63 bring-ups at once all race their timeouts (decision)
    explicit_window: int = 4
    # nodes being brought up (Allocate sent, or configuring) at once: a node is allocated
    # only when it can be configured at once, or its explicit connection (EPR 2.5 s) would
    # time out while it waits (decision)
    bringup_window: int = 4
    # s between Allocate/Release requests: a line of 63 drives coming up (or leaving) does
    # not put 63 frames at once into a SocketCAN transmit queue of 10 (decision).
    request_spacing: float = 0.002
    # bit/s of the line, for the receive hold's bit times (Scanner.hold_until); 0: unknown,
    # no hold
    bitrate: int = 0
    tx_backoff_min: float = 0.01
    tx_backoff_max: float = 1.0

    def __post_init__(self) -> None:
        if not 0 <= self.mac <= MAX_MAC:
            raise ValueError(f"scanner MAC ID {self.mac} out of 0..63")
        if self.poll_window < 1:
            raise ValueError("poll_window must be at least 1")
        if self.explicit_window < 1:
            raise ValueError("explicit_window must be at least 1")
        if self.bringup_window < 1:
            raise ValueError("bringup_window must be at least 1")
        if self.request_spacing < 0:
            raise ValueError("request_spacing cannot be negative")
        if self.bitrate < 0:
            raise ValueError("bitrate cannot be negative")


# ---------------------------------------------------------------- events (in)


Event = FrameIn[CanFrame] | BadFrame | BusErrorIn | TxFailed | LinkDown
"""The scanner's events: its link's (:mod:`adapters.can.events`)."""


# ---------------------------------------------------------------- actions (out)


@dataclass(frozen=True, slots=True)
class NodeIdentity:
    vendor_id: int | None = None
    product_code: int | None = None
    product_name: str | None = None


@dataclass(frozen=True, slots=True)
class NodeUp:
    """Allocated, identity and sizes checked, EPR set: I/O is running."""

    mac: int
    identity: NodeIdentity
    epr: float  # the EPR the node actually uses (its Set reply)


@dataclass(frozen=True, slots=True)
class NodeDown:
    mac: int
    reason: str


@dataclass(frozen=True, slots=True)
class InputData:
    """The node's produced data (poll response or COS/cyclic production)."""

    mac: int
    data: bytes


@dataclass(frozen=True, slots=True)
class IoConflict:
    """A poll response nobody asked for: a second answer to one poll, or one before any
    poll. Another station sends with the node's identifier (a forger, or a second node
    at that MAC); the data is not delivered, and the node's readings are doubtful.
    ``count`` is the node's total (its ``io_conflicts`` figure)."""

    mac: int
    data: bytes
    count: int


@dataclass(frozen=True, slots=True)
class ExplicitResult:
    """The end of a submitted explicit request: a response, or why there is none."""

    token: int
    mac: int
    response: Response | None = None
    error: str | None = None
    timed_out: bool = False  # no answer in time (else: refused, offline, cancelled)


class ReportKind(Enum):
    ALLOCATION = "allocation"
    IDENTITY = "identity"
    SIZE = "size"
    TIMEOUT = "timeout"
    DUPLICATE_MAC = "duplicate_mac"
    BUS = "bus"
    PROTOCOL = "protocol"


@dataclass(frozen=True, slots=True)
class Report:
    """Something a person should see: a node problem or a line condition."""

    mac: int | None
    kind: ReportKind
    text: str
    data: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class LineOnline:
    """The scanner passed its Duplicate MAC ID check and is on the line."""


@dataclass(frozen=True, slots=True)
class LineFault:
    """The scanner's MAC is taken: it stays off the line."""

    text: str


Action = (
    Send[CanFrame]
    | NodeUp
    | NodeDown
    | InputData
    | IoConflict
    | ExplicitResult
    | Report
    | LineOnline
    | LineFault
)
