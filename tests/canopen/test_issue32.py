"""Issue 32 items 11 and 12 on the CANopen master engine, stepped with an injected clock
against the scripted node of :mod:`tests.canopen.test_master`: a drive is online only
while its TPDO1 comes each SYNC; a drive whose bring-up failed does not watch the
gateway's heartbeat; the fault reset is an edge 0 -> 1 -> 0 before the next command; no
burst of SYNCs or heartbeats after a late one; one master per line; frames that
contradict each other are conflicts."""

from __future__ import annotations

from collections.abc import Sequence

from adapters.canopen.codec import codes
from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import State
from adapters.canopen.master import (
    Conflict,
    FrameIn,
    LineClaimed,
    Master,
    MasterHeard,
    NodeDown,
    NodeProblem,
    SdoStep,
    Send,
    Want,
)
from adapters.canopen.master.engine import TPDO_STEADY_CYCLES, tpdo_loss_cycles
from tests.canopen.test_master import CYCLE, HB_MS, FakeNode, Line, config, node_config, up

CONSUMER = SdoStep(0x1016, 1, ((127 << 16) | 300).to_bytes(4, "little"), "consumer 0x1016:1")
RELEASE = (SdoStep(0x1016, 1, bytes(4), "consumer heartbeat time 0x1016:1 off (leaving)"),)
MODE = SdoStep(0x6060, 0, b"\x02", "modes of operation 0x6060")


def sends(actions: Sequence[object], cob_id: int) -> list[f.CanFrame]:
    return [a.frame for a in actions if isinstance(a, Send) and a.frame.cob_id == cob_id]


# ---------------------------------------------------------------- item 11


def test_a_drive_whose_tpdo1_stops_is_offline_though_heartbeats_go_on() -> None:
    """A powered-off drive stayed online while another node sent heartbeats with its id."""
    line, _node = up()
    assert line.master.online(5)
    cycles = tpdo_loss_cycles(CYCLE)
    line.run(CYCLE * (cycles - 0.5), tpdo=False)
    assert line.master.online(5)  # a late TPDO1 is not a loss
    line.run(CYCLE * 2, tpdo=False)  # heartbeats go on
    down = [a for a in line.of(NodeDown) if isinstance(a, NodeDown)]
    assert [d.reason for d in down] == [f"no TPDO1 for {cycles} cycles"]
    assert not line.master.online(5)


def test_a_drive_whose_bring_up_failed_stops_watching_the_gateways_heartbeat() -> None:
    """EMCY 0x8130 on a clean stop: 0x1016:1 stayed set on a drive the gateway never
    started."""
    node = FakeNode()
    node.od[(0x1016, 1)] = bytes(4)
    node.refuse[(0x6060, 0)] = codes.ABORT_RANGE
    steps = (
        SdoStep(0x1017, 0, HB_MS.to_bytes(2, "little"), "producer heartbeat time 0x1017"),
        CONSUMER,
        MODE,
    )
    line = Line(Master(config(), [node_config(steps=steps, release=RELEASE)]), node)
    line.run(0.5)
    assert line.of(NodeProblem)
    assert node.od[(0x1016, 1)] == bytes(4)  # switched off again by SDO
    assert line.master.released


def test_leaving_releases_a_failed_drive_that_still_watches() -> None:
    node = FakeNode()
    node.od[(0x1016, 1)] = bytes(4)
    node.refuse[(0x6060, 0)] = codes.ABORT_RANGE
    steps = (CONSUMER, MODE)
    master = Master(config(), [node_config(steps=steps, release=RELEASE)])
    line = Line(master, node)
    node.sdo_silent = True
    line.run(0.05)
    node.sdo_silent = False
    line.run(0.5)  # the consumer written, the mode refused
    node.od[(0x1016, 1)] = CONSUMER.data  # the release write was lost: it still watches
    master.nodes[5].consumer_set = True
    line._deliver(list(master.release(line.now)))
    line.run(0.1)
    assert node.od[(0x1016, 1)] == bytes(4)


