"""The SDO side of a node's bring-up on the master, sans-IO: what each answered transfer
of the engine's own does next (module docstring of :mod:`.engine`, steps 1-3).

PROBE's answer (0x1000, the device profile checked; a reset where the config asks for
one) starts CONFIGURE: the bring-up writes, each read back and compared (an optional
step refused is reported and passed over), then the report reads, then NMT start
(START; ONLINE with an operational heartbeat). A refusal stops the bring-up: the node is
not started (FAILED, tried again after ``failed_retry``; its heartbeat consumer released
when it was set). The fault reads on entering FAULT and the release writes of a clean
leave are answered here too. The engine (:class:`~.engine.Master`) runs the SDO channel
and hands each ended transfer to :meth:`BringUp.answered`.
"""

from __future__ import annotations

from collections.abc import Callable

from adapters.can.events import Send
from adapters.canopen.codec import codes, frames
from adapters.canopen.codec.frames import CanFrame, NmtCommand, NmtState
from adapters.canopen.master.events import (
    Action,
    Configured,
    FaultInfo,
    MasterConfig,
    NodeProblem,
    NodeSeen,
    NodeUp,
    Report,
    SdoDone,
)
from adapters.canopen.master.node import Job, Node, Phase, Purpose

SDO_LATE_MAX = 4  # late answers expected at most (transfers ended without an answer)


