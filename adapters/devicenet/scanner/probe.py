"""The line scan of ``drive-gateway devicenet scan``: which MAC IDs answer, and who they are.

A sans-IO engine stepped with an injected clock, like :class:`Scanner`:

1. The scan tool claims its own MAC ID with the Duplicate MAC ID check (fact sheet 2.3:
   two requests, ``dupmac_timeout`` apart). A running scanner (a gateway) at that MAC
   answers: the scan then refuses to run and sends nothing else, so it never disturbs a
   running scanner's connections (one master per line).
2. Each MAC ID is probed on the Group 2 Only unconnected port (G2 message 6, fact sheet
   2.5): Allocate of the explicit connection only, the Identity object (class 1,
   instance 1) attributes 1, 2, 3, 4, 6, 7 read on it (fragmented replies reassembled and
   acknowledged, 2.8), then Release of what was allocated. A node that does not answer
   the Allocate in ``timeout`` is absent; one that refuses it (owned by another master)
   is listed as present with the reason. ``window`` nodes are probed at once.

Automatic Device Replacement (seed 6.1) uses the same probe from the running scanner
(``claim=False``: the scanner already holds its MAC ID) on MAC 63, with an ``assign``
function: when it names a MAC ID for the identity read, the node's MAC ID is set
(DeviceNet object 03h attribute 1, seed table 9; effective after a reset, seed 4.1.5)
and the node is reset (Identity Reset service); it then comes up at its new MAC ID.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum

from adapters.devicenet.codec.cip import AllocationRejection, allocation_rejection
from adapters.devicenet.codec.datatypes import CipType, decode_short_string, decode_value
from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind
from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    ErrorResponse,
    ExplicitMessage,
    GetAttributeSingle,
    ReleaseConnectionSet,
    Request,
    Reset,
    SetAttributeSingle,
    error_text,
)
from adapters.devicenet.codec.fragment import (
    ExplicitReassembler,
    FragmentAck,
    Unfragmented,
    decode_explicit_frame,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import (
    MAX_MAC,
    PredefinedMessage,
    match_predefined,
    predefined_can_id,
)
from adapters.devicenet.codec.objects import AllocationChoice, IdentityAttribute
from adapters.devicenet.errors import DeviceNetDecodeError, FragmentationError

IDENTITY_CLASS = 1
DEVICENET_CLASS = 3
MAC_ID_ATTRIBUTE = 1  # seed table 9
IDENTITY_READS = (
    IdentityAttribute.VENDOR_ID,
    IdentityAttribute.DEVICE_TYPE,
    IdentityAttribute.PRODUCT_CODE,
    IdentityAttribute.REVISION,
    IdentityAttribute.SERIAL_NUMBER,
    IdentityAttribute.PRODUCT_NAME,
)


@dataclass(frozen=True, slots=True)
class ProbeConfig:
    mac: int = 0  # the scan tool's own MAC ID
    vendor_id: int = 0xFFFF  # its Duplicate MAC ID check identity (docs/devices.md)
    serial_number: int = 0x44475300  # "DGS" + 0
    macs: tuple[int, ...] = tuple(range(MAX_MAC + 1))
    timeout: float = 0.2  # s per Allocate / request / Release answer
    dupmac_timeout: float = 1.0  # fact sheet 2.3
    window: int = 4  # nodes probed at once
    claim: bool = True  # run the Duplicate MAC ID check first (False: a running scanner)

    def __post_init__(self) -> None:
        if not 0 <= self.mac <= MAX_MAC:
            raise ValueError(f"MAC ID {self.mac} out of 0..63")
        if self.window < 1 or self.timeout <= 0 or self.dupmac_timeout <= 0:
            raise ValueError("window, timeout and dupmac_timeout must be positive")


@dataclass(frozen=True, slots=True)
class NodeInfo:
    """One MAC ID that answered."""

    mac: int
    vendor_id: int | None = None
    product_type: int | None = None
    product_code: int | None = None
    revision: tuple[int, int] | None = None
    serial_number: int | None = None
    product_name: str | None = None
    problem: str | None = None  # why the identity is incomplete (owned by another master...)
    readdressed: int | None = None  # the MAC ID it was given (Automatic Device Replacement)


@dataclass(frozen=True, slots=True)
class Progress:
    done: int
    total: int
    mac: int
    found: NodeInfo | None


@dataclass(frozen=True, slots=True)
class Refused:
    """The scan tool's MAC ID is taken: a scanner runs on this line."""

    text: str