def test_the_fault_reset_bit_is_clear_before_the_next_command() -> None:
    """0x0086 (bit 7 with Shutdown) was sent: the reset is 0 -> 1 -> 0, then Shutdown."""
    line, node = up()
    node.state = State.FAULT
    line.run(0.1)
    assert line.master.fault_reset(5, line.now)
    before = len(node.controlwords)
    line.run(0.3)
    words = node.controlwords[before:]
    assert not [w for w in words if w & 0x80 and w & 0x7F]  # bit 7 alone, never 0x86
    first_set = words.index(0x80)
    first_shutdown = words.index(0x06)
    assert 0x00 in words[first_set:first_shutdown]  # bit 7 back at 0 before Shutdown
    assert node.state is State.SWITCHED_ON


def test_a_late_sync_is_not_followed_by_a_burst() -> None:
    """Gaps of 0.60 ms were seen against a 50 ms period."""
    master = Master(config(sync_period=0.05), [node_config()])
    assert sends(master.step(0.0), f.COB_SYNC)
    late = 0.05 + 0.0494  # the loop was late by almost a period
    assert sends(master.step(late), f.COB_SYNC)
    nxt = master.next_cycle
    assert nxt is not None and nxt - late >= 0.9 * 0.05


def test_a_late_heartbeat_is_not_followed_by_a_burst() -> None:
    master = Master(config(own_node_id=127, own_heartbeat=0.1), [node_config()])
    hb = 0x700 + 127
    assert sends(master.step(0.0), hb)
    assert sends(master.step(0.25), hb)  # late by one and a half periods
    assert not sends(master.step(0.2501), hb)
    assert not sends(master.step(0.33), hb)
    assert sends(master.step(0.35), hb)


# ---------------------------------------------------------------- item 12: one master


def test_another_master_heard_while_listening_refuses_the_line() -> None:
    master = Master(config(listen=0.3, own_node_id=127, own_heartbeat=0.1), [node_config()])
    assert master.step(0.0) == []  # listening: nothing sent
    out = master.step(0.1, FrameIn(f.encode_sync()))
    assert out == [MasterHeard("a SYNC from another producer", claimed=False)]
    for t in (0.3, 0.5, 1.0):
        assert master.step(t) == []  # never a frame
    assert master.release(1.0) == [] and master.released
    assert master.leave(1.0) == []


def test_a_heartbeat_with_the_gateways_node_id_while_listening_refuses_the_line() -> None:
    master = Master(config(listen=0.3, own_node_id=127, own_heartbeat=0.1), [node_config()])
    master.step(0.0)
    out = master.step(0.2, FrameIn(f.encode_heartbeat(127, f.NmtState.OPERATIONAL)))
    assert [a for a in out if isinstance(a, MasterHeard)] == [
        MasterHeard("a heartbeat with the gateway's own node id 127", claimed=False)
    ]


def test_a_quiet_line_is_claimed_after_listening() -> None:
    master = Master(config(listen=0.3, own_node_id=127, own_heartbeat=0.1), [node_config()])
    assert master.step(0.0) == []
    assert master.next_deadline() == 0.3
    assert master.step(0.2, FrameIn(f.encode_heartbeat(9, f.NmtState.OPERATIONAL))) == []
    out = master.step(0.3)
    assert LineClaimed() in out
    assert sends(out, f.COB_SYNC) and sends(out, 0x700 + 127)


def test_another_master_joining_later_is_heard() -> None:
    line, _node = up(own_node_id=127, own_heartbeat=0.1)
    for frame, text in (
        (f.encode_sync(), "a SYNC from another producer"),
        (f.encode_nmt(f.NmtCommand.RESET_NODE, 0), "an NMT command (8100) from another master"),
        (
            f.encode_heartbeat(127, f.NmtState.OPERATIONAL),
            "a heartbeat with the gateway's own node id 127",
        ),
        (f.CanFrame(f.rpdo_id(1, 5), bytes(4)), "RPDO1 to node 5 from another producer"),
    ):
        before = len(line.actions)
        line.inject(frame)
        assert MasterHeard(text, claimed=True) in line.actions[before:]
    assert line.master.figures["foreign_master_frames"] == 4


# ---------------------------------------------------------------- item 12: forged frames