class BringUp:
    """What the answers of the engine's own SDO transfers do (see the module docstring)."""

    def __init__(self, config: MasterConfig, leaving: Callable[[], bool]) -> None:
        """``leaving``: whether the gateway is leaving the line (its release writes)."""
        self.config = config
        self.leaving = leaving
        self._handlers = {
            Purpose.PROBE: self._probed,
            Purpose.WRITE: self._written,
            Purpose.VERIFY: self._verified,
            Purpose.REPORT: self._reported,
            Purpose.FAULT: self._fault_read,
            Purpose.RELEASE: self._released_one,
        }

    def answered(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> bool:
        """What the ended transfer of ``job`` does next; False for a job that is not the
        engine's own (the adapter's: its :class:`SdoDone` is the caller's)."""
        handler = self._handlers.get(job.purpose)
        if handler is None:
            return False
        handler(node, now, job, result, out)
        return True

    def _configure(self, node: Node, now: float, out: list[Action]) -> None:
        """PROBE -> CONFIGURE: the bring-up writes, one after the other."""
        if self.config.nmt_master:
            out.append(Send(frames.encode_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, node.id)))
        node.phase = Phase.CONFIGURE
        node.step = 0
        node.reports = {}
        self._next_step(node, now, out)

    def _next_step(self, node: Node, now: float, out: list[Action]) -> None:
        steps = node.config.steps
        if node.step < len(steps):
            s = steps[node.step]
            node.jobs.appendleft(Job(Purpose.WRITE, s.index, s.subindex, s.data, step=node.step))
            return
        pending = [k for k in node.config.reports if k not in node.reports]
        if pending:
            node.jobs.appendleft(Job(Purpose.REPORT, *pending[0]))
            return
        out.append(Configured(node.id, dict(node.reports)))
        node.phase = Phase.START
        node.watch_heartbeat = True
        if node.heard_at is None:
            node.heard_at = now
        if self.config.nmt_master:
            out.append(Send(frames.encode_nmt(NmtCommand.START, node.id)))
            node.phase_deadline = now + max(
                self.config.heartbeat_factor * node.heartbeat_timeout, self.config.boot_timeout
            )
        if node.heard is NmtState.OPERATIONAL and not self.config.nmt_master:
            self.online(node, out)

    def online(self, node: Node, out: list[Action]) -> None:
        """START -> ONLINE: the node is operational (its heartbeat says so)."""
        node.phase = Phase.ONLINE
        node.tpdo_silent = 0
        node.tpdo_credit = 1
        node.phase_deadline = None
        node.last_problem = None
        out.append(NodeUp(node.id))

    def _fail(self, node: Node, now: float, text: str, code: int | None, out: list[Action]) -> None:
        drop_jobs(node, f"bring-up failed: {text}", out)
        node.phase = Phase.FAILED
        node.probe_at = None
        node.watch_heartbeat = False  # not started: its silence is no news
        node.phase_deadline = now + self.config.failed_retry
        node.last_problem = text
        out.append(NodeProblem(node.id, text, code))
        if node.consumer_set:
            # a drive the gateway does not start must not watch its heartbeat: it would
            # react per 0x6007 when the gateway stops (EMCY 0x8130 on a clean stop)
            queue_release(node)

    def _probed(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        if node.phase is not Phase.PROBE:
            return
        if not result.ok:
            if result.by_server:  # it answers, but not 0x1000: no CANopen device we know
                self._fail(node, now, f"device type 0x1000: {result.message}", None, out)
            else:
                node.probe_at = now + self.config.retry
                if self.config.nmt_master and node.heard is NmtState.STOPPED:
                    # a stopped node serves no SDO (CiA 301 §7.3.2.2.3): wake it up
                    out.append(Send(frames.encode_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, node.id)))
            return
        if not node.seen:
            node.seen = True
            out.append(NodeSeen(node.id))
        profile = node.config.device_profile
        device_type = int.from_bytes(result.data, "little")
        if profile is not None and device_type & 0xFFFF != profile:
            text = (
                f"device type 0x1000 is 0x{device_type:08X}: profile {device_type & 0xFFFF}, "
                f"not CiA {profile}"
            )
            self._fail(node, now, text, None, out)
            return
        if (
            self.config.nmt_master
            and node.config.reset_if_operational
            and node.heard in (NmtState.OPERATIONAL, None)  # or not known: no heartbeat yet
            and not node.reset_done
        ):
            node.reset_done = True
            node.phase = Phase.RESET
            node.phase_deadline = now + self.config.boot_timeout
            out.append(Send(frames.encode_nmt(NmtCommand.RESET_NODE, node.id)))
            heard = "was operational" if node.heard is not None else "sends no heartbeat"
            out.append(Report(node.id, f"node {heard}: NMT reset node sent"))
            return
        self._configure(node, now, out)

    def _written(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        s = node.config.steps[job.step]
        if not result.ok:
            who = "refused" if result.by_server else "failed"
            text = (
                f"{s.what}: write of 0x{s.index:04X}:{s.subindex} = 0x{s.data[::-1].hex()} "
                f"{who}: {result.message}"
            )
            if s.optional and result.by_server:
                self._pass_over(node, now, text, out)
                return
            self._fail(node, now, text, result.abort_code, out)
            return
        if s.index == 0x1017 and s.subindex == 0:
            node.watch_heartbeat = True  # the producer runs from now on
            node.heard_at = now
        if (s.index, s.subindex) == (0x1016, 1) and int.from_bytes(s.data, "little"):
            node.consumer_set = True  # it watches the gateway's heartbeat from now on
        if s.read_back:
            node.jobs.appendleft(Job(Purpose.VERIFY, s.index, s.subindex, step=job.step))
            return
        node.step += 1
        self._next_step(node, now, out)

    def _verified(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        s = node.config.steps[job.step]
        if not result.ok:
            text = f"{s.what}: read-back of 0x{s.index:04X}:{s.subindex} failed: {result.message}"
            if s.optional and result.by_server:
                self._pass_over(node, now, text, out)
                return
            self._fail(node, now, text, result.abort_code, out)
            return
        wrote = int.from_bytes(s.data, "little") & s.mask
        read = int.from_bytes(result.data, "little") & s.mask
        if wrote != read:
            text = (
                f"{s.what}: 0x{s.index:04X}:{s.subindex} reads back 0x{read:X} after "
                f"writing 0x{wrote:X}"
            )
            if s.optional:
                self._pass_over(node, now, text, out)
                return
            self._fail(node, now, text, None, out)
            return
        node.step += 1
        self._next_step(node, now, out)

    def _pass_over(self, node: Node, now: float, text: str, out: list[Action]) -> None:
        """An optional step the node refused (an unused PDO it will not switch off):
        reported, and the bring-up goes on with the next step."""
        out.append(Report(node.id, f"{text} (the bring-up goes on)"))
        node.step += 1
        self._next_step(node, now, out)

    def _reported(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        node.reports[(job.index, job.subindex)] = result.data if result.ok else b""
        self._next_step(node, now, out)

    def _released_one(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        if result.ok:
            node.figures["released"] += 1
            node.consumer_set = False
            return
        what = "leaving" if self.leaving() else "not started"
        text = (
            f"{what}: write of 0x{job.index:04X}:{job.subindex} failed: {result.message} "
            "(the drive reacts per 0x6007 when the gateway's heartbeat stops)"
        )
        out.append(Report(node.id, text))

    def _fault_read(
        self, node: Node, now: float, job: Job, result: frames.SdoResult, out: list[Action]
    ) -> None:
        if result.ok:
            node.fault_reads[(job.index, job.subindex)] = result.data
        node.fault_pending -= 1
        if node.fault_pending <= 0:
            out.append(FaultInfo(node.id, dict(node.fault_reads)))


def queue_release(node: Node) -> None:
    """Queue the node's release writes (its consumer of the gateway's heartbeat off)."""
    for s in node.config.release:
        node.jobs.append(Job(Purpose.RELEASE, s.index, s.subindex, s.data))


def drop_jobs(node: Node, why: str, out: list[Action]) -> None:
    """End every SDO job of the node; a transfer under way is aborted on the line
    (CiA 301 §7.2.4.3.17, general error) so that the server starts afresh."""
    jobs = list(node.jobs)
    if node.current is not None:
        jobs.insert(0, node.current)
        transfer = node.transfer
        if transfer is not None and transfer.result is None:
            abort = frames.Abort(transfer.index, transfer.subindex, codes.ABORT_GENERAL)
            out.append(Send(CanFrame(frames.sdo_rx_id(node.id), frames.encode_sdo_request(abort))))
            node.sdo_late = min(node.sdo_late + 1, SDO_LATE_MAX)
    node.jobs.clear()
    node.current = node.transfer = None
    node.sdo_deadline = None
    for job in jobs:
        if job.purpose is Purpose.USER:
            out.append(SdoDone(job.token, node.id, error=why))


def read_fault(node: Node) -> None:
    """Queue the reads of a node that entered FAULT (``NodeConfig.fault_reads``)."""
    node.fault_reads = {}
    reads = node.config.fault_reads
    node.fault_pending = len(reads)
    for index, subindex in reads:
        node.jobs.append(Job(Purpose.FAULT, index, subindex))