@dataclass(frozen=True, slots=True)
class Finished:
    nodes: tuple[NodeInfo, ...]


ProbeAction = CanFrame | Progress | Refused | Finished


class _Step(Enum):
    ALLOCATE = "allocate"
    READ = "read"
    SET_MAC = "set MAC ID"
    RESET = "reset"
    RELEASE = "release"
    DONE = "done"


@dataclass(slots=True)
class _Node:
    mac: int
    step: _Step = _Step.ALLOCATE
    deadline: float = 0.0
    xid: bool = False
    request: ExplicitMessage | None = None
    reads: list[int] = field(default_factory=list)
    values: dict[int, bytes] = field(default_factory=dict)
    answered: bool = False
    problem: str | None = None
    target: int | None = None
    readdressed: int | None = None
    reassembler: ExplicitReassembler = field(default_factory=ExplicitReassembler)


class LineProbe:
    """The scan as ``step(now, frame) -> actions``; ``next_deadline()`` says when to step."""

    def __init__(
        self, config: ProbeConfig, assign: Callable[[NodeInfo], int | None] | None = None
    ) -> None:
        self.config = config
        self.assign = assign
        self.macs = [m for m in config.macs if m != config.mac]
        self._queue = list(self.macs)
        self._active: dict[int, _Node] = {}
        self._found: dict[int, NodeInfo] = {}
        self._done = 0
        self._checks_sent = 0 if config.claim else 2
        self._check_until: float | None = None if config.claim else 0.0
        self.refused: str | None = None
        self.finished = False

    # ------------------------------------------------------------ driving

    def step(self, now: float, frame: CanFrame | None = None) -> list[ProbeAction]:
        out: list[ProbeAction] = []
        if self.finished or self.refused is not None:
            return out
        if frame is not None:
            self._on_frame(now, frame, out)
        if self.refused is None:
            self._tick(now, out)
        return out

    def next_deadline(self) -> float | None:
        if self.finished or self.refused is not None:
            return None
        if self._checks_sent < 2 or self._check_until is None:
            return self._check_until or 0.0
        times = [n.deadline for n in self._active.values()]
        return min(times) if times else self._check_until

    # ------------------------------------------------------------ duplicate MAC check

    def _tick(self, now: float, out: list[ProbeAction]) -> None:
        c = self.config
        if self._check_until is None or (now >= self._check_until and self._checks_sent < 2):
            out.append(
                DupMacCheck(c.mac, DupMacKind.REQUEST, 0, c.vendor_id, c.serial_number).to_frame()
            )
            self._checks_sent += 1
            self._check_until = now + c.dupmac_timeout
            return
        if now < self._check_until:
            return
        for node in list(self._active.values()):
            if now >= node.deadline:
                self._on_timeout(now, node, out)
        while self._queue and len(self._active) < c.window:
            node = _Node(self._queue.pop(0))
            self._active[node.mac] = node
            self._allocate(now, node, out)
        if not self._active and not self._queue:
            self.finished = True
            out.append(Finished(tuple(self._found[m] for m in sorted(self._found))))

    def _on_frame(self, now: float, frame: CanFrame, out: list[ProbeAction]) -> None:
        try:
            found = match_predefined(frame.arbitration_id)
        except DeviceNetDecodeError:
            return
        if found is None:
            return
        if found.message is PredefinedMessage.DUPLICATE_MAC_CHECK:
            self._on_dupmac(frame, out)
        elif found.message is PredefinedMessage.SLAVE_EXPLICIT_RESPONSE:
            node = self._active.get(found.mac)
            if node is not None:
                self._on_response(now, node, frame.data, out)

    def _on_dupmac(self, frame: CanFrame, out: list[ProbeAction]) -> None:
        try:
            check = DupMacCheck.from_frame(frame)
        except DeviceNetDecodeError:
            return
        if check.mac != self.config.mac:
            return
        self.refused = (
            f"MAC ID {check.mac} is taken on the line (vendor 0x{check.vendor_id:04X}, serial "
            f"{check.serial_number}): a scanner is running there; a scan does not run beside "
            "it (stop the gateway, or scan from a free MAC ID with --mac)"
        )
        out.append(Refused(self.refused))

    # ------------------------------------------------------------ one node

    def _send(
        self,
        now: float,
        node: _Node,
        message: PredefinedMessage,
        body: Request,
        out: list[ProbeAction],
    ) -> None:
        node.xid = not node.xid
        request = ExplicitMessage(self.config.mac, node.xid, body)
        node.request = request
        node.deadline = now + self.config.timeout
        out.append(CanFrame(predefined_can_id(message, node.mac), request.encode()))

    def _allocate(self, now: float, node: _Node, out: list[ProbeAction]) -> None:
        body = AllocateConnectionSet(AllocationChoice.EXPLICIT, self.config.mac)
        self._send(now, node, PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST, body, out)

    def _release(self, now: float, node: _Node, out: list[ProbeAction]) -> None:
        node.step = _Step.RELEASE
        body = ReleaseConnectionSet(AllocationChoice.EXPLICIT)
        self._send(now, node, PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST, body, out)

    def _read_next(self, now: float, node: _Node, out: list[ProbeAction]) -> None:
        if not node.reads:
            target = None
            if self.assign is not None and node.problem is None:
                target = self.assign(_node_info(node))
            if target is None:
                self._release(now, node, out)
                return
            node.step, node.target = _Step.SET_MAC, target
            set_mac = SetAttributeSingle(DEVICENET_CLASS, 1, MAC_ID_ATTRIBUTE, bytes((target,)))
            self._send(now, node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, set_mac, out)
            return
        attribute = node.reads[0]
        node.reassembler.reset()
        body = GetAttributeSingle(IDENTITY_CLASS, 1, attribute)
        self._send(now, node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, body, out)

    def _on_timeout(self, now: float, node: _Node, out: list[ProbeAction]) -> None:
        if node.step is _Step.ALLOCATE:
            self._finish(node, out)  # no answer: nobody at that MAC ID
        elif node.step is _Step.READ:
            node.problem = f"no answer to reading Identity attribute {node.reads[0]}"
            self._release(now, node, out)
        elif node.step in (_Step.SET_MAC, _Step.RESET):
            node.problem = f"no answer to the {node.step.value} request"
            self._release(now, node, out)
        else:
            self._finish(node, out)  # the Release went unanswered: the node times it out

    def _on_response(self, now: float, node: _Node, data: bytes, out: list[ProbeAction]) -> None:
        if not data or data[0] & 0x3F != self.config.mac:
            return  # a response to another master
        try:
            frame = decode_explicit_frame(data)
        except DeviceNetDecodeError:
            return
        if isinstance(frame, FragmentAck):
            return
        if isinstance(frame, Unfragmented):
            raw = frame.message
        else:
            try:
                fed = node.reassembler.feed(now, frame)
            except FragmentationError:
                return
            if fed.ack is not None:
                can_id = predefined_can_id(PredefinedMessage.MASTER_EXPLICIT_REQUEST, node.mac)
                out.append(CanFrame(can_id, fed.ack.encode()))
                node.deadline = now + self.config.timeout
            if fed.message is None:
                return
            raw = fed.message
        try:
            message = ExplicitMessage.decode(raw)
        except DeviceNetDecodeError:
            return
        if message.is_request or node.request is None or not message.answers(node.request):
            return
        node.answered = True
        self._on_answer(now, node, message, out)

    def _on_answer(
        self, now: float, node: _Node, message: ExplicitMessage, out: list[ProbeAction]
    ) -> None:
        body = message.body
        if node.step is _Step.ALLOCATE:
            if isinstance(body, AllocateResponse):
                node.step, node.reads = _Step.READ, list(IDENTITY_READS)
                self._read_next(now, node, out)
            elif isinstance(body, ErrorResponse):
                node.problem = _allocate_problem(body)
                self._finish(node, out)
            return
        if node.step is _Step.READ:
            attribute = node.reads.pop(0)
            if isinstance(body, ErrorResponse):
                node.problem = f"Identity attribute {attribute}: {error_text(body)}"
            else:
                node.values[attribute] = body.encode_data()
            self._read_next(now, node, out)
            return
        if node.step is _Step.SET_MAC:
            if isinstance(body, ErrorResponse):
                node.problem = f"setting MAC ID {node.target} refused: {error_text(body)}"
                self._release(now, node, out)
                return
            node.step = _Step.RESET
            body_reset = Reset(IDENTITY_CLASS, 1)
            self._send(now, node, PredefinedMessage.MASTER_EXPLICIT_REQUEST, body_reset, out)
            return
        if node.step is _Step.RESET:
            if isinstance(body, ErrorResponse):
                node.problem = f"reset refused: {error_text(body)}"
                self._release(now, node, out)
                return
            node.readdressed = node.target  # the reset drops its connections: no Release
        self._finish(node, out)

    def _finish(self, node: _Node, out: list[ProbeAction]) -> None:
        node.step = _Step.DONE
        self._active.pop(node.mac, None)
        self._done += 1
        info = _node_info(node) if node.answered else None
        if info is not None:
            self._found[node.mac] = info
        out.append(Progress(self._done, len(self.macs), node.mac, info))


