"""The CANopen master engine: NMT master, SDO client, PDO producer and consumer,
heartbeat consumer and producer, SYNC producer, CiA 402 master side; sans-IO, stepped
with an injected clock (``step(now, event) -> actions``, ``next_deadline()``).

Per node (CiA 301 §7.3.2, CiA 402-2 §6.2):

1. PROBE: SDO upload of 0x1000 (device type; the low word is the profile, 402) until
   the node answers; a node heard operational, or not heard at all (no heartbeat yet),
   is reset (NMT reset node, then its boot-up awaited) when its config says so, else put
   in pre-operational.
2. CONFIGURE: the bring-up SDO writes (0x1017 heartbeat, RPDO1/TPDO1 communication
   and mapping, the other PDOs switched off, 0x1016 consumer, 0x6007, 0x605A, 0x6060,
   startup SDOs), each read back and compared; then the report reads (0x605A as the
   drive has it). A refusal or a different read-back stops the bring-up: the node is
   not started (NodeProblem); an optional step's (an unused PDO switched off) is
   reported (Report) and the bring-up goes on.
3. START: NMT start node; ONLINE on its first operational heartbeat.
4. ONLINE: RPDO1 (controlword, target) every cycle, after the SYNC when the gateway
   produces it; TPDO1 in (statusword and actual values); EMCY in, within the node's
   budget (:mod:`~adapters.canopen.master.emcy`, the rest counted); on entering FAULT
   0x1001 and 0x603F read. A node is lost when no heartbeat came within
   ``heartbeat_factor`` times its producer time, on a boot-up, or on a heartbeat that
   is not operational; it is then brought up again from PROBE.

SDO: one transfer in flight per node; the adapter's jobs wait behind the bring-up.
The controlword is :func:`~adapters.canopen.master.control.controlword` of the last
statusword and the node's :class:`~adapters.canopen.master.control.Want`; a fault reset
is one pulse of bit 7 (at least two cycles long so a synchronous RPDO carries it to a
SYNC), started by :meth:`Master.fault_reset` and never repeated.
"""

from __future__ import annotations

import itertools
import math
import struct
from collections.abc import Iterable, Sequence

from adapters.can.events import (
    BadFrame,
    BusErrorIn,
    FrameIn,
    LinkDown,
    NodeUnavailable,
    Send,
    TxFailed,
)
from adapters.canopen.codec import frames
from adapters.canopen.codec.cia402 import Cw, State, decode_state
from adapters.canopen.codec.frames import CanFrame, Kind, NmtCommand, NmtState, SdoClientTransfer
from adapters.canopen.errors import CanOpenDecodeError
from adapters.canopen.master.bringup import (
    SDO_LATE_MAX,
    BringUp,
    drop_jobs,
    queue_release,
    read_fault,
)
from adapters.canopen.master.control import STOPPED, Want, controlword, target
from adapters.canopen.master.emcy import EmcyBudget
from adapters.canopen.master.events import (
    Action,
    Conflict,
    EmcyIn,
    Event,
    Inputs,
    LineClaimed,
    MasterConfig,
    MasterHeard,
    NodeConfig,
    NodeDown,
    PdoField,
    Report,
    SdoDone,
)
from adapters.canopen.master.node import Job, Node, Phase, Purpose

RPDO_REFRESH = 0.1  # s: an unchanged RPDO1 is sent again at least this often
INPUTS_REFRESH = 1.0  # s: an unchanged TPDO1 of a quiet node is reported at least this often (0102)
COB_CACHE = 2048  # COB-IDs remembered (11-bit: all of them)
RESET_PULSE_CYCLES = 2.5  # the fault reset bit stays set this many cycles (>= 2 RPDOs)
# then the bit is back at 0 this many cycles (>= 1 RPDO and SYNC) before the next
# command: the reset is an edge 0 -> 1 -> 0, never 1 carried into Shutdown (0x0086)
RESET_CLEAR_CYCLES = 1.5
# a node online gets its TPDO1 every cycle (every SYNC, or its event timer without
# SYNC): this many cycles without one and it is lost (issue 32 item 11)
TPDO_LOSS_CYCLES = 3
# ... and at least this long (s): at a line's minimum SYNC period (285 us for one node at
# 1 Mbit/s) three cycles are shorter than a busy host's scheduling and a slave's reply
# jitter; a silent drive is still found within 0.1 s
TPDO_LOSS_MIN = 0.1


def tpdo_loss_cycles(cycle: float) -> int:
    """Cycles without a TPDO1 after which a node online is lost, for a SYNC period."""
    return max(TPDO_LOSS_CYCLES, math.ceil(TPDO_LOSS_MIN / cycle - 1e-9))


