"""What the CANopen master engine takes (events) and gives (actions), and its configs.

Sans-IO: frames in, frames and reports out; the adapter turns reports into the common
drive model. Values are raw (bytes, integers): the object dictionary (canopen library)
is the adapter's, the engine knows only indexes, sizes and the bring-up plan it is given.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from adapters.can.events import BadFrame, BusErrorIn, FrameIn, LinkDown, Send, TxFailed
from adapters.canopen.codec.frames import CanFrame, Emcy, MappingEntry, SdoResult
from adapters.canopen.master.emcy import EMCY_BURST, EMCY_RATE

# ---------------------------------------------------------------- configuration


@dataclass(frozen=True, slots=True)
class SdoStep:
    """One SDO write of the bring-up, read back and compared under ``mask`` (a COB-ID
    is compared on its valid bit and 11-bit id: 0x800007FF). ``what`` names it for the
    error ("producer heartbeat time 0x1017")."""

    index: int
    subindex: int
    data: bytes
    what: str
    mask: int = 0xFFFFFFFFFFFFFFFF
    read_back: bool = True
    # a refusal or a different read-back is reported (Report) and the bring-up goes on
    # (an unused PDO switched off); a write that is not answered still stops it
    optional: bool = False


@dataclass(frozen=True, slots=True)
class PdoField:
    """One mapped object of a PDO, with the signedness of its data type."""

    entry: MappingEntry
    signed: bool = False

    @property
    def size(self) -> int:
        return self.entry.bits // 8


@dataclass(frozen=True, slots=True)
class NodeConfig:
    """One drive as the engine sees it.

    ``steps``: the bring-up writes in order (heartbeat, PDO mapping, option codes, mode,
    startup SDOs). ``rpdo``: RPDO1's fields, the controlword first then the target;
    ``tpdo``: TPDO1's, the statusword first. ``reports``: objects read after the bring-up
    and reported (the quick stop option 0x605A as the drive has it). ``fault_reads``:
    objects read when the drive enters FAULT (0x1001, 0x603F where the EDS has it).
    ``device_profile``: the profile number the low word of 0x1000 must show (402), None
    not to check. ``mode_bits``: added to Enable operation (vl: 0x70).
    """

    node_id: int
    heartbeat_ms: int
    steps: tuple[SdoStep, ...] = ()
    rpdo: tuple[PdoField, ...] = ()
    tpdo: tuple[PdoField, ...] = ()
    reports: tuple[tuple[int, int], ...] = ()
    fault_reads: tuple[tuple[int, int], ...] = ((0x1001, 0), (0x603F, 0))
    reset_if_operational: bool = False
    device_profile: int | None = 402
    mode_bits: int = 0
    release: tuple[SdoStep, ...] = ()  # written on a clean leave (the heartbeat consumer off)


@dataclass(frozen=True, slots=True)
class MasterConfig:
    """The gateway's own node behaviour on the line.

    ``sync_period``: SYNC produced every this many s (0: none; RPDOs then go every
    ``pdo_period``). ``heartbeat_factor``: a node is lost when no heartbeat came for
    this many of its producer periods. ``own_node_id``/``own_heartbeat``: the gateway's
    heartbeat (0: none), which the drives consume (0x1016) to react per 0x6007.
    ``listen``: s the engine only listens before it sends its first frame (one master
    per line: a SYNC, an NMT command, a heartbeat with ``own_node_id`` or an RPDO to one
    of its nodes heard meanwhile is another master, :class:`MasterHeard` with
    ``claimed`` False, and the engine never starts); 0: no listening. ``emcy_rate`` and
    ``emcy_burst``: each node's EMCY budget (:mod:`adapters.canopen.master.emcy`).
    """

    nmt_master: bool = True
    sync_period: float = 0.0
    pdo_period: float = 0.05
    sdo_timeout: float = 0.5
    heartbeat_factor: float = 3.0
    boot_timeout: float = 2.0
    retry: float = 1.0
    failed_retry: float = 10.0
    own_node_id: int = 0
    own_heartbeat: float = 0.0
    listen: float = 0.0
    emcy_rate: float = EMCY_RATE
    emcy_burst: int = EMCY_BURST

    @property
    def cycle(self) -> float:
        return self.sync_period if self.sync_period > 0 else self.pdo_period


# ---------------------------------------------------------------- events


Event = FrameIn[CanFrame] | BadFrame | BusErrorIn | LinkDown | TxFailed
"""The master's events: its link's (:mod:`adapters.can.events`)."""


# ---------------------------------------------------------------- actions


@dataclass(frozen=True, slots=True)
class NodeSeen:
    """The node answered SDO: it is being brought up (comm: connecting)."""

    node: int


@dataclass(frozen=True, slots=True)
class Configured:
    """Every bring-up write done and read back; ``reports``: the objects of
    ``NodeConfig.reports`` as read ((index, subindex) -> raw bytes)."""

    node: int
    reports: dict[tuple[int, int], bytes] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class NodeUp:
    """The node is operational and exchanging PDOs."""

    node: int


@dataclass(frozen=True, slots=True)
class NodeDown:
    """A node that was seen is lost (heartbeat missed, rebooted, left operational);
    the engine brings it up again when it answers."""

    node: int
    reason: str


@dataclass(frozen=True, slots=True)
class NodeProblem:
    """The bring-up failed on the node's side (a write refused or read back different,
    a wrong device type): the node is not started (it gets no PDO) and is tried again
    after ``MasterConfig.failed_retry``."""

    node: int
    text: str
    abort_code: int | None = None


@dataclass(frozen=True, slots=True)
class Inputs:
    """TPDO1 of an operational node: the statusword and the other mapped values, raw."""

    node: int
    statusword: int
    values: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class EmcyIn:
    node: int
    emcy: Emcy


@dataclass(frozen=True, slots=True)
class FaultInfo:
    """Read on entering FAULT: ``reads`` (index, subindex) -> raw bytes (absent: not read)."""

    node: int
    reads: dict[tuple[int, int], bytes]


@dataclass(frozen=True, slots=True)
class SdoDone:
    """An SDO job of the adapter ended: ``result`` (data or abort code), or ``error``
    when it could not run (node lost before it ended)."""

    token: int
    node: int
    result: SdoResult | None = None
    error: str | None = None


@dataclass(frozen=True, slots=True)
class Report:
    """Something for the log and the events (a bad frame, a bus condition)."""

    node: int | None
    text: str


@dataclass(frozen=True, slots=True)
class LineClaimed:
    """The listening before the first frame ended with no other master heard: the engine
    produces its SYNC, heartbeat and NMT from now on."""


@dataclass(frozen=True, slots=True)
class MasterHeard:
    """A frame only a master sends, from another producer (a SYNC, an NMT command, a
    heartbeat with the gateway's node id, an RPDO to one of its nodes). ``claimed``
    False: heard while listening, before the first frame: the engine stays silent for
    good (the adapter refuses the line)."""

    text: str
    claimed: bool


@dataclass(frozen=True, slots=True)
class Conflict:
    """Frames for one node that contradict each other (a second TPDO1 in one SYNC
    cycle, an SDO answer with no request under way, two answers to one request): they
    may be forged; ``what`` says which."""

    node: int
    what: str


Action = (
    Send[CanFrame]
    | LineClaimed
    | MasterHeard
    | Conflict
    | NodeSeen
    | Configured
    | NodeUp
    | NodeDown
    | NodeProblem
    | Inputs
    | EmcyIn
    | FaultInfo
    | SdoDone
    | Report
)