def _allocate_problem(err: ErrorResponse) -> str:
    rejection = allocation_rejection(err.general_status, err.additional_code)
    if rejection is AllocationRejection.OWNED_BY_ANOTHER_MASTER:
        return "owned by another master (identity not read)"
    if rejection is AllocationRejection.ALREADY_ALLOCATED:
        return "explicit connection already allocated (identity not read)"
    return f"Allocate refused: {error_text(err)}"


def _node_info(node: _Node) -> NodeInfo:
    v = node.values

    def uint(attribute: int, kind: CipType) -> int | None:
        raw = v.get(attribute)
        if raw is None:
            return None
        try:
            return decode_value(kind, raw)
        except DeviceNetDecodeError:
            return None

    rev_raw = v.get(IdentityAttribute.REVISION)
    revision = (rev_raw[0], rev_raw[1]) if rev_raw is not None and len(rev_raw) == 2 else None
    name: str | None = None
    name_raw = v.get(IdentityAttribute.PRODUCT_NAME)
    if name_raw is not None:
        try:
            name = decode_short_string(name_raw)
        except DeviceNetDecodeError:
            name = None
    return NodeInfo(
        mac=node.mac,
        vendor_id=uint(IdentityAttribute.VENDOR_ID, CipType.UINT),
        product_type=uint(IdentityAttribute.DEVICE_TYPE, CipType.UINT),
        product_code=uint(IdentityAttribute.PRODUCT_CODE, CipType.UINT),
        revision=revision,
        serial_number=uint(IdentityAttribute.SERIAL_NUMBER, CipType.UDINT),
        product_name=name,
        problem=node.problem,
        readdressed=node.readdressed,
    )


def macs_of(values: Iterable[int]) -> tuple[int, ...]:
    return tuple(sorted(set(values)))