# TPDO1s allowed ahead: one per SYNC, those of late cycles carried over up to this; more is a
# second producer of the node's TPDO1 (docs/safety.md, CiA 402 hazards)
TPDO_CREDIT_MAX = 3
# cycles of exactly one TPDO1 each after which nothing of a late cycle is carried any more
TPDO_STEADY_CYCLES = 8
# a late SYNC or heartbeat moves the next one: never sooner than this share of the period
# after it (missed slots are skipped, never sent in a burst)
SLOT_MIN_GAP = 0.9
FAULT_STATES = frozenset({State.FAULT, State.FAULT_REACTION_ACTIVE})
HOLD_MARGIN = 0.002  # s: a receive hold ends this long before the next SYNC (at most cycle/4)
# s: no shorter hold (the loop's wait is rounded up to whole milliseconds, epoll: a short
# hold would put the SYNC off; on a short cycle there are few frames to save a wake-up for)
HOLD_MIN = 0.002
SYNC_FRAME = frames.encode_sync()  # no counter (CiA 301 §7.2.5.2.1): the same every cycle


class Master:
    """The engine (see the module docstring)."""

    def __init__(self, config: MasterConfig, nodes: Sequence[NodeConfig]) -> None:
        self.config = config
        self._tpdo_loss_cycles = tpdo_loss_cycles(config.cycle)
        self.nodes: dict[int, Node] = {}
        for n in nodes:
            if n.node_id in self.nodes:
                raise ValueError(f"node {n.node_id} configured twice")
            emcy = EmcyBudget(config.emcy_rate, config.emcy_burst)
            self.nodes[n.node_id] = Node(n, tpdo_struct=_pdo_struct(n.tpdo), emcy=emcy)
        self._tokens = itertools.count(1)
        self._next_cycle: float | None = 0.0
        self._next_heartbeat: float | None = 0.0 if config.own_heartbeat > 0 else None
        self.figures = {
            "syncs_tx": 0,
            "bad_frames": 0,
            "bus_errors": 0,
            "tx_failures": 0,
            "tx_dropped": 0,
            "foreign_master_frames": 0,
            "emcy_dropped": 0,  # EMCY frames over their node's budget, not decoded
        }
        self._left = False
        self._releasing = False
        self._kick = False  # a job was queued for an idle SDO channel
        self._due: float | None = 0.0  # a lower bound of the next deadline
        self._cobs: dict[int, frames.CobId | None] = {}
        self._quiet = False  # the event stepped moved no deadline (a PDO)
        self._claimed = config.listen <= 0  # listened without hearing another master
        self._refused = False  # another master heard while listening: silent for good
        self._listen_until: float | None = None
        self._bringup = BringUp(config, lambda: self._releasing)
        self._emcy_unsaid = False  # EMCY frames dropped that no report counted yet

    # ------------------------------------------------------------ the adapter's side

    def set_want(self, node_id: int, want: Want) -> None:
        self.nodes[node_id].want = want

    def quiet_inputs(self, node_id: int, quiet: bool) -> None:
        """Whether the adapter is quiet for the node: an unchanged TPDO1 tells it nothing
        (its readings and the node's RPDO1 depend on nothing but the TPDO1 and what it is
        told otherwise: docs/decisions/0098). A quiet node's TPDO1 is reported
        (:class:`Inputs`) when its bytes changed and at least every
        :data:`INPUTS_REFRESH` s; the engine's own bookkeeping (the TPDO1 allowance, the
        loss watch, the state behind the statusword) is kept for every one. A node that
        is lost or brought up again is never quiet until the adapter says so again."""
        self.nodes[node_id].quiet = quiet

    def wish(self, node_id: int) -> Want:
        """The node's wish as the engine holds it (STOPPED again once the node is lost)."""
        return self.nodes[node_id].want

    def fault_reset(self, node_id: int, now: float) -> bool:
        """Start one fault reset pulse (bit 7 of the controlword); False when the node is
        not online or its statusword shows no fault (CiA 402-2 §6.2: transition 15 leaves
        FAULT only; nothing is sent, nothing is kept for later) or a pulse is under way.

        The pulse: Disable voltage with bit 7 for :data:`RESET_PULSE_CYCLES`, then
        Disable voltage with bit 7 at 0 for :data:`RESET_CLEAR_CYCLES`, then the word for
        the state and the wish: bit 7 is never set together with a command that moves
        the drive toward operation (0x0086 was sent before)."""
        node = self.nodes[node_id]
        if node.phase is not Phase.ONLINE or now < node.reset_clear_until:
            return False
        if node.state not in FAULT_STATES:
            return False
        cycle = self.config.cycle
        node.reset_until = now + RESET_PULSE_CYCLES * cycle
        node.reset_clear_until = node.reset_until + RESET_CLEAR_CYCLES * cycle
        return True

    def submit(self, node_id: int, index: int, subindex: int, write: bytes | None) -> int:
        """Queue an SDO read (``write`` None) or write for an online node; the token its
        :class:`SdoDone` will carry."""
        node = self.nodes.get(node_id)
        if node is None:
            raise NodeUnavailable(f"node {node_id} is not configured on this line")
        if self._releasing:
            raise NodeUnavailable(f"node {node_id}: the gateway is leaving the line")
        if node.phase is not Phase.ONLINE:
            raise NodeUnavailable(f"node {node_id} is {node.phase.value}, not online")
        token = next(self._tokens)
        node.jobs.append(Job(Purpose.USER, index, subindex, write, token=token))
        self._kick = node.current is None
        return token

    def online(self, node_id: int) -> bool:
        return self.nodes[node_id].phase is Phase.ONLINE

    def release(self, now: float) -> list[Action]:
        """Start leaving the line cleanly: every node that may consume the gateway's
        heartbeat (configuring, started or online) has its ``release`` writes made by SDO
        (0x1016:1 = 0, CiA 301 §7.2.8.3.2.1: an entry with node id 0 and time 0 is not
        used), before any other job, whose transfer under way is aborted; no node is
        probed or configured any more. The cycle (SYNC, RPDOs) and the gateway's heartbeat
        go on meanwhile; :attr:`released` tells when every write ended (answered, refused
        or timed out), then :meth:`leave`."""
        out: list[Action] = []
        self._releasing = True
        if not self._claimed:
            return out  # never on the line: nothing to release
        for node in self.nodes.values():
            drop_jobs(node, "the gateway is leaving the line", out)
            node.probe_at = None
            if node.consumer_set or node.phase in (Phase.CONFIGURE, Phase.START, Phase.ONLINE):
                queue_release(node)
            if node.jobs:
                self._start_job(node, now, out)
        self._due = self._compute_due()
        return out

    @property
    def released(self) -> bool:
        """No release write is waiting or under way (see :meth:`release`)."""
        return not any(
            j.purpose is Purpose.RELEASE
            for n in self.nodes.values()
            for j in (*n.jobs, *((n.current,) if n.current is not None else ()))
        )

    def leave(self, now: float) -> list[Action]:
        """Leaving the line (shutdown): each online node gets its last RPDO (the wish as
        it is, stopped after the gateway's shutdown stop), a SYNC for the synchronous
        RPDOs to act, and, from an NMT master, NMT enter pre-operational (no PDO is
        obeyed after it; the drive's 0x6007 reaction follows when the gateway's
        heartbeat stops)."""
        if not self._claimed:
            self._left = True
            return []  # never on the line (another master holds it): nothing is sent
        online = [n for n in self.nodes.values() if n.phase is Phase.ONLINE]
        out: list[Action] = [Send(self._rpdo(node, now)) for node in online]
        if online and self.config.sync_period > 0:
            out.append(Send(frames.encode_sync()))  # synchronous RPDOs act on a SYNC
        if self.config.nmt_master:
            for node in online:
                out.append(Send(frames.encode_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, node.id)))
        self._left = True
        return out

    # ------------------------------------------------------------ the engine protocol

    @property
    def next_cycle(self) -> float | None:
        """When the next cycle (SYNC, RPDOs) is due; None once the engine left the line."""
        if self._left or not self._claimed:
            return None
        return self._next_cycle

    def hold_until(self, now: float) -> float | None:
        """Until when received frames may wait (the driver's receive hold), or None.

        Only on a steady line: SYNC produced (``sync_period`` > 0), every node online, no
        SDO under way or queued (no bring-up, no job, no release), not leaving. Then what
        the next cycle needs of the line is the TPDO1s the last SYNC asked for, so frames
        may wait until just before the next SYNC (:data:`HOLD_MARGIN`, at most a quarter
        of the cycle, ahead of it): stepped then, before that SYNC and its RPDOs; no hold
        shorter than :data:`HOLD_MIN` (the loop's waits are whole milliseconds). The hold
        also ends as far ahead of any other deadline of the engine (the gateway's
        heartbeat, a node's heartbeat loss), so a heartbeat that came in time is stepped
        before the loss is judged, as without a hold. An EMCY or a boot-up is seen at most
        one cycle later."""
        cfg = self.config
        at = self._next_cycle
        if at is None or cfg.sync_period <= 0 or self._left or self._releasing or self._kick:
            return None
        if not self._claimed:
            return None
        due = self._due
        if due is not None and due < at:
            at = due
        for node in self.nodes.values():
            if node.phase is not Phase.ONLINE or node.current is not None or node.jobs:
                return None
        at -= min(HOLD_MARGIN, cfg.cycle / 4)
        return at if at - now >= HOLD_MIN else None

    def next_deadline(self) -> float | None:
        if self._kick:
            return -math.inf  # a job waits for its node's free SDO channel: step now
        return self._due

    def _node_due(self, node: Node) -> float | None:
        due = node.probe_at
        t = node.phase_deadline
        if t is not None and (due is None or t < due):
            due = t
        t = node.sdo_deadline
        if t is not None and (due is None or t < due):
            due = t
        if node.watch_heartbeat and node.heard_at is not None:
            t = node.heard_at + self.config.heartbeat_factor * node.heartbeat_timeout
            if due is None or t < due:
                due = t
        return due

    def _compute_due(self) -> float | None:
        due = self._next_cycle
        t = self._next_heartbeat
        if t is not None and (due is None or t < due):
            due = t
        node_due = self._node_due
        for node in self.nodes.values():
            t = node_due(node)
            if t is not None and (due is None or t < due):
                due = t
        return due

    def step(self, now: float, event: Event | None = None) -> list[Action]:
        """A frame touches its node only: the timers of every node run when one is due
        (``_due``, a lower bound of the next deadline, is kept so that a busy line costs
        O(1) per frame, not a pass over every node)."""
        out: list[Action] = []
        self._kick = self._quiet = False
        if self._left:
            return out
        if not self._claimed:
            self._listen(now, event, out)
            if not self._claimed:
                return out
        touched: Node | None = None
        if event is not None:
            touched = self._on_event(now, event, out)
        due = self._due
        if event is None or touched is None or (due is not None and now >= due):
            self._timers(now, out)
            for node in self.nodes.values():
                if node.current is None and node.jobs:
                    self._start_job(node, now, out)
            self._due = self._compute_due()
            return out
        if touched.current is None and touched.jobs:
            self._start_job(touched, now, out)
        elif self._quiet:
            return out
        mine = self._node_due(touched)
        if mine is not None and (due is None or mine < due):
            self._due = mine
        return out

    # ------------------------------------------------------------ one master per line

    def _listen(self, now: float, event: Event | None, out: list[Action]) -> None:
        """Before the first frame: listen for ``config.listen`` s (issue 32 item 12: the
        gateway never becomes a second master; the Profibus and DeviceNet lines refuse a
        line another master holds the same way). Then the cycle, the heartbeat and the
        probes start at once, as they would have at the first step."""
        if self._listen_until is None:
            self._listen_until = now + self.config.listen
            self._due = self._listen_until
        if self._refused:
            return
        if isinstance(event, FrameIn):
            cob = self._classify(event.frame.arbitration_id)
            what = None if cob is None else self._master_frame(cob, event.frame)
            if what is not None:
                self.figures["foreign_master_frames"] += 1
                self._refused = True
                self._due = None
                out.append(MasterHeard(what, claimed=False))
                return
        if now < self._listen_until:
            return
        self._claimed = True
        self._next_cycle = now
        if self._next_heartbeat is not None:
            self._next_heartbeat = now
        for node in self.nodes.values():
            if node.probe_at is not None:
                node.probe_at = now
        self._due = now
        out.append(LineClaimed())

    def _master_frame(self, cob: frames.CobId, frame: CanFrame) -> str | None:
        """What a frame from another producer says of another master on the line, or None
        (CiA 301 §7.2.5, §7.2.8: one SYNC producer, one NMT master per network; the node
        id of the gateway's heartbeat is its own)."""
        kind, cfg = cob.kind, self.config
        if kind is Kind.SYNC and cfg.sync_period > 0:
            return "a SYNC from another producer"
        if kind is Kind.NMT and cfg.nmt_master:
            return f"an NMT command ({frame.data.hex()}) from another master"
        if kind is Kind.HEARTBEAT and cfg.own_heartbeat > 0 and cob.node_id == cfg.own_node_id:
            return f"a heartbeat with the gateway's own node id {cfg.own_node_id}"
        if kind is Kind.RPDO and cob.node_id in self.nodes:
            return f"RPDO{cob.pdo} to node {cob.node_id} from another producer"
        return None

    # ------------------------------------------------------------ time

    def _hb_timeout(self, node: Node) -> float:
        return self.config.heartbeat_factor * node.heartbeat_timeout

    def _timers(self, now: float, out: list[Action]) -> None:
        cfg = self.config
        if self._next_heartbeat is not None and now >= self._next_heartbeat:
            out.append(Send(frames.encode_heartbeat(cfg.own_node_id, NmtState.OPERATIONAL)))
            self._next_heartbeat = _next_slot(self._next_heartbeat, cfg.own_heartbeat, now)
        for node in self.nodes.values():
            if node.sdo_deadline is not None and now >= node.sdo_deadline:
                self._sdo_timeout(node, now, out)
            if (
                node.watch_heartbeat
                and node.heard_at is not None
                and now >= node.heard_at + self._hb_timeout(node)
            ):
                waited = round((now - node.heard_at) * 1000)
                self._lose(node, now, f"no heartbeat for {waited} ms", out)
            if node.phase_deadline is not None and now >= node.phase_deadline:
                node.phase_deadline = None
                self._phase_timeout(node, now, out)
            if node.probe_at is not None and now >= node.probe_at and not self._releasing:
                node.probe_at = None
                node.jobs.appendleft(Job(Purpose.PROBE, 0x1000, 0))
        if self._emcy_unsaid:
            self._emcy_unsaid = _emcy_reports(self.nodes.values(), now, out)
        if self._next_cycle is not None and now >= self._next_cycle:
            self._cycle(now, out)
            # late (a loaded machine): the missed slots skipped, no burst to catch up
            self._next_cycle = _next_slot(self._next_cycle, cfg.cycle, now)

    def _cycle(self, now: float, out: list[Action]) -> None:
        if self.config.sync_period > 0:
            out.append(Send(SYNC_FRAME))
            self.figures["syncs_tx"] += 1
        refresh = max(RPDO_REFRESH, self.config.cycle)
        sync = self.config.sync_period > 0
        for node in self.nodes.values():
            if node.phase is not Phase.ONLINE:
                continue
            if sync:
                _tpdo_allowance(node)
            node.tpdo_silent += 1
            if node.tpdo_silent > self._tpdo_loss_cycles:
                # CiA 301 §7.2.2.2: a TPDO of transmission type 1 goes on every SYNC (the
                # event timer without SYNC): a heartbeat alone (another node may send it
                # with this id) does not keep a drive online
                self._lose(node, now, f"no TPDO1 for {self._tpdo_loss_cycles} cycles", out)
                continue
            frame = self._rpdo(node, now)
            if frame.data == node.rpdo_sent and now - node.rpdo_at < refresh:
                continue  # the drive holds the last RPDO (CiA 301 §7.2.2): sent on change
            node.rpdo_sent, node.rpdo_at = frame.data, now
            out.append(Send(frame))
            node.figures["rpdo_tx"] += 1

    def _rpdo(self, node: Node, now: float) -> CanFrame:
        want = node.want
        resetting = 0 if now >= node.reset_clear_until else 1 if now < node.reset_until else 2
        key = (node.state, want, resetting)
        if key == node.rpdo_key and node.rpdo_frame is not None:
            return node.rpdo_frame  # a pure function of these: built once per change
        if resetting:
            # transition 15 on the drive's 0 -> 1 edge of bit 7 (CiA 402-2 §6.2), with
            # Disable voltage, which moves nothing; then bit 7 back at 0 for a cycle, and
            # only then the word for the state (Shutdown, ...): never 0x0086
            cw = int(Cw.DISABLE_VOLTAGE) | (Cw.FAULT_RESET_BIT if resetting == 1 else 0)
            values = (cw, 0)
        else:
            cw = controlword(node.state, want, mode_bits=node.config.mode_bits)
            values = (cw, target(node.state, want))
        data = bytearray()
        for field_, value in zip(node.config.rpdo, values, strict=False):
            data += _pack(field_, value)
        frame = CanFrame(frames.rpdo_id(1, node.id), bytes(data))
        node.rpdo_key, node.rpdo_frame = key, frame
        return frame

    def _phase_timeout(self, node: Node, now: float, out: list[Action]) -> None:
        if node.phase is Phase.RESET:
            self._to_probe(node, now, now, out)  # no boot-up: ask again
        elif node.phase is Phase.START:
            self._lose(node, now, "did not become operational after NMT start", out)
        elif node.phase is Phase.FAILED:
            self._to_probe(node, now, now, out)

    # ------------------------------------------------------------ phases

    def _to_probe(self, node: Node, now: float, at: float, out: list[Action]) -> None:
        drop_jobs(node, "node lost", out)
        node.phase = Phase.PROBE
        node.phase_deadline = None
        node.probe_at = at
        node.watch_heartbeat = False
        node.state = node.statusword = None
        node.want = STOPPED
        node.reset_until = node.reset_clear_until = 0.0
        node.rpdo_sent, node.rpdo_at = None, 0.0
        node.rpdo_key = node.rpdo_frame = None
        node.tpdo_data = node.tpdo_inputs = None
        node.quiet = False

    def _lose(self, node: Node, now: float, reason: str, out: list[Action]) -> None:
        was_seen = node.seen
        drop_jobs(node, f"node lost: {reason}", out)
        self._to_probe(node, now, now + self.config.retry, out)
        node.seen = False
        node.figures["lost"] += 1
        if was_seen:
            out.append(NodeDown(node.id, reason))

    # ------------------------------------------------------------ SDO channel

    def _start_job(self, node: Node, now: float, out: list[Action]) -> None:
        job = node.jobs.popleft()
        transfer = SdoClientTransfer(job.index, job.subindex, job.write)
        node.current, node.transfer = job, transfer
        node.sdo_deadline = now + self.config.sdo_timeout
        out.append(Send(CanFrame(frames.sdo_rx_id(node.id), transfer.first())))

    def _sdo_timeout(self, node: Node, now: float, out: list[Action]) -> None:
        transfer = node.transfer
        if transfer is None:
            node.sdo_deadline = None
            return
        out.append(Send(CanFrame(frames.sdo_rx_id(node.id), transfer.timeout())))
        node.figures["sdo_timeouts"] += 1
        node.sdo_late = min(node.sdo_late + 1, SDO_LATE_MAX)
        self._sdo_end(node, now, out)

    def _on_sdo(self, node: Node, now: float, data: bytes, out: list[Action]) -> None:
        transfer = node.transfer
        if transfer is None:
            self._unexpected_sdo(node, now, "an SDO answer with no request under way", out)
            return
        ignored = transfer.ignored
        reply = transfer.on_response(data)
        if reply is not None:
            out.append(Send(CanFrame(frames.sdo_rx_id(node.id), reply)))
        if transfer.result is None:
            if transfer.ignored != ignored:
                # not this transfer's answer, and its deadline stays as it is (CiA 301
                # §7.2.4.3)
                what = (
                    "an SDO answer that does not answer the request for "
                    f"0x{transfer.index:04X}:{transfer.subindex}"
                )
                self._unexpected_sdo(node, now, what, out)
                return
            node.sdo_deadline = now + self.config.sdo_timeout
            return
        self._sdo_end(node, now, out)

    def _unexpected_sdo(self, node: Node, now: float, what: str, out: list[Action]) -> None:
        """An SDO answer no request under way asked for: the one late answer a transfer
        that ended without one (timed out, aborted) may still get, else a conflict (CiA
        301 §7.2.4: one server answers one client's request once; a second answer, or one
        nobody asked for, is another node's, or forged)."""
        if node.sdo_late > 0:
            node.sdo_late -= 1
            node.figures["sdo_stale"] += 1
            return
        self._conflict(node, f"{what} (unsolicited, or a second answer to one request)", out)

    def _conflict(self, node: Node, what: str, out: list[Action]) -> None:
        node.figures["conflicts"] += 1
        out.append(Conflict(node.id, what))

    def _sdo_end(self, node: Node, now: float, out: list[Action]) -> None:
        job, transfer = node.current, node.transfer
        node.current = node.transfer = None
        node.sdo_deadline = None
        if job is None or transfer is None or transfer.result is None:
            return
        result = transfer.result
        node.figures["sdo_transfers"] += 1
        if result.abort_code is not None:
            node.figures["sdo_aborts"] += 1
        if not self._bringup.answered(node, now, job, result, out):
            out.append(SdoDone(job.token, node.id, result))

    # ------------------------------------------------------------ frames in

    def _on_event(self, now: float, event: Event, out: list[Action]) -> Node | None:
        """The node the event concerned (None: the line, or no node of ours)."""
        if isinstance(event, FrameIn):
            return self._on_frame(now, event.frame, out)
        if isinstance(event, BadFrame):
            self.figures["bad_frames"] += 1
        elif isinstance(event, BusErrorIn):
            self.figures["bus_errors"] += 1
            names = ", ".join(sorted(c.value for c in event.conditions))
            out.append(Report(None, f"CAN bus: {names}"))
        elif isinstance(event, LinkDown):
            for node in self.nodes.values():
                if node.phase is not Phase.PROBE or node.seen:
                    self._lose(node, now, f"CAN link down: {event.reason}", out)
        elif isinstance(event, TxFailed):
            self.figures["tx_failures"] += 1
            self.figures["tx_dropped"] += event.dropped
        return None

    def _classify(self, cob_id: int) -> frames.CobId | None:
        """``frames.classify`` remembered per COB-ID (every frame received asks)."""
        try:
            return self._cobs[cob_id]
        except KeyError:
            pass
        try:
            cob: frames.CobId | None = frames.classify(cob_id)
        except CanOpenDecodeError:
            cob = None
        if len(self._cobs) < COB_CACHE:
            self._cobs[cob_id] = cob
        return cob

    def _on_frame(self, now: float, frame: CanFrame, out: list[Action]) -> Node | None:
        cob = self._classify(frame.arbitration_id)
        if cob is None:
            self.figures["bad_frames"] += 1
            return None
        node = self.nodes.get(cob.node_id)
        kind = cob.kind
        if node is None:
            # another node, or a broadcast: a SYNC or NMT of another master, a heartbeat
            # with the gateway's own node id
            if kind is not Kind.TPDO:
                what = self._master_frame(cob, frame)
                if what is not None:
                    self.figures["foreign_master_frames"] += 1
                    out.append(MasterHeard(what, claimed=True))
            return None
        if kind is Kind.TPDO:
            self._quiet = True  # a PDO moves no deadline of its node
            if cob.pdo == 1 and node.phase is Phase.ONLINE:
                self._on_tpdo(node, now, frame.data, out)
        elif kind is Kind.RPDO:
            self.figures["foreign_master_frames"] += 1
            what = f"RPDO{cob.pdo} to node {node.id} from another producer"
            out.append(MasterHeard(what, claimed=True))
        elif kind is Kind.SDO_TX:
            self._on_sdo(node, now, frame.data, out)
        elif kind is Kind.HEARTBEAT:
            self._on_heartbeat(node, now, frame.data, out)
        elif kind is Kind.EMCY:
            if not node.emcy.take(now):
                self._emcy_over(node, now, out)
                return node
            try:
                emcy = frames.decode_emcy(frame.data, cob_id=frame.arbitration_id)
            except CanOpenDecodeError as exc:
                self.figures["bad_frames"] += 1
                out.append(Report(node.id, f"bad EMCY: {exc}"))
                return node
            node.figures["emcy_rx"] += 1
            out.append(EmcyIn(node.id, emcy))
        return node

    def _emcy_over(self, node: Node, now: float, out: list[Action]) -> None:
        """An EMCY over its node's budget: counted, not decoded; reported at most once per
        :data:`~adapters.canopen.master.emcy.EMCY_REPORT_EVERY` (the rest by
        :func:`_emcy_reports` when that time has passed)."""
        self.figures["emcy_dropped"] += 1
        self._quiet = True  # it moves no deadline
        budget = node.emcy
        if budget.report_due(now):
            out.append(Report(node.id, budget.report(node.id, now)))
        else:
            self._emcy_unsaid = True

    def _on_heartbeat(self, node: Node, now: float, data: bytes, out: list[Action]) -> None:
        try:
            state = frames.decode_heartbeat(data)
        except CanOpenDecodeError:
            self.figures["bad_frames"] += 1
            return
        node.figures["heartbeats_rx"] += 1
        node.heard, node.heard_at = state, now
        phase = node.phase
        if state is NmtState.BOOTUP:
            node.consumer_set = False  # its OD back at the defaults
            if phase is Phase.RESET:
                self._to_probe(node, now, now, out)
            elif phase in (Phase.CONFIGURE, Phase.START, Phase.ONLINE):
                self._lose(node, now, "the node restarted (boot-up message)", out)
                node.probe_at = now  # it is there: bring it up at once
            return
        if phase is Phase.START and state is NmtState.OPERATIONAL:
            self._bringup.online(node, out)
        elif phase is Phase.ONLINE and state is not NmtState.OPERATIONAL:
            self._lose(node, now, f"the node left operational ({state.name.lower()})", out)

    def _on_tpdo(self, node: Node, now: float, data: bytes, out: list[Action]) -> None:
        """TPDO1 in. A drive at rest repeats its TPDO1 every SYNC: the same data gives the
        same :class:`Inputs` (the statusword in it is the node's already, so no state
        changes and no fault read starts), the same object again without decoding."""
        node.tpdo_silent = 0
        if self.config.sync_period > 0:
            node.tpdo_in_cycle += 1
            node.tpdo_credit -= 1
            if node.tpdo_credit < 0:
                node.tpdo_credit = 0
                self._conflict(node, "a second TPDO1 in one SYNC cycle", out)
        last = node.tpdo_inputs
        if data == node.tpdo_data and last is not None and last.statusword == node.statusword:
            node.figures["tpdo_rx"] += 1
            if node.quiet and now < node.inputs_due:
                return  # the steady case: nothing new for a quiet adapter
            node.inputs_due = now + INPUTS_REFRESH
            out.append(last)
            return
        inputs = self._decode_tpdo(node, data)
        if inputs is not None:
            node.inputs_due = now + INPUTS_REFRESH
            out.append(inputs)
        node.tpdo_data, node.tpdo_inputs = data, inputs

    def _decode_tpdo(self, node: Node, data: bytes) -> Inputs | None:
        """The general path: unpack, the state behind a new statusword, a fault's reads."""
        try:
            values = _unpack(node.config.tpdo, data, node.tpdo_struct)
        except CanOpenDecodeError:
            node.figures["bad_pdos"] += 1
            return None
        node.figures["tpdo_rx"] += 1
        statusword = values[0]
        if statusword != node.statusword:
            try:
                state: State | None = decode_state(statusword)
            except CanOpenDecodeError:
                state = None
            previous = node.state
            node.statusword, node.state = statusword, state
            if state in FAULT_STATES and previous not in FAULT_STATES:
                read_fault(node)
        return Inputs(node.id, statusword, values[1:])

    # ------------------------------------------------------------ diagnostics

    def node_diagnostics(self, node_id: int) -> dict[str, object]:
        node = self.nodes[node_id]
        return {
            "phase": node.phase.value,
            "nmt_state": None if node.heard is None else node.heard.name.lower(),
            "statusword": None if node.statusword is None else f"0x{node.statusword:04X}",
            "cia402_state": None if node.state is None else node.state.value,
            "problem": node.last_problem,
            "sdo_queue": len(node.jobs) + (node.current is not None),
            **node.figures,
            "emcy_dropped": node.emcy.dropped,
        }


