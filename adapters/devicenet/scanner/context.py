"""What the parts of the scanner share: the config, the nodes, the actions going out,
the line figures, the send hold, the spacing of unconnected requests, and the soonest
deadline (:meth:`LineContext.fold`)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from adapters.can.events import Send
from adapters.devicenet.codec.fragment import UNFRAGMENTED_MAX, fragment_io
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import PredefinedId, PredefinedMessage
from adapters.devicenet.scanner.events import Action, Report, ReportKind, ScannerConfig
from adapters.devicenet.scanner.node import Node


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


class LineContext:
    """The state every part of the scanner reads and writes, and the ways out of it."""

    def __init__(self, config: ScannerConfig, nodes: dict[int, Node]) -> None:
        self.config = config
        self.nodes = nodes
        self.figures = LineFigures()
        self.out: list[Action] = []
        self.leaving = False
        self.touched: Node | None = None  # the node an event step concerns
        self.soonest: float | None = 0.0  # see Scanner.next_deadline
        self.request_slot = 0.0  # no Allocate/Release before this (request_spacing)
        self.tx_hold_until = 0.0
        self.tx_backoff = config.tx_backoff_min
        self.last_tx_failure: float | None = None

    def take(self) -> list[Action]:
        """The actions gathered since the last call."""
        out, self.out = self.out, []
        return out

    def fold(self, times: Iterable[float]) -> None:
        """Bring the soonest deadline forward to any of ``times``."""
        for t in times:
            if self.soonest is None or t < self.soonest:
                self.soonest = t

    def wake(self) -> None:
        """Something that may let a node go on (a request queued, a window freed, an
        output changed): a timer step at once. It ticks every node that is not steady
        (:class:`~adapters.devicenet.scanner.timers.SteadyTimers`), which every node that
        can go on is: a steady node has nothing to send but its polls."""
        self.soonest = 0.0

    # ------------------------------------------------------------ send hold

    def tx_ok(self, now: float) -> bool:
        if now < self.tx_hold_until:
            return False
        self.tx_hold_until = 0.0
        return True

    def gated(self, t: float) -> float:
        """When something due at ``t`` can be sent: not before the send hold ends.

        Every deadline that leads to a send goes through here, so a held line is not
        stepped again until the hold ends (no busy loop while sends fail).
        """
        return t if t >= self.tx_hold_until else self.tx_hold_until

    # ------------------------------------------------------------ out

    def send(self, node: Node, message: PredefinedMessage, data: bytes) -> None:
        node.figures.frames_tx += 1
        self.emit(_frame(message, node.mac, data))

    def send_io(self, node: Node, data: bytes) -> None:
        """Our I/O data to a node, fragmented when longer than one frame (fact sheet 2.8)."""
        if len(data) <= UNFRAGMENTED_MAX:
            self.send(node, PredefinedMessage.MASTER_POLL_COMMAND, data)
            return
        for payload in fragment_io(data):
            self.send(node, PredefinedMessage.MASTER_POLL_COMMAND, payload)

    def send_poll(self, node: Node) -> None:
        """The node's poll (its output), as :meth:`send_io` sends it; an output of one frame
        is encoded once and its :class:`Send` kept on the node until the output changes
        (the steady poll costs no encoding: docs/decisions/0097)."""
        data = node.output
        poll = node.poll
        if poll is None or poll.frame.data is not data:
            if len(data) > UNFRAGMENTED_MAX:
                self.send_io(node, data)
                return
            poll = node.poll = Send(_frame(PredefinedMessage.MASTER_POLL_COMMAND, node.mac, data))
        node.figures.frames_tx += 1
        self.figures.frames_tx += 1
        self.out.append(poll)

    def emit(self, frame: CanFrame) -> None:
        self.figures.frames_tx += 1
        self.out.append(Send(frame))

    def report(self, mac: int | None, kind: ReportKind, text: str, **data: object) -> None:
        self.out.append(Report(mac, kind, text, dict(data)))


_FRAME_IDS: dict[tuple[PredefinedMessage, int], int] = {}


def _frame(message: PredefinedMessage, mac: int, data: bytes) -> CanFrame:
    key = (message, mac)
    arbitration_id = _FRAME_IDS.get(key)
    if arbitration_id is None:
        arbitration_id = _FRAME_IDS[key] = PredefinedId(message, mac).arbitration_id
    return CanFrame(arbitration_id, data)


def ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000.0, 3)