def test_a_second_tpdo1_in_one_sync_cycle_is_a_conflict() -> None:
    """A second node sending TPDO1 with a drive's id showed a stopped drive running."""
    line, node = up()
    line.run(0.05)
    assert not line.of(Conflict)
    node.state = State.OPERATION_ENABLED  # what the forger says
    line.inject(node.tpdo(1500))
    node.state = State.SWITCHED_ON
    line.run(0.05)
    conflicts = [a for a in line.of(Conflict) if isinstance(a, Conflict)]
    assert conflicts and conflicts[0] == Conflict(5, "a second TPDO1 in one SYNC cycle")
    assert line.master.nodes[5].figures["conflicts"] >= 1


def test_one_late_tpdo1_carried_into_the_next_cycle_is_no_conflict() -> None:
    line, node = up()
    node.tpdo_on_sync = False
    master = line.master

    def next_sync() -> None:
        line.now = master.next_cycle or line.now
        line._deliver(list(master.step(line.now)))

    for _ in range(3):
        next_sync()  # its TPDO1 is late
        next_sync()
        line.inject(node.tpdo())  # the late one
        line.inject(node.tpdo())  # this cycle's
        next_sync()
        line.inject(node.tpdo())
    assert not line.of(Conflict)
    assert master.online(5)


def test_a_drive_two_cycles_late_catching_up_one_at_a_time_is_no_conflict() -> None:
    """A loaded line: the TPDO1s of two SYNCs come late, then catch up over two cycles."""
    line, node = up()
    node.tpdo_on_sync = False
    master = line.master

    def next_sync() -> None:
        line.now = master.next_cycle or line.now
        line._deliver(list(master.step(line.now)))

    for _ in range(2):  # one TPDO1 each cycle
        next_sync()
        line.inject(node.tpdo())
    next_sync()  # n: late
    next_sync()  # n + 1: late too
    line.inject(node.tpdo())  # n
    next_sync()  # n + 2
    line.inject(node.tpdo())  # n + 1
    line.inject(node.tpdo())  # n + 2: caught up
    for _ in range(TPDO_STEADY_CYCLES + 1):
        next_sync()
        line.inject(node.tpdo())
    assert not line.of(Conflict)
    assert master.online(5)
    line.inject(node.tpdo())  # steady again: a second producer is heard at once
    assert line.of(Conflict) == [Conflict(5, "a second TPDO1 in one SYNC cycle")]


def test_a_forged_sdo_answer_then_the_real_one_is_a_conflict() -> None:
    """Forged SDO answers replaced a real 0x2310 fault code by 0x1234."""
    line, node = up()
    node.sdo_silent = True
    line.master.submit(5, 0x603F, 0, None)
    line.run(0.001)
    forged = f.encode_sdo_response(f.InitiateUploadResponse(0x603F, 0, b"\x34\x12"))
    real = f.encode_sdo_response(f.InitiateUploadResponse(0x603F, 0, b"\x10\x23"))
    line.inject(f.CanFrame(f.sdo_tx_id(5), forged))
    assert not line.of(Conflict)
    line.inject(f.CanFrame(f.sdo_tx_id(5), real))  # two answers to one request
    assert line.of(Conflict) == [
        Conflict(
            5,
            "an SDO answer with no request under way (unsolicited, or a second answer to "
            "one request)",
        )
    ]


def test_an_unsolicited_sdo_answer_is_a_conflict_a_late_one_is_not() -> None:
    line, node = up()
    answer = f.CanFrame(
        f.sdo_tx_id(5), f.encode_sdo_response(f.InitiateUploadResponse(0x605A, 0, b"\x02\x00"))
    )
    node.sdo_silent = True
    line.master.submit(5, 0x605A, 0, None)
    line.run(0.15)  # timed out
    line.inject(answer)  # its late answer
    assert not line.of(Conflict)
    line.inject(answer)  # nobody asked
    assert len(line.of(Conflict)) == 1


def test_a_steady_line_has_no_conflict_and_stays_online() -> None:
    line, _node = up()
    line.master.set_want(5, Want(run=True, target=100))
    line.run(2.0)
    assert not line.of(Conflict) and not line.of(NodeDown)
    assert line.master.online(5)
