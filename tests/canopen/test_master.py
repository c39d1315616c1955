"""The CANopen master engine, stepped with an injected clock against a scripted node
(CiA 301 SDO server and NMT slave, CiA 402 transitions from adapters.canopen.codec.cia402)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.canopen.codec import cia402, codes
from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import DeviceCommand, State
from adapters.canopen.master import (
    STOPPED,
    Configured,
    EmcyIn,
    FaultInfo,
    FrameIn,
    Inputs,
    Master,
    MasterConfig,
    NodeConfig,
    NodeDown,
    NodeProblem,
    NodeSeen,
    NodeUnavailable,
    NodeUp,
    PdoField,
    Phase,
    Report,
    SdoDone,
    SdoStep,
    Send,
    Want,
    controlword,
)
from adapters.canopen.master.control import VL_OPERATION_BITS, target
from adapters.canopen.master.engine import RESET_PULSE_CYCLES

CYCLE = 0.01
HB_MS = 100


def config(**kw: object) -> MasterConfig:
    base: dict[str, object] = {
        "sync_period": CYCLE,
        "sdo_timeout": 0.1,
        "heartbeat_factor": 3.0,
        "retry": 0.5,
        "failed_retry": 5.0,
    }
    base.update(kw)
    return MasterConfig(**base)  # type: ignore[arg-type]


def node_config(**kw: object) -> NodeConfig:
    base: dict[str, object] = {
        "node_id": 5,
        "heartbeat_ms": HB_MS,
        "steps": (
            SdoStep(0x1017, 0, HB_MS.to_bytes(2, "little"), "producer heartbeat time 0x1017"),
            SdoStep(0x6060, 0, b"\x02", "modes of operation 0x6060"),
        ),
        "rpdo": (
            PdoField(f.MappingEntry(0x6040, 0, 16)),
            PdoField(f.MappingEntry(0x6042, 0, 16), signed=True),
        ),
        "tpdo": (
            PdoField(f.MappingEntry(0x6041, 0, 16)),
            PdoField(f.MappingEntry(0x6044, 0, 16), signed=True),
        ),
        "reports": ((0x605A, 0),),
    }
    base.update(kw)
    return NodeConfig(**base)  # type: ignore[arg-type]


class FakeNode:
    """An NMT slave and SDO server with a CiA 402 state machine, answering at once."""

    def __init__(self, node_id: int = 5) -> None:
        self.id = node_id
        self.od: dict[tuple[int, int], bytes] = {
            (0x1000, 0): (0x00020192).to_bytes(4, "little"),
            (0x1017, 0): bytes(2),
            (0x6060, 0): b"\x00",
            (0x605A, 0): (2).to_bytes(2, "little"),
            (0x1001, 0): b"\x00",
            (0x603F, 0): bytes(2),
        }
        self.nmt = f.NmtState.PRE_OPERATIONAL
        self.state = State.SWITCH_ON_DISABLED
        self.refuse: dict[tuple[int, int], int] = {}
        self.silent = False
        self.controlwords: list[int] = []
        self.nmt_seen: list[f.NmtCommand] = []
        self.sdo_requests: list[f.SdoRequest] = []
        self.sdo_log: list[str] = []
        self.tpdo_on_sync = True
        self.sdo_silent = False  # SDO requests unanswered, the rest goes on

    def statusword(self) -> int:
        return cia402.statusword_bits(self.state) | cia402.SW_REMOTE

    def receive(self, frame: f.CanFrame) -> list[f.CanFrame]:
        if frame.cob_id == f.sdo_rx_id(self.id):
            request = f.decode_sdo_request(frame.data)
            self.sdo_log.append("abort" if isinstance(request, f.Abort) else "request")
            if self.silent or self.sdo_silent or isinstance(request, f.Abort):
                return []
            self.sdo_log.append("response")
        if self.silent:
            return []
        if frame.cob_id == f.COB_NMT:
            nmt = f.decode_nmt(frame.data)
            if nmt.node_id not in (0, self.id):
                return []
            self.nmt_seen.append(nmt.command)
            if nmt.command is f.NmtCommand.START:
                self.nmt = f.NmtState.OPERATIONAL
            elif nmt.command is f.NmtCommand.ENTER_PRE_OPERATIONAL:
                self.nmt = f.NmtState.PRE_OPERATIONAL
            elif nmt.command is f.NmtCommand.RESET_NODE:
                self.nmt = f.NmtState.PRE_OPERATIONAL
                return [f.encode_heartbeat(self.id, f.NmtState.BOOTUP)]
            return []
        if frame.cob_id == f.sdo_rx_id(self.id):
            return [f.CanFrame(f.sdo_tx_id(self.id), self._sdo(frame.data))]
        if frame.cob_id == f.COB_SYNC and self.nmt is f.NmtState.OPERATIONAL:
            return [self.tpdo()] if self.tpdo_on_sync else []  # transmission type 1
        if frame.cob_id == f.rpdo_id(1, self.id) and self.nmt is f.NmtState.OPERATIONAL:
            cw = int.from_bytes(frame.data[:2], "little")
            previous = self.controlwords[-1] if self.controlwords else 0
            self.controlwords.append(cw)
            command = cia402.device_command(cw)
            if command is DeviceCommand.FAULT_RESET and previous & 0x80:
                command = None  # no edge
            if command is not None:
                after = cia402.next_state(self.state, command)
                if after is not None:
                    self.state = after
            return []
        return []

    def _sdo(self, data: bytes) -> bytes:
        request = f.decode_sdo_request(data)
        self.sdo_requests.append(request)
        assert isinstance(request, f.InitiateUpload | f.InitiateDownload)
        key = (request.index, request.subindex)
        if key in self.refuse:
            return f.encode_sdo_response(f.Abort(*key, self.refuse[key]))
        if isinstance(request, f.InitiateUpload):
            if key not in self.od:
                return f.encode_sdo_response(f.Abort(*key, codes.ABORT_NO_OBJECT))
            return f.encode_sdo_response(f.InitiateUploadResponse(*key, self.od[key]))
        self.od[key] = request.data
        return f.encode_sdo_response(f.InitiateDownloadResponse(*key))

    def heartbeat(self) -> f.CanFrame:
        return f.encode_heartbeat(self.id, self.nmt)

    def tpdo(self, velocity: int = 0) -> f.CanFrame:
        return f.CanFrame(
            f.tpdo_id(1, self.id),
            self.statusword().to_bytes(2, "little") + velocity.to_bytes(2, "little", signed=True),
        )


class Line:
    """The engine and fake nodes on an ideal bus, stepped on a fake clock."""

    def __init__(self, master: Master, *nodes: FakeNode) -> None:
        self.master = master
        self.nodes = {n.id: n for n in nodes}
        self.now = 0.0
        self.actions: list[object] = []
        self.sent: list[f.CanFrame] = []

    def _deliver(self, actions: Sequence[object]) -> None:
        queue = list(actions)
        while queue:
            action = queue.pop(0)
            if not isinstance(action, Send):
                self.actions.append(action)
                continue
            self.sent.append(action.frame)
            for node in self.nodes.values():
                for reply in node.receive(action.frame):
                    queue.extend(self.master.step(self.now, FrameIn(reply)))

    def inject(self, frame: f.CanFrame) -> None:
        self._deliver(list(self.master.step(self.now, FrameIn(frame))))

    def run(self, seconds: float, *, heartbeats: bool = True, tpdo: bool = True) -> None:
        end = self.now + seconds
        next_hb = self.now
        while self.now < end:
            deadline = self.master.next_deadline()
            step_at = min(end, deadline if deadline is not None else end, next_hb)
            self.now = max(self.now, step_at)
            self._deliver(list(self.master.step(self.now)))
            for node in self.nodes.values():
                node.tpdo_on_sync = tpdo
            if self.now >= next_hb:
                next_hb = self.now + HB_MS / 1000
                for node in self.nodes.values():
                    if heartbeats and not node.silent:
                        self.inject(node.heartbeat())
            if self.now >= end:
                break
            self.now += 1e-4

    def of(self, kind: type) -> list[object]:
        return [a for a in self.actions if isinstance(a, kind)]


def node_state(node: FakeNode) -> State:
    return node.state


def up(**kw: object) -> tuple[Line, FakeNode]:
    node = FakeNode()
    line = Line(Master(config(**kw), [node_config()]), node)
    line.run(0.5)
    return line, node


# ---------------------------------------------------------------- the CiA 402 master side


@pytest.mark.parametrize("start", list(State))
def test_run_reaches_operation_enabled_from_every_state_but_fault(start: State) -> None:
    """Stepping the drive with the controlword chosen for its state reaches OE (or stays
    in FAULT / FAULT_REACTION_ACTIVE: only a reset edge leaves them)."""
    state = start
    wish = Want(run=True, target=100)
    for _ in range(6):
        after = cia402.next_state(state, cia402.device_command(controlword(state, wish)))  # type: ignore[arg-type]
        state = after or state
    if start in (State.FAULT, State.FAULT_REACTION_ACTIVE):
        assert state is start
    elif start is State.NOT_READY_TO_SWITCH_ON:
        assert state is start  # the drive's own transition 1 is not the master's
    else:
        assert state is State.OPERATION_ENABLED


@pytest.mark.parametrize(
    ("state", "wish", "command"),
    [
        (State.SWITCH_ON_DISABLED, Want(run=True), DeviceCommand.SHUTDOWN),  # 2
        (State.READY_TO_SWITCH_ON, Want(run=True), DeviceCommand.SWITCH_ON),  # 3
        (State.SWITCHED_ON, Want(run=True), DeviceCommand.ENABLE_OPERATION),  # 4
        (State.OPERATION_ENABLED, STOPPED, DeviceCommand.SWITCH_ON),  # 5 disable operation
        (State.SWITCHED_ON, STOPPED, DeviceCommand.SWITCH_ON),  # held, switched on
        (State.OPERATION_ENABLED, Want(coast=True, run=True), DeviceCommand.DISABLE_VOLTAGE),  # 9
        (State.OPERATION_ENABLED, Want(quick_stop=True), DeviceCommand.QUICK_STOP),  # 11
        (State.QUICK_STOP_ACTIVE, Want(quick_stop=True), DeviceCommand.QUICK_STOP),  # held
        (State.QUICK_STOP_ACTIVE, Want(run=True), DeviceCommand.DISABLE_VOLTAGE),  # 12, never 16
        (State.SWITCHED_ON, Want(quick_stop=True), DeviceCommand.DISABLE_VOLTAGE),  # 10
        (State.FAULT, Want(run=True), DeviceCommand.DISABLE_VOLTAGE),  # waits for the reset
    ],
)
def test_controlword_for_state_and_wish(state: State, wish: Want, command: DeviceCommand) -> None:
    assert cia402.device_command(controlword(state, wish)) is command


def test_vl_operation_bits_and_target() -> None:
    assert controlword(State.OPERATION_ENABLED, Want(run=True), mode_bits=VL_OPERATION_BITS) == 0x7F
    assert controlword(None, Want(run=True)) == 0  # nothing known: never toward a start
    assert target(State.OPERATION_ENABLED, Want(run=True, target=-300)) == -300
    assert target(State.SWITCHED_ON, Want(run=True, target=-300)) == 0
    assert target(State.OPERATION_ENABLED, Want(run=True, quick_stop=True, target=5)) == 0


@given(st.sampled_from(list(State)), st.booleans(), st.booleans(), st.booleans())
def test_no_wish_without_run_ever_enables_operation(
    state: State, quick: bool, coast: bool, _: bool
) -> None:
    """Rule 1 at the controlword: without run, no word moves a drive into OPERATION_ENABLED."""
    cw = controlword(state, Want(run=False, quick_stop=quick, coast=coast))
    command = cia402.device_command(cw)
    assert command is not None
    assert cia402.next_state(state, command) is not State.OPERATION_ENABLED
    assert not cw & 0x80  # the reset bit is never part of the steady word


# ---------------------------------------------------------------- bring-up


def test_bring_up_in_order_then_operational() -> None:
    line, node = up()
    seen = [type(a).__name__ for a in line.actions if isinstance(a, NodeSeen | Configured | NodeUp)]
    assert seen == ["NodeSeen", "Configured", "NodeUp"]
    configured = line.of(Configured)[0]
    assert isinstance(configured, Configured)
    assert configured.reports == {(0x605A, 0): (2).to_bytes(2, "little")}
    requests = [
        (type(r).__name__, r.index, r.subindex)
        for r in node.sdo_requests
        if isinstance(r, f.InitiateUpload | f.InitiateDownload)
    ]
    assert requests[:6] == [
        ("InitiateUpload", 0x1000, 0),
        ("InitiateDownload", 0x1017, 0),
        ("InitiateUpload", 0x1017, 0),  # read back
        ("InitiateDownload", 0x6060, 0),
        ("InitiateUpload", 0x6060, 0),
        ("InitiateUpload", 0x605A, 0),
    ]
    assert node.nmt_seen == [f.NmtCommand.ENTER_PRE_OPERATIONAL, f.NmtCommand.START]
    assert node.od[(0x1017, 0)] == HB_MS.to_bytes(2, "little")
    assert line.master.online(5)
    # SYNC every cycle, RPDO1 after it
    assert f.encode_sync() in line.sent
    assert any(fr.cob_id == 0x205 for fr in line.sent)


def test_the_drive_is_stepped_to_run_and_back() -> None:
    line, node = up()
    line.master.set_want(5, Want(run=True, target=1500))
    line.run(0.5)
    assert node.state is State.OPERATION_ENABLED
    last = [fr for fr in line.sent if fr.cob_id == 0x205][-1]
    assert int.from_bytes(last.data[2:], "little", signed=True) == 1500
    line.master.set_want(5, STOPPED)
    line.run(0.3)
    assert node_state(node) is State.SWITCHED_ON


def test_a_refused_write_is_a_problem_and_the_node_is_not_started() -> None:
    node = FakeNode()
    node.refuse[(0x6060, 0)] = 0x06090030
    line = Line(Master(config(), [node_config()]), node)
    line.run(0.5)
    problem = line.of(NodeProblem)[0]
    assert isinstance(problem, NodeProblem)
    assert problem.text == (
        "modes of operation 0x6060: write of 0x6060:0 = 0x02 refused: 0x06090030 value "
        "range of parameter exceeded"
    )
    assert problem.abort_code == 0x06090030
    assert f.NmtCommand.START not in node.nmt_seen
    assert not line.master.online(5)
    assert not line.of(NodeUp)
    assert not any(fr.cob_id == 0x205 for fr in line.sent)  # no PDO to it
    node.refuse.clear()
    line.run(5.5)  # failed_retry: tried again, and now it goes
    assert line.master.online(5)


def test_a_read_back_that_differs_is_a_problem() -> None:
    class Stubborn(FakeNode):
        def _sdo(self, data: bytes) -> bytes:
            reply = super()._sdo(data)
            self.od[(0x1017, 0)] = (50).to_bytes(2, "little")
            return reply

    node = Stubborn()
    line = Line(Master(config(), [node_config()]), node)
    line.run(0.3)
    problem = line.of(NodeProblem)[0]
    assert isinstance(problem, NodeProblem)
    assert (
        problem.text
        == "producer heartbeat time 0x1017: 0x1017:0 reads back 0x32 after writing 0x64"
    )


def test_a_node_of_another_profile_is_refused() -> None:
    node = FakeNode()
    node.od[(0x1000, 0)] = (0x00000191).to_bytes(4, "little")
    line = Line(Master(config(), [node_config()]), node)
    line.run(0.3)
    problem = line.of(NodeProblem)[0]
    assert isinstance(problem, NodeProblem)
    assert "profile 401, not CiA 402" in problem.text


def test_an_operational_node_is_reset_when_the_config_says_so() -> None:
    node = FakeNode()
    node.nmt = f.NmtState.OPERATIONAL
    line = Line(Master(config(), [node_config(reset_if_operational=True)]), node)
    line.inject(node.heartbeat())
    line.run(0.5)
    assert node.nmt_seen[:3] == [
        f.NmtCommand.RESET_NODE,
        f.NmtCommand.ENTER_PRE_OPERATIONAL,
        f.NmtCommand.START,
    ]
    assert line.master.online(5)


# ---------------------------------------------------------------- losing a node


def test_a_missed_heartbeat_takes_the_node_offline_then_it_comes_back() -> None:
    line, _node = up()
    line.master.set_want(5, Want(run=True, target=100))
    line.run(0.2)
    line.run(HB_MS / 1000 * 3 + 0.05, heartbeats=False)  # its TPDO1 still comes
    down = line.of(NodeDown)
    assert len(down) == 1 and isinstance(down[0], NodeDown)
    assert down[0].reason.startswith("no heartbeat for ")
    assert not line.master.online(5)
    assert line.master.nodes[5].want == STOPPED  # nothing of the old wish survives
    line.run(1.0)
    assert line.master.online(5)
    assert line.master.nodes[5].want == STOPPED


def test_a_boot_up_while_online_is_a_lost_node_brought_up_at_once() -> None:
    line, node = up()
    node.nmt = f.NmtState.PRE_OPERATIONAL
    line.inject(f.encode_heartbeat(5, f.NmtState.BOOTUP))
    down = line.of(NodeDown)
    assert isinstance(down[0], NodeDown) and "boot-up" in down[0].reason
    line.run(0.3)
    assert line.master.online(5)


# ---------------------------------------------------------------- fault, EMCY, reset


def test_fault_reads_and_one_reset_pulse() -> None:
    line, node = up()
    node.state = State.FAULT
    node.od[(0x603F, 0)] = (0x2310).to_bytes(2, "little")
    node.od[(0x1001, 0)] = b"\x03"
    line.inject(f.encode_emcy(5, f.Emcy(0x2310, 0x03)))
    line.run(0.2)
    emcy = line.of(EmcyIn)[0]
    assert isinstance(emcy, EmcyIn) and emcy.emcy.error_code == 0x2310
    info = line.of(FaultInfo)[0]
    assert isinstance(info, FaultInfo)
    assert info.reads == {(0x1001, 0): b"\x03", (0x603F, 0): b"\x10\x23"}
    assert line.master.fault_reset(5, line.now)
    assert not line.master.fault_reset(5, line.now)  # one pulse at a time
    before = len(node.controlwords)
    line.run(1.0)
    words = node.controlwords[before:]
    with_bit = [w & 0x80 for w in words]
    # one run of set bits, then never again
    runs = [k for k, _ in itertools.groupby(with_bit)]
    assert runs == [0x80, 0]
    # the bit is in force across at least two SYNCs (a synchronous RPDO acts on the next)
    rpdo = [(i, fr) for i, fr in enumerate(line.sent) if fr.cob_id == 0x205]
    set_at = next(i for i, fr in rpdo if fr.data[0] & 0x80)
    clear_at = next(i for i, fr in rpdo if i > set_at and not fr.data[0] & 0x80)
    syncs = [fr for fr in line.sent[set_at:clear_at] if fr == f.encode_sync()]
    assert len(syncs) >= 2
    assert node.state is State.SWITCHED_ON  # reset, then stepped to switched on (no run)
    assert RESET_PULSE_CYCLES >= 2


def test_no_reset_for_a_node_not_online() -> None:
    node = FakeNode()
    line = Line(Master(config(), [node_config()]), node)
    assert not line.master.fault_reset(5, 0.0)


# ---------------------------------------------------------------- SDO jobs


def test_sdo_jobs_one_at_a_time_with_abort_texts() -> None:
    line, _node = up()
    first = line.master.submit(5, 0x605A, 0, None)
    second = line.master.submit(5, 0x6099, 0, None)
    assert line.master.nodes[5].jobs and line.master.nodes[5].current is None
    line.run(0.05)
    done = {a.token: a for a in line.of(SdoDone) if isinstance(a, SdoDone)}
    assert done[first].result == f.SdoResult((2).to_bytes(2, "little"))
    result = done[second].result
    assert result is not None and result.message == (
        "0x06020000 object does not exist in the object dictionary"
    )


def test_sdo_timeout_aborts_and_reports() -> None:
    line, node = up()
    node.sdo_silent = True
    token = line.master.submit(5, 0x605A, 0, None)
    line.run(0.15)
    done = next(a for a in line.of(SdoDone) if isinstance(a, SdoDone) and a.token == token)
    assert done.result == f.SdoResult(abort_code=codes.ABORT_TIMEOUT)
    abort = f.CanFrame(0x605, f.encode_sdo_request(f.Abort(0x605A, 0, codes.ABORT_TIMEOUT)))
    assert abort in line.sent


def test_jobs_only_for_online_nodes() -> None:
    master = Master(config(), [node_config()])
    with pytest.raises(NodeUnavailable):
        master.submit(5, 0x6041, 0, None)
    with pytest.raises(NodeUnavailable):
        master.submit(9, 0x6041, 0, None)


def test_a_lost_node_ends_its_jobs() -> None:
    line, node = up()
    node.silent = True
    token = line.master.submit(5, 0x605A, 0, None)
    line.run(0.5, heartbeats=False, tpdo=False)
    done = [a for a in line.of(SdoDone) if isinstance(a, SdoDone) and a.token == token]
    assert len(done) == 1


def test_inputs_and_the_state_behind_them() -> None:
    line, node = up()
    node.state = State.OPERATION_ENABLED
    line.inject(node.tpdo(-1200))
    inputs = [a for a in line.of(Inputs) if isinstance(a, Inputs)][-1]
    assert inputs.values == (-1200,)
    assert inputs.statusword == node.statusword()
    assert line.master.node_diagnostics(5)["cia402_state"] == "operation_enabled"
    line.inject(f.CanFrame(0x185, b"\x01"))  # short: counted, not taken
    assert line.master.nodes[5].figures["bad_pdos"] == 1


def test_leave_sends_the_last_rpdo_and_pre_operational() -> None:
    line, _node = up()
    actions = line.master.leave(line.now)
    frames_ = [a.frame for a in actions if isinstance(a, Send)]
    assert [fr.cob_id for fr in frames_] == [0x205, 0x080, 0x000]
    assert frames_[2].data == bytes((f.NmtCommand.ENTER_PRE_OPERATIONAL, 5))
    assert line.master.step(line.now + 1) == []
    assert Phase.ONLINE is line.master.nodes[5].phase


RELEASE = (SdoStep(0x1016, 1, bytes(4), "consumer heartbeat time 0x1016:1 off (leaving)"),)


def test_release_switches_the_consumer_off_by_sdo_while_the_cycle_goes_on() -> None:
    node = FakeNode()
    line = Line(Master(config(), [node_config(release=RELEASE)]), node)
    line.run(0.5)
    line.master.set_want(5, Want(run=True, target=10))
    line.run(0.05)
    token = line.master.submit(5, 0x605A, 0, None)  # a job queued: it ends, not the release
    node.silent = True  # the job's request goes unanswered...
    line._deliver(list(line.master.step(line.now)))
    node.silent = False
    sent = len(line.sent)
    line._deliver(list(line.master.release(line.now)))
    # ...and is aborted on the line, then the release: SDO download 0x1016:1 = 0 (golden)
    assert line.sent[sent] == f.CanFrame(0x605, bytes.fromhex("80 5A 60 00 00 00 00 08"))
    assert line.sent[sent + 1] == f.CanFrame(0x605, bytes.fromhex("23 16 10 01 00 00 00 00"))
    assert node.od[(0x1016, 1)] == bytes(4)
    assert line.master.released
    done = [a for a in line.of(SdoDone) if isinstance(a, SdoDone) and a.token == token]
    assert len(done) == 1 and done[0].error == "the gateway is leaving the line"
    with pytest.raises(NodeUnavailable, match="leaving the line"):
        line.master.submit(5, 0x605A, 0, None)
    assert line.master.nodes[5].figures["released"] == 1
    before = len([fr for fr in line.sent if fr.cob_id == 0x080])
    line.run(0.05)
    assert len([fr for fr in line.sent if fr.cob_id == 0x080]) > before  # SYNC goes on
    assert line.master.nodes[5].phase is Phase.ONLINE


def test_a_release_unanswered_ends_at_the_sdo_timeout_and_is_reported() -> None:
    node = FakeNode()
    line = Line(Master(config(), [node_config(release=RELEASE)]), node)
    line.run(0.5)
    node.sdo_silent = True
    line._deliver(list(line.master.release(line.now)))
    assert not line.master.released
    line.run(0.15)
    assert line.master.released
    reports = [a.text for a in line.of(Report) if isinstance(a, Report)]
    assert any(t.startswith("leaving: write of 0x1016:1 failed: 0x05040000") for t in reports)


def test_nothing_to_release_without_a_consumer_or_a_node_up() -> None:
    line, _node = up()
    assert [a for a in line.master.release(line.now) if isinstance(a, Send)] == []
    assert line.master.released
    quiet = Master(config(), [node_config(release=RELEASE)])  # never heard: nothing sent
    assert quiet.release(0.0) == [] and quiet.released
    probes = [
        a
        for t in (5.0, 6.0)
        for a in quiet.step(t)
        if isinstance(a, Send) and a.frame.cob_id == 0x605
    ]
    assert probes == []  # no node is probed once the gateway leaves


def test_an_unchanged_rpdo_is_sent_on_change_and_refreshed() -> None:
    line, node = up()
    start = len([fr for fr in line.sent if fr.cob_id == 0x205])
    line.run(0.5)  # 50 cycles, nothing changes
    steady = len([fr for fr in line.sent if fr.cob_id == 0x205]) - start
    assert 4 <= steady <= 6  # refreshed every RPDO_REFRESH (0.1 s), not every cycle
    line.master.set_want(5, Want(run=True, target=10))
    line.run(0.05)
    assert node.state is State.OPERATION_ENABLED  # changes go out at the next cycle


def test_a_stopped_node_is_put_in_pre_operational_to_answer() -> None:
    class Stopped(FakeNode):
        def _sdo(self, data: bytes) -> bytes:
            if self.nmt is f.NmtState.STOPPED:
                raise _NoAnswer
            return super()._sdo(data)

        def receive(self, frame: f.CanFrame) -> list[f.CanFrame]:
            try:
                return super().receive(frame)
            except _NoAnswer:
                return []

    node = Stopped()
    node.nmt = f.NmtState.STOPPED
    line = Line(Master(config(), [node_config()]), node)
    line.run(2.0)
    assert node.nmt_seen[0] is f.NmtCommand.ENTER_PRE_OPERATIONAL
    assert line.master.online(5)


def test_a_failed_node_is_not_watched_until_it_is_tried_again() -> None:
    node = FakeNode()
    node.refuse[(0x6060, 0)] = 0x06090030
    line = Line(Master(config(), [node_config()]), node)
    line.run(0.5)
    node.silent = True
    line.run(2.0)
    assert not line.of(NodeDown)  # its silence is no news: it was never started
    assert line.master.nodes[5].phase is Phase.FAILED


class _NoAnswer(Exception):
    pass


def test_no_reset_pulse_for_a_drive_that_is_not_faulted() -> None:
    """Transition 15 leaves FAULT only (CiA 402-2 §6.2): a reset asked of a running drive
    sends nothing (bit 7 never rides on Enable operation)."""
    line, node = up()
    line.master.set_want(5, Want(run=True, target=100))
    line.run(0.3)
    assert node.state is State.OPERATION_ENABLED
    assert not line.master.fault_reset(5, line.now)
    line.run(0.1)
    assert not [w for w in node.controlwords if w & 0x80]
    assert node_state(node) is State.OPERATION_ENABLED


@given(
    st.lists(
        st.tuples(st.sampled_from(["submit", "run", "silence", "talk"]), st.integers(1, 30)),
        max_size=25,
    )
)
def test_one_sdo_transfer_in_flight_and_every_job_ends(script: list[tuple[str, int]]) -> None:
    """Whatever the order of jobs, silences and time: at most one SDO request is waiting
    for its answer per node, and every job of the adapter ends exactly once."""
    line, node = up()
    tokens: list[int] = []
    for op, n in script:
        if op == "submit" and line.master.online(5):
            tokens += [line.master.submit(5, 0x605A, 0, None) for _ in range(n % 4 + 1)]
        elif op == "run":
            line.run(n / 100, heartbeats=not node.silent, tpdo=not node.silent)
        elif op == "silence":
            node.silent = True
        else:
            node.silent = False
    node.silent = False
    line.run(3.0)
    outstanding = 0
    for entry in node.sdo_log:
        if entry == "request":
            assert outstanding == 0, node.sdo_log  # one transfer in flight
            outstanding = 1
        else:
            outstanding = 0
    done = [a.token for a in line.of(SdoDone) if isinstance(a, SdoDone)]
    assert sorted(done) == sorted(tokens)  # each ended once (answered, aborted or dropped)
    assert node.sdo_requests  # it was asked


def test_a_transfer_under_way_when_the_node_is_lost_is_aborted() -> None:
    line, node = up(sdo_timeout=5.0)  # longer than the heartbeat watch
    node.silent = True
    token = line.master.submit(5, 0x605A, 0, None)
    line.run(0.5, heartbeats=False, tpdo=False)
    done = next(a for a in line.of(SdoDone) if isinstance(a, SdoDone) and a.token == token)
    assert done.error is not None and done.error.startswith("node lost: no TPDO1")
    abort = f.encode_sdo_request(f.Abort(0x605A, 0, codes.ABORT_GENERAL))
    assert f.CanFrame(0x605, abort) in line.sent


# ---------------------------------------------------------------- unused PDOs switched off

TPDO2_OFF = SdoStep(
    0x1801,
    1,
    (0x80000285).to_bytes(4, "little"),
    "TPDO2 switched off (not used): 0x1801:1 bit 31",
    0x80000000,
    optional=True,
)


def pdo_node() -> FakeNode:
    node = FakeNode()
    node.od[(0x1801, 1)] = (0x285).to_bytes(4, "little")  # TPDO2 valid, as the EDS has it
    return node


def pdo_config() -> NodeConfig:
    base = node_config()
    return node_config(steps=(base.steps[0], TPDO2_OFF, *base.steps[1:]))


def test_an_unused_pdo_is_switched_off_and_read_back_before_start() -> None:
    node = pdo_node()
    line = Line(Master(config(), [pdo_config()]), node)
    line.run(0.5)
    assert line.master.online(5) and not line.of(Report)
    # CiA 301 §7.5.2.36: 0x1801:1 with bit 31 set (PDO not valid), the id kept
    write = f.CanFrame(0x605, bytes.fromhex("23 01 18 01 85 02 00 80"))
    read = f.CanFrame(0x605, bytes.fromhex("40 01 18 01 00 00 00 00"))
    start = f.encode_nmt(f.NmtCommand.START, 5)
    assert line.sent.index(write) < line.sent.index(read) < line.sent.index(start)
    assert node.od[(0x1801, 1)] == (0x80000285).to_bytes(4, "little")


def test_an_unused_pdo_the_node_will_not_switch_off_is_reported_and_the_node_goes_on() -> None:
    node = pdo_node()
    node.refuse[(0x1801, 1)] = 0x06010002  # attempt to write a read only object
    line = Line(Master(config(), [pdo_config()]), node)
    line.run(0.5)
    (report,) = line.of(Report)
    assert isinstance(report, Report) and report.text == (
        "TPDO2 switched off (not used): 0x1801:1 bit 31: write of 0x1801:1 = 0x80000285 "
        "refused: 0x06010002 attempt to write a read only object (the bring-up goes on)"
    )
    assert not line.of(NodeProblem)
    assert line.master.online(5) and f.NmtCommand.START in node.nmt_seen
    asked = {
        (r.index, r.subindex)
        for r in node.sdo_requests
        if isinstance(r, f.InitiateUpload | f.InitiateDownload)
    }
    assert (0x6060, 0) in asked  # the next step


def test_an_unused_pdo_that_stays_valid_is_reported_and_the_node_goes_on() -> None:
    class Fixed(FakeNode):  # takes the write, keeps its COB-ID as it was
        def _sdo(self, data: bytes) -> bytes:
            reply = super()._sdo(data)
            self.od[(0x1801, 1)] = (0x285).to_bytes(4, "little")
            return reply

    node = Fixed()
    line = Line(Master(config(), [pdo_config()]), node)
    line.run(0.5)
    (report,) = line.of(Report)
    assert isinstance(report, Report) and report.text == (
        "TPDO2 switched off (not used): 0x1801:1 bit 31: 0x1801:1 reads back 0x0 after "
        "writing 0x80000000 (the bring-up goes on)"
    )
    assert line.master.online(5)


def test_an_unused_pdo_write_unanswered_stops_the_bring_up() -> None:
    class Deaf(FakeNode):  # no answer to 0x1801 (a timeout is no refusal)
        def receive(self, frame: f.CanFrame) -> list[f.CanFrame]:
            if frame.cob_id == 0x605 and frame.data[1:4] == bytes.fromhex("01 18 01"):
                return []
            return super().receive(frame)

    node = Deaf()
    line = Line(Master(config(), [pdo_config()]), node)
    line.run(0.5)
    problem = line.of(NodeProblem)[0]
    assert isinstance(problem, NodeProblem) and problem.abort_code == codes.ABORT_TIMEOUT
    assert not line.master.online(5) and f.NmtCommand.START not in node.nmt_seen


# ---------------------------------------------------------------- late SDO answers


def test_a_late_answer_of_a_timed_out_transfer_is_not_the_next_ones() -> None:
    """Under overload: the probe 0x1000 times out (the client aborts it, CiA 301
    §7.2.4.3.17, 0x05040000), the retry is answered, the bring-up's first write goes out,
    and then the first probe's late answer arrives. It names 0x1000 and is an upload
    response: not the write's answer. It is ignored; taken as the write's it ended the
    write with 0x05040001 (command specifier not valid) and failed the bring-up."""
    master = Master(config(), [node_config()])
    probe = f.CanFrame(0x605, bytes.fromhex("40 00 10 00 00 00 00 00"))
    answer = f.CanFrame(0x585, bytes.fromhex("43 00 10 00 92 01 02 00"))
    assert Send(probe) in master.step(0.0)
    abort = f.CanFrame(0x605, bytes.fromhex("80 00 10 00 00 00 04 05"))
    assert Send(abort) in master.step(0.1)  # sdo_timeout: the client aborts
    assert Send(probe) in master.step(0.6)  # retry
    out = master.step(0.61, FrameIn(answer))
    write = f.CanFrame(0x605, bytes.fromhex("2B 17 10 00 64 00 00 00"))
    assert out[-1] == Send(write)

    def sdo(actions: Sequence[object]) -> list[object]:
        return [a for a in actions if isinstance(a, Send) and a.frame.cob_id == 0x605]

    assert sdo(master.step(0.62, FrameIn(answer))) == []  # the late answer: no abort
    node = master.nodes[5]
    assert node.current is not None and node.current.index == 0x1017
    assert node.figures["sdo_stale"] == 1
    assert node.sdo_deadline == pytest.approx(0.71)  # the write's own, not moved
    done = f.CanFrame(0x585, bytes.fromhex("60 17 10 00 00 00 00 00"))
    read_back = f.CanFrame(0x605, bytes.fromhex("40 17 10 00 00 00 00 00"))
    assert sdo(master.step(0.63, FrameIn(done))) == [Send(read_back)]
    assert node.phase is Phase.CONFIGURE and node.last_problem is None