def _next_slot(slot: float, period: float, now: float) -> float:
    """The slot after ``slot`` (sent at ``now``): on the grid, unless the send was late;
    then a period after ``now`` whenever the grid's next slot is nearer than
    :data:`SLOT_MIN_GAP` periods: the missed slots are skipped, never sent in a burst."""
    nxt = slot + period
    if nxt < now + SLOT_MIN_GAP * period:
        return now + period
    return nxt


def _pack(field_: PdoField, value: int) -> bytes:
    size = field_.size
    bits = size * 8
    if field_.signed:
        low, high = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    else:
        low, high = 0, (1 << bits) - 1
    return max(low, min(high, value)).to_bytes(size, "little", signed=field_.signed)


_STRUCT_CODES = {1: "b", 2: "h", 4: "i", 8: "q"}  # signed; upper case: unsigned


def _pdo_struct(fields_: Sequence[PdoField]) -> struct.Struct | None:
    """The mapping as one little-endian struct (CiA 301 §7.4.7.1: PDO data is packed
    little-endian in mapping order), None when a field is not 1, 2, 4 or 8 bytes."""
    codes_: list[str] = []
    for f in fields_:
        code = _STRUCT_CODES.get(f.size)
        if code is None or f.entry.bits % 8:
            return None
        codes_.append(code if f.signed else code.upper())
    return struct.Struct("<" + "".join(codes_))


