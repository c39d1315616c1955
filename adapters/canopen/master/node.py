"""One node's state on the master: its bring-up phase, its SDO channel (one transfer in
flight, CiA 301 §7.2.4: a server serves one client transfer at a time), its heartbeat
watch and the last statusword."""

from __future__ import annotations

import struct
from collections import deque
from dataclasses import dataclass, field
from enum import Enum

from adapters.canopen.codec.cia402 import State
from adapters.canopen.codec.frames import CanFrame, NmtState, SdoClientTransfer
from adapters.canopen.master.control import STOPPED, Want
from adapters.canopen.master.emcy import EmcyBudget
from adapters.canopen.master.events import Inputs, NodeConfig


class Phase(Enum):
    """Where a node is in the bring-up (CiA 301 §7.3.2 boot-up, NMT start)."""

    PROBE = "probe"  # asking 0x1000 by SDO until the node answers
    RESET = "reset"  # NMT reset node sent: waiting for the boot-up message
    CONFIGURE = "configure"  # SDO writes and read-backs of the bring-up
    START = "start"  # NMT start sent: waiting for an operational heartbeat
    ONLINE = "online"  # operational, PDOs exchanged
    FAILED = "failed"  # the node refused the bring-up: retried after a long pause


class Purpose(Enum):
    """Why an SDO transfer runs."""

    PROBE = "probe"
    WRITE = "write"
    VERIFY = "verify"
    REPORT = "report"
    FAULT = "fault"
    USER = "user"  # a job of the adapter (parameter read or write)
    RELEASE = "release"  # leaving the line: the node's consumer of our heartbeat off


@dataclass(slots=True)
class Job:
    purpose: Purpose
    index: int
    subindex: int
    write: bytes | None = None
    token: int = 0
    step: int = 0  # the bring-up step (WRITE, VERIFY)


@dataclass(slots=True)
class Node:
    config: NodeConfig
    phase: Phase = Phase.PROBE
    seen: bool = False  # answered since it was last lost (NodeSeen sent)
    phase_deadline: float | None = None
    probe_at: float | None = 0.0
    reset_done: bool = False
    heard: NmtState | None = None  # the last NMT state its heartbeat or boot-up said
    heard_at: float | None = None
    watch_heartbeat: bool = False
    jobs: deque[Job] = field(default_factory=deque)
    current: Job | None = None
    transfer: SdoClientTransfer | None = None
    sdo_deadline: float | None = None
    step: int = 0
    reports: dict[tuple[int, int], bytes] = field(default_factory=dict)
    fault_reads: dict[tuple[int, int], bytes] = field(default_factory=dict)
    fault_pending: int = 0
    statusword: int | None = None
    state: State | None = None
    want: Want = STOPPED
    reset_until: float = 0.0  # the fault reset bit set until then
    reset_clear_until: float = 0.0  # then at 0 until then, before the next command
    rpdo_sent: bytes | None = None  # the last RPDO1 data sent, and when
    rpdo_at: float = 0.0
    # RPDO1 as last built, and what it was built from (state, want, reset pulse on)
    rpdo_key: tuple[State | None, Want, int] | None = None
    rpdo_frame: CanFrame | None = None
    # TPDO1 as last received and what it gave (a repeated TPDO1 gives the same again)
    tpdo_data: bytes | None = None
    tpdo_inputs: Inputs | None = None
    # the steady case (docs/decisions/0098): the adapter said an unchanged TPDO1 tells it
    # nothing (quiet), and until when an unchanged one need not be reported again
    quiet: bool = False
    inputs_due: float = 0.0
    # TPDO1's mapping as one struct (every field 1, 2, 4 or 8 bytes), else None
    tpdo_struct: struct.Struct | None = None
    # cycles (SYNCs) since the last TPDO1 while online: lost beyond TPDO_LOSS_CYCLES
    tpdo_silent: int = 0
    # TPDO1s the SYNCs allow (one each, one carried over at most): below 0 is a conflict
    tpdo_credit: int = 1
    tpdo_in_cycle: int = 0  # TPDO1s heard since the last SYNC
    tpdo_steady: int = 0  # cycles in a row with exactly one TPDO1
    # transfers that ended without an answer (timed out, aborted): each may still get
    # its one late answer (ignored); any other answer no request asked for is a conflict
    sdo_late: int = 0
    # the bring-up wrote the consumer of the gateway's heartbeat (0x1016:1) and no
    # release write has switched it off since: the drive watches the gateway
    consumer_set: bool = False
    figures: dict[str, int] = field(
        default_factory=lambda: {
            "tpdo_rx": 0,
            "rpdo_tx": 0,
            "emcy_rx": 0,
            "heartbeats_rx": 0,
            "sdo_transfers": 0,
            "sdo_aborts": 0,
            "sdo_timeouts": 0,
            "sdo_stale": 0,  # late answers of timed-out transfers, ignored
            "bad_pdos": 0,
            "lost": 0,
            "released": 0,
            "conflicts": 0,  # frames that contradict each other (may be forged)
        }
    )
    last_problem: str | None = None
    emcy: EmcyBudget = field(default_factory=EmcyBudget)  # the EMCY frames taken from it

    @property
    def id(self) -> int:
        return self.config.node_id

    @property
    def heartbeat_timeout(self) -> float:
        return self.config.heartbeat_ms / 1000.0