def _unpack(
    fields_: Sequence[PdoField], data: bytes, compiled: struct.Struct | None = None
) -> tuple[int, ...]:
    """The mapped values of a PDO (bytes beyond the mapping ignored);
    :class:`CanOpenDecodeError` when it is shorter than the mapping. ``compiled``: the
    same mapping as one struct (:func:`_pdo_struct`), a short cut."""
    if compiled is not None:
        if len(data) >= compiled.size:
            return compiled.unpack_from(data)
        raise CanOpenDecodeError(f"TPDO of {len(data)} bytes, mapping needs more", data)
    out: list[int] = []
    offset = 0
    for f in fields_:
        size = f.size
        if offset + size > len(data):
            raise CanOpenDecodeError(f"TPDO of {len(data)} bytes, mapping needs more", data)
        out.append(int.from_bytes(data[offset : offset + size], "little", signed=f.signed))
        offset += size
    return tuple(out)


def _emcy_reports(nodes: Iterable[Node], now: float, out: list[Action]) -> bool:
    """The reports of EMCY frames dropped whose time has come (a flood that stopped is
    reported too); whether frames dropped are left for a later report."""
    unsaid = False
    for node in nodes:
        budget = node.emcy
        if budget.report_due(now):
            out.append(Report(node.id, budget.report(node.id, now)))
        unsaid = unsaid or budget.unsaid > 0
    return unsaid


def _tpdo_allowance(node: Node) -> None:
    """A SYNC goes out: one TPDO1 more allowed. The TPDO1s of cycles the drive (or a loaded
    line) answered late are carried over, up to :data:`TPDO_CREDIT_MAX`, so that a drive
    catching up, two TPDO1s in one cycle, is no conflict; once it answered exactly one per
    cycle for :data:`TPDO_STEADY_CYCLES`, nothing is carried (a skipped TPDO1 does not allow
    a second producer one for ever)."""
    node.tpdo_steady = node.tpdo_steady + 1 if node.tpdo_in_cycle == 1 else 0
    node.tpdo_in_cycle = 0
    if node.tpdo_steady >= TPDO_STEADY_CYCLES:
        node.tpdo_credit = 1
    else:
        node.tpdo_credit = min(node.tpdo_credit + 1, TPDO_CREDIT_MAX)
