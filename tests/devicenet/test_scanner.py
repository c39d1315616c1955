"""The scanner engine against simulated CFW-08s on an ideal bus, with a fake clock.

Golden identifiers from fact sheet 2.2 (master MAC 0, slave MAC 10): Allocate 0x456,
slave response 0x453, explicit request 0x454, poll 0x455, poll response 0x3CA, master
DupMAC 0x407.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import pytest

from adapters.devicenet.cfw08 import Out21
from adapters.devicenet.codec.cip import GeneralStatus
from adapters.devicenet.codec.datatypes import CipType, encode_value
from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    ErrorResponse,
    ExplicitMessage,
    GetAttributeSingle,
    Response,
    SetAttributeSingle,
    SuccessResponse,
)
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    FragmentType,
    IoReassembler,
    fragment_io,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.objects import AllocationChoice, ConnectionInstance
from adapters.devicenet.scanner import (
    BusErrorIn,
    ExplicitResult,
    FrameIn,
    IdentityCheck,
    InputData,
    IoKind,
    LineFault,
    LineOnline,
    LinePhase,
    LinkDown,
    NodeConfig,
    NodeDown,
    NodeUnavailable,
    NodeUp,
    Phase,
    Report,
    ReportKind,
    Scanner,
    ScannerConfig,
    Send,
    TxFailed,
)
from adapters.devicenet.sim.node import SimNodeConfig, SimPhase
from adapters.link.canerror import LineCondition
from gateway.errors import FrameEncodeError
from tests.devicenet.harness import Line

FAST = ScannerConfig(
    dupmac_timeout=0.05,
    poll_interval=0.02,
    response_timeout=0.01,
    explicit_timeout=0.05,
    allocate_timeout=0.05,
    retry_min=0.05,
    retry_max=0.4,
)
CFW08 = IdentityCheck(0x355, None, "CFW-08")


def node(mac: int, **kw: object) -> NodeConfig:
    return NodeConfig(mac, epr=0.05, identity=CFW08, **kw)  # type: ignore[arg-type]


def sim(mac: int, **kw: object) -> SimNodeConfig:
    return SimNodeConfig(mac, dupmac_timeout=0.05, **kw)  # type: ignore[arg-type]


def line(*macs: int, config: ScannerConfig = FAST, **kw: object) -> Line:
    lin = Line(config, [node(m, **kw) for m in macs], [sim(m) for m in macs])
    lin.power_on()
    return lin


def ups(lin: Line) -> list[int]:
    return [a.mac for a in lin.take(NodeUp)]


def test_bring_up_on_the_wire() -> None:
    lin = line(10)
    lin.run(0.3)
    scanner = [(f.arbitration_id, f.data.hex(" ")) for _, who, f in lin.frames if who == "scanner"]
    # 2.3: two Duplicate MAC ID requests for MAC 0 (vendor 0, serial 0x44470000), 1 s apart.
    assert scanner[0] == (0x407, "00 00 00 00 00 47 44")
    assert scanner[1] == scanner[0]
    # 2.5: Allocate explicit + poll on G2 msg 6 of MAC 10 (XID toggled for the first request).
    assert scanner[2] == (0x456, "40 4b 03 01 03 00")
    # 2.9: the explicit connection's EPR first, 2500 ms, on G2 msg 4 (class 5, instance 1,
    # attribute 9), so that a bring-up waiting its turns keeps its connection.
    assert scanner[3] == (0x454, "00 10 05 01 09 c4 09")
    # 2.12: Identity vendor ID read on G2 msg 4 (XID toggled again).
    assert scanner[4] == (0x454, "40 0e 01 01 01")
    ids = [i for i, _ in scanner]
    assert 0x455 in ids  # polls
    # 2.10 step 5: the poll EPR, 50 ms, set with [hdr, 10, 05, 02, 09, lo, hi].
    assert any(d.endswith("10 05 02 09 32 00") for i, d in scanner if i == 0x454)
    replies = [(f.arbitration_id, f.data.hex(" ")) for _, who, f in lin.frames if who == "node"]
    assert (0x453, "40 cb 00") in replies  # Allocate success, 8/8 body format
    assert any(i == 0x3CA and len(d.split()) == 4 for i, d in replies)  # poll responses
    assert [a for a in lin.actions if isinstance(a, LineOnline)]
    assert ups(lin) == [10]
    assert len(lin.inputs(10)) > 5


def test_63_nodes_come_online_and_are_polled() -> None:
    macs = list(range(1, 64))
    lin = line(*macs)
    lin.run(1.0)
    assert sorted(ups(lin)) == macs
    assert all(len(lin.inputs(m)) > 3 for m in macs)
    diag = lin.scanner.line_diagnostics()
    assert diag["online"] == 63 and diag["poll_cycles"] > 3
    assert lin.scanner.node_diagnostics(63)["poll_timeouts"] == 0


def test_unanswered_polls_time_out_and_the_cycle_goes_on() -> None:
    """Two of five nodes fall silent: each of their polls times out after
    ``response_timeout`` (counted for them alone), and the poll cycles go on, the
    others' polls answered, until inactivity (4 x EPR) takes the two offline."""
    lin = line(2, 3, 4, 5, 6)
    lin.run(0.3)
    assert sorted(ups(lin)) == [2, 3, 4, 5, 6]
    cycles = lin.scanner.line.cycles
    answered = {m: len(lin.inputs(m)) for m in (2, 4, 6)}
    for mac in (3, 5):
        lin.sims[mac].power_off()
    lin.run(0.15)  # under 4 x EPR (0.2 s): still online, polled, unanswered
    timeouts = {m: lin.scanner.node_diagnostics(m)["poll_timeouts"] for m in (2, 3, 4, 5, 6)}
    assert timeouts[2] == timeouts[4] == timeouts[6] == 0
    # a cycle lasts one response_timeout (0.01 s) when a poll goes unanswered
    assert timeouts[3] == timeouts[5] >= 5
    assert lin.scanner.line.cycles - cycles >= 5
    assert all(len(lin.inputs(m)) > answered[m] + 5 for m in (2, 4, 6))
    lin.run(0.1)
    assert sorted(d.mac for d in lin.take(NodeDown)) == [3, 5]


def test_outputs_reach_the_drive() -> None:
    lin = line(3)
    lin.outputs[3] = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=600).encode()
    lin.run(2.5)
    drive = lin.sims[3].drive
    assert drive.motor.speed == 600.0 and drive.net_ctrl
    last = lin.inputs(3)[-1]
    assert last == bytes.fromhex("F4 04 58 02")  # 71: running fwd, ready, net, at ref, 600


def test_scanner_mac_taken_stays_off_the_line() -> None:
    lin = Line(FAST, [node(5)], [sim(0), sim(5)])
    lin.power_on()
    lin.run(0.5)
    faults = lin.take(LineFault)
    assert len(faults) == 1 and "scanner MAC ID 0 is taken" in faults[0].text
    assert lin.scanner.phase is LinePhase.MAC_TAKEN
    assert not ups(lin)
    assert not [f for _, who, f in lin.frames if who == "scanner" and f.arbitration_id == 0x42E]


def test_own_mac_claim_is_answered_when_online() -> None:
    lin = line(5)
    lin.run(0.3)
    claim = CanFrame(0x407, bytes.fromhex("00 55 03 01 00 00 00"))
    actions = lin.scanner.step(lin.now, FrameIn(claim))
    sends = [a.frame for a in actions if isinstance(a, Send)]
    assert sends == [CanFrame(0x407, bytes.fromhex("80 00 00 00 00 47 44"))]
    assert any(isinstance(a, Report) and "tried to claim" in a.text for a in actions)


def test_duplicate_mac_between_nodes_is_reported() -> None:
    lin = Line(FAST, [node(5)], [sim(5), sim(5, serial_number=99)])
    lin.power_on(lin.sims[5])
    lin.run(0.3)
    late = lin.extra[0]
    lin.power_on(late)
    lin.run(0.3)
    assert late.phase is SimPhase.MAC_FAULT
    assert lin.sims[5].phase is SimPhase.ONLINE
    dups = [a for a in lin.take(Report) if a.kind is ReportKind.DUPLICATE_MAC]
    assert dups and "duplicate MAC ID 5" in dups[0].text and "serial 99" in dups[0].text
    assert lin.scanner.line_diagnostics()["duplicate_macs"]["5"] == dups[0].text


def test_identity_mismatch_refuses_io() -> None:
    lin = Line(
        FAST,
        [NodeConfig(4, epr=0.05, identity=IdentityCheck(product_name="CFW-09"))],
        [sim(4)],
    )
    lin.power_on()
    lin.run(0.5)
    reports = [a for a in lin.take(Report) if a.kind is ReportKind.IDENTITY]
    assert len(reports) == 1
    assert reports[0].text == (
        "node 4: identity mismatch: product name 'CFW-08', expected 'CFW-09': I/O refused"
    )
    assert lin.scanner.nodes[4].phase is Phase.REFUSED
    assert not ups(lin) and not lin.inputs(4)
    assert lin.sims[4].allocation == 0  # released


def test_vendor_mismatch() -> None:
    lin = Line(FAST, [NodeConfig(4, epr=0.05, identity=IdentityCheck(vendor_id=1))], [sim(4)])
    lin.power_on()
    lin.run(0.5)
    texts = [a.text for a in lin.take(Report)]
    assert "node 4: identity mismatch: vendor ID 0x0355, expected 0x0001: I/O refused" in texts


def test_size_mismatch_refuses_io() -> None:
    lin = Line(FAST, [NodeConfig(4, epr=0.05, produced_size=8)], [sim(4)])
    lin.power_on()
    lin.run(0.5)
    reports = [a for a in lin.take(Report) if a.kind is ReportKind.SIZE]
    assert reports[0].text == (
        "node 4: I/O size mismatch: the node produces 4 bytes, the assembly has 8: I/O refused"
    )
    assert not ups(lin)


def test_owned_by_another_master_is_reported_and_retried_with_backoff() -> None:
    lin = line(6)
    lin.sims[6].force_owner(9, 0.0)
    lin.run(1.5)
    reports = [a for a in lin.take(Report) if a.kind is ReportKind.ALLOCATION]
    assert len(reports) == 1  # reported once, not at every retry
    assert "owned by another master [0x0C Object state conflict (additional 0x01)]" in (
        reports[0].text
    )
    allocates = [t for t, who, f in lin.frames if who == "scanner" and f.arbitration_id == 0x436]
    gaps = [b - a for a, b in itertools.pairwise(allocates)]
    assert len(allocates) >= 4 and gaps[-1] > gaps[0]  # back-off grows
    assert lin.scanner.node_diagnostics(6)["retries"] >= 3
    assert not ups(lin)


def test_already_allocated_to_us_is_released_then_allocated() -> None:
    lin = line(6)
    lin.sims[6].force_owner(0, 0.0)  # a scanner restart without Release
    lin.run(0.5)
    assert ups(lin) == [6]
    releases = [f for _, who, f in lin.frames if who == "scanner" and f.data[1:2] == b"\x4c"]
    assert len(releases) == 1


def test_invalid_choice_rejection_is_reported() -> None:
    lin = Line(FAST, [node(7)], [])
    lin.run(0.15)  # online, Allocate sent
    allocate = next(f for _, who, f in lin.frames if who == "scanner" and f.arbitration_id == 0x43E)
    request = ExplicitMessage.decode(allocate.data)
    reply = request.reply(ErrorResponse(0x09, 0x02)).encode()
    actions = lin.scanner.step(lin.now, FrameIn(CanFrame(0x43B, reply)))
    texts = [a.text for a in actions if isinstance(a, Report)]
    assert texts == [
        "node 7: Allocate refused: rejects allocation choice 0x03 (check the connection "
        "setting) [0x09 Invalid attribute value (additional 0x02)]"
    ]
    assert lin.scanner.nodes[7].phase is Phase.WAITING


def test_inactivity_takes_a_node_offline_and_it_comes_back() -> None:
    lin = line(8)
    lin.run(0.3)
    assert ups(lin) == [8]
    off_at = lin.now
    lin.sims[8].power_off()
    lin.run(0.5)
    downs = lin.take(NodeDown)
    assert len(downs) == 1 and downs[0].reason == "no data for 0.2 s (4 x EPR)"
    down_at = next(t for t, who, f in reversed(lin.frames) if who == "node")
    assert down_at <= off_at + 0.02
    lin.power_on(lin.sims[8])
    lin.run(1.0)
    assert ups(lin) == [8]
    assert lin.scanner.node_diagnostics(8)["offline_count"] == 1


def test_inactivity_detected_at_four_epr() -> None:
    lin = line(8)
    lin.run(0.3)
    lin.take(NodeUp)
    last_rx = lin.scanner.nodes[8].last_rx
    lin.sims[8].power_off()
    start = lin.now
    while not lin.take(NodeDown):
        lin.run(0.001)
    assert lin.now - last_rx == pytest.approx(0.2, abs=0.002)
    assert lin.now - start < 0.25


def test_explicit_requests_interleave_with_polls() -> None:
    lin = line(2)
    lin.run(0.3)
    before = len(lin.inputs(2))
    tokens = [lin.scanner.submit(2, GetAttributeSingle(0x67, 1, 113)) for _ in range(5)]
    tokens.append(lin.scanner.submit(2, GetAttributeSingle(0x64, 1, 199)))  # P099: not there
    lin.run(0.3)
    results = {a.token: a for a in lin.take(ExplicitResult)}
    assert [results[t].response for t in tokens[:5]] == [SuccessResponse(0x0E, b"\x02\x00")] * 5
    assert results[tokens[5]].response == ErrorResponse(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
    assert len(lin.inputs(2)) > before + 5  # polls went on meanwhile


def test_explicit_turns_ahead_count_the_lines_window() -> None:
    """A request waits its turn behind those already on the line, explicit_window at a time:
    the adapter's bound for an answer grows with it (63 drives configuring at once)."""
    lin = line(*range(2, 12))
    lin.run(0.3)
    assert lin.scanner.explicit_turns_ahead() == 0
    window = FAST.explicit_window
    for mac in range(2, 2 + window + 1):
        lin.scanner.submit(mac, GetAttributeSingle(1, 1, 1))
    assert lin.scanner.explicit_turns_ahead() == 2  # window + 1 requests: two turns
    lin.run(0.3)
    lin.take(ExplicitResult)
    assert lin.scanner.explicit_turns_ahead() == 0


def test_the_explicit_window_serves_requests_in_the_order_they_were_queued() -> None:
    """First come, first served on the line's explicit window, whatever the node's MAC:
    in the nodes' order the lowest MACs, kept busy, took every freed place and a request
    for a higher MAC waited past its bound (a 63-drive bring-up in the VM starved)."""
    lin = line(2, 3, 4, config=replace(FAST, explicit_window=1))
    lin.run(0.3)
    assert sorted(ups(lin)) == [2, 3, 4]
    lin.take(ExplicitResult)
    first = lin.scanner.submit(4, GetAttributeSingle(1, 1, 1))
    later = [
        lin.scanner.submit(mac, GetAttributeSingle(1, 1, 1)) for _ in range(3) for mac in (2, 3)
    ]
    lin.run(0.2)
    answered = [r.token for r in lin.take(ExplicitResult) if r.token in {first, *later}]
    assert answered == [first, *later]
    assert lin.late_deadlines == []


def test_fragmentation_both_ways() -> None:
    lin = line(2)
    lin.run(0.3)
    # 9-byte request: Set assembly 21 data (4 bytes) -> fragmented request.
    data = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=100).encode()
    set_token = lin.scanner.submit(2, SetAttributeSingle(4, 21, 3, data))
    # 9-byte response: the product name "CFW-08" -> fragmented response.
    get_token = lin.scanner.submit(2, GetAttributeSingle(1, 1, 7))
    lin.run(0.2)
    results = {a.token: a.response for a in lin.take(ExplicitResult)}
    assert results[set_token] == SuccessResponse(0x10)
    assert results[get_token] == SuccessResponse(0x0E, b"\x06CFW-08")
    frag_out = [
        f
        for _, who, f in lin.frames
        if who == "scanner" and f.data and f.data[0] & 0x80 and f.arbitration_id >= 0x400
    ]
    frag_in = [
        f
        for _, who, f in lin.frames
        if who == "node" and f.data and f.data[0] & 0x80 and f.arbitration_id >= 0x400
    ]
    kinds_out = {f.data[1] >> 6 for f in frag_out}
    kinds_in = {f.data[1] >> 6 for f in frag_in}
    assert {0, 2, 3} <= kinds_out  # first and last fragments, and acks of the response
    assert {0, 2, 3} <= kinds_in  # acks of the request, first and last of the response
    assert lin.sims[2].drive.net_ctrl  # the Set arrived whole


def test_explicit_timeout_and_offline_results() -> None:
    lin = line(2)
    lin.run(0.3)
    lin.sims[2].faults.drop_rate = 1.0  # replies lost (polls too)
    token = lin.scanner.submit(2, GetAttributeSingle(1, 1, 1))
    lin.run(0.06)
    result = next(a for a in lin.take(ExplicitResult) if a.token == token)
    assert result.timed_out and result.error == "no response within 0.05 s"
    queued = lin.scanner.submit(2, GetAttributeSingle(1, 1, 1))
    lin.run(0.3)
    failed = next(a for a in lin.take(ExplicitResult) if a.token == queued)
    assert failed.timed_out and failed.response is None
    assert [d.reason for d in lin.take(NodeDown)] == ["no data for 0.2 s (4 x EPR)"]
    with pytest.raises(NodeUnavailable):
        lin.scanner.submit(2, GetAttributeSingle(1, 1, 1))
    with pytest.raises(NodeUnavailable):
        lin.scanner.submit(40, GetAttributeSingle(1, 1, 1))


@pytest.mark.parametrize(
    ("io", "ack"), [(IoKind.COS, True), (IoKind.COS, False), (IoKind.CYCLIC, True)]
)
def test_change_of_state_and_cyclic(io: IoKind, ack: bool) -> None:
    lin = line(3, io=io, ack=ack)
    lin.outputs[3] = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=300).encode()
    lin.run(1.5)
    assert ups(lin) == [3]
    assert lin.sims[3].drive.motor.speed == 300.0
    node_frames = [f for _, who, f in lin.frames if who == "node"]
    scanner_frames = [f for _, who, f in lin.frames if who == "scanner"]
    productions = [f for f in node_frames if f.arbitration_id == 0x340 | 3]  # G1 0xD
    acks_out = [f for f in scanner_frames if f.arbitration_id == 0x400 | 3 << 3 | 2]  # G2 msg 2
    acks_in = [f for f in node_frames if f.arbitration_id == 0x3C0 | 3 and not f.data]
    assert len(productions) > 5 and lin.inputs(3)
    assert (len(acks_out) > 0) is ack and (len(acks_in) > 0) is ack
    choice = next(f for f in scanner_frames if f.arbitration_id == 0x41E).data[4]
    assert choice == (0x11 if io is IoKind.COS else 0x21) | (0 if ack else 0x40)
    assert lin.scanner.node_diagnostics(3)["ack_timeouts"] == 0


def test_cyclic_produces_at_the_epr() -> None:
    lin = line(3, io=IoKind.CYCLIC)
    lin.run(1.0)
    times = [t for t, who, f in lin.frames if who == "node" and f.arbitration_id == 0x343]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert gaps and all(g == pytest.approx(0.05, abs=0.002) for g in gaps)


def test_transmit_failure_backs_off() -> None:
    lin = line(2)
    lin.run(0.3)
    s = lin.scanner
    first = s.step(lin.now, TxFailed("Transmit buffer full"))
    assert [a.text for a in first if isinstance(a, Report)] == [
        "cannot send (Transmit buffer full): backing off 0.01 s"
    ]
    assert not [a for a in s.step(lin.now + 0.005) if isinstance(a, Send)]
    again = s.step(lin.now + 0.005, TxFailed("Transmit buffer full"))
    assert not [a for a in again if isinstance(a, Report)]  # one report per series
    assert not [a for a in s.step(lin.now + 0.02) if isinstance(a, Send)]  # held 0.02 s
    assert s.line_diagnostics()["tx_failures"] == 2


def test_bus_errors_are_reported_and_restart_resumes_nodes() -> None:
    lin = line(2)
    lin.run(0.3)
    s = lin.scanner
    passive = s.step(lin.now, BusErrorIn(frozenset({LineCondition.ERROR_PASSIVE})))
    assert [a.text for a in passive if isinstance(a, Report)] == [
        "line: error passive (health error passive)"
    ]
    off = s.step(lin.now, BusErrorIn(frozenset({LineCondition.BUS_OFF})))
    assert [a.text for a in off if isinstance(a, Report)] == ["line: bus-off (health bus-off)"]
    lin.sims[2].power_off()
    lin.run(1.0)
    assert lin.take(NodeDown)
    s.nodes[2].retry_at = lin.now + 100.0  # deep in its back-off
    lin.power_on(lin.sims[2])
    lin.run(0.2)
    back = s.step(lin.now, BusErrorIn(frozenset({LineCondition.RESTARTED})))
    assert [a.text for a in back if isinstance(a, Report)] == ["line: restarted (health ok)"]
    lin.run(0.3)
    assert ups(lin)[-1] == 2
    assert s.line_diagnostics()["bus_conditions"] == {
        "error passive": 1,
        "bus-off": 1,
        "restarted": 1,
    }


def test_leave_releases_every_node() -> None:
    lin = line(1, 2)
    lin.run(0.3)
    lin.leave()
    lin.run(0.05)
    releases = [f for _, who, f in lin.frames if who == "scanner" and f.data[1:2] == b"\x4c"]
    assert sorted(f.arbitration_id for f in releases) == [0x40E, 0x416]
    assert all(f.data[1:] == bytes.fromhex("4c 03 01 03") for f in releases)
    assert lin.scanner.left
    assert all(n.allocation == 0 for n in lin.sims.values())


def test_allocate_and_release_requests_are_spaced() -> None:
    """63 drives coming up or leaving do not put 63 frames at once into a SocketCAN
    transmit queue (10 frames by default): one Allocate or Release per request_spacing."""
    macs = list(range(1, 64))
    lin = Line(FAST, [node(m) for m in macs], [sim(m) for m in macs])
    lin.power_on()
    lin.run(1.0)
    assert sorted(ups(lin)) == macs
    lin.leave()
    lin.run(0.5)
    assert lin.scanner.left and all(n.allocation == 0 for n in lin.sims.values())
    for service in (b"\x4b", b"\x4c"):
        times = [
            t
            for t, who, f in lin.frames
            if who == "scanner" and f.arbitration_id & 7 == 6 and f.data[1:2] == service
        ]
        assert len(times) == 63
        assert min(b - a for a, b in itertools.pairwise(times)) >= 0.002 - 1e-9
    assert lin.late_deadlines == []


def test_keepalive_reads_identity_status() -> None:
    config = replace(FAST, explicit_epr=0.1)
    lin = line(2, config=config)
    lin.run(1.0)
    gets = [
        f
        for _, who, f in lin.frames
        if who == "scanner" and f.arbitration_id == 0x414 and f.data[1:] == b"\x0e\x01\x01\x05"
    ]
    assert len(gets) >= 10
    assert lin.scanner.nodes[2].phase is Phase.ONLINE


def test_a_reset_node_comes_back() -> None:
    lin = line(2)
    lin.run(0.3)
    lin.sims[2].inject_fault(12)
    lin.outputs[2] = Out21(fault_reset=True).encode()
    lin.run(0.1)
    assert lin.sims[2].phase is SimPhase.RESETTING
    lin.outputs[2] = Out21().encode()
    lin.run(1.5)
    assert [type(a) for a in lin.actions if isinstance(a, NodeUp | NodeDown)] == [
        NodeUp,
        NodeDown,
        NodeUp,
    ]
    assert lin.sims[2].drive.fault_code is None


def test_config_errors() -> None:
    with pytest.raises(ValueError, match="used twice"):
        Scanner(FAST, [node(1), node(1)])
    with pytest.raises(ValueError, match="used twice"):
        Scanner(FAST, [node(0)])
    s = Scanner(FAST, [node(1)])
    with pytest.raises(FrameEncodeError):
        s.set_output(1, b"\x00")
    assert s.next_deadline() is None or s.next_deadline() == 0.0


# ---------------------------------------------------------------- line faults and timers


def test_a_line_that_cannot_send_is_not_stepped_in_a_loop() -> None:
    """Transmit buffer full / bus-off: the scanner holds its sends and is not stepped
    again until the hold ends, whatever work is waiting (polls, explicit, COS, Allocate)."""
    lin = Line(FAST, [node(2), node(3, io=IoKind.COS)], [sim(2), sim(3)])
    lin.power_on()
    lin.run(0.3)
    assert sorted(ups(lin)) == [2, 3]
    lin.scanner.submit(2, GetAttributeSingle(1, 1, 1))
    lin.scanner.set_output(3, Out21(run_fwd=True).encode())  # a change of state to send
    lin.bus_down = True
    steps = lin.timer_steps
    lin.run(3.0)
    assert sorted(d.mac for d in lin.take(NodeDown)) == [2, 3]
    assert lin.late_deadlines == []
    assert lin.timer_steps - steps < 200  # a held line is stepped when the hold ends
    reports = [a.text for a in lin.take(Report) if a.kind is ReportKind.BUS]
    assert reports[0] == "cannot send (Transmit buffer full): backing off 0.01 s"


def test_send_failures_do_not_grow_the_nodes_back_off() -> None:
    """A long outage of the line itself (bus-off, interface down): the nodes are allocated
    again as soon as the line is back, not after their longest back-off."""
    lin = line(4, config=replace(FAST, retry_max=30.0))
    lin.run(0.3)
    assert ups(lin) == [4]
    lin.bus_down = True
    lin.run(120.0)
    assert lin.take(NodeDown)
    assert lin.scanner.nodes[4].backoff < 1.0
    lin.bus_down = False
    back = lin.now
    while not ups(lin):
        lin.run(0.01)
    assert lin.now - back < 1.5  # the send hold (at most 1 s), then Release + Allocate


def test_a_restarted_node_is_allocated_when_its_duplicate_mac_check_ends() -> None:
    """A node off for long is deep in its back-off; when it powers up again its Duplicate
    MAC ID requests show it, and it is allocated as soon as its check is over."""
    lin = line(4, config=replace(FAST, retry_max=30.0))
    lin.run(0.3)
    lin.sims[4].power_off()
    lin.run(120.0)
    assert lin.take(NodeDown) and lin.scanner.nodes[4].backoff == 30.0
    lin.take(NodeUp)
    powered = lin.now
    lin.power_on(lin.sims[4])
    while not ups(lin):
        lin.run(0.005)
    assert lin.now - powered < 2 * 0.05 + 0.03  # its two checks, then the bring-up
    assert lin.late_deadlines == []


def test_no_ack_is_reported_once_per_series() -> None:
    """An unanswered frame is retransmitted with an error frame each time: one event."""
    lin = line(2)
    lin.run(0.3)
    s = lin.scanner
    no_ack = BusErrorIn(frozenset({LineCondition.NO_ACK}))
    texts = [a.text for _ in range(50) for a in s.step(lin.now, no_ack) if isinstance(a, Report)]
    assert texts == ["line: no ACK (health ok)"]
    assert s.line_diagnostics()["bus_conditions"] == {"no ACK": 50}
    lin.run(0.1)  # frames come in again: the next series is reported
    assert [a.text for a in s.step(lin.now, no_ack) if isinstance(a, Report)] == [
        "line: no ACK (health ok)"
    ]


def test_back_to_error_active_restores_the_line_health() -> None:
    lin = line(2)
    lin.run(0.3)
    s = lin.scanner
    s.step(lin.now, BusErrorIn(frozenset({LineCondition.CONTROLLER, LineCondition.ERROR_PASSIVE})))
    assert s.line_diagnostics()["health"] == "error passive"
    active = BusErrorIn(frozenset({LineCondition.CONTROLLER, LineCondition.ERROR_ACTIVE}))
    assert [a.text for a in s.step(lin.now, active) if isinstance(a, Report)] == [
        "line: controller problem, error active (health ok)"
    ]
    assert s.line_diagnostics()["health"] == "ok"


def test_a_late_fragment_of_a_closed_connection_is_ignored() -> None:
    lin = line(2)
    lin.run(0.3)
    lin.sims[2].power_off()
    while not lin.take(NodeDown):
        lin.run(0.01)
    s = lin.scanner
    s.nodes[2].retry_at = lin.now + 100.0  # deep in its back-off
    first = ExplicitFragment(0x40, FragmentType.FIRST, 0, bytes.fromhex("8e 06 43 46 57 2d"))
    s.step(lin.now, FrameIn(CanFrame(0x413, first.encode())))
    s.step(lin.now)
    deadline = s.next_deadline()
    assert deadline is not None and deadline > lin.now  # no partial message left to time out
    assert s.node_diagnostics(2)["stale_responses"] == 1


def test_timer_steps_never_ask_to_be_repeated_at_once() -> None:
    """After a timer step every due timer is handled: the next deadline is in the future
    (else a real event loop would spin), through bring-up, I/O of every kind, a node
    lost and back, a fault reset, and a line that cannot send for a while."""
    nodes = [node(2), node(3, io=IoKind.COS), node(4, io=IoKind.CYCLIC, ack=False)]
    lin = Line(FAST, nodes, [sim(2), sim(3), sim(4)])
    lin.power_on()
    lin.outputs[3] = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=300).encode()
    lin.run(0.5)
    lin.sims[2].power_off()
    lin.run(0.5)
    lin.power_on(lin.sims[2])
    lin.sims[4].inject_fault(12)
    lin.outputs[4] = Out21(fault_reset=True).encode()
    lin.run(1.0)
    lin.bus_down = True
    lin.run(1.5)
    lin.bus_down = False
    lin.run(2.0)
    assert sorted(set(ups(lin))) == [2, 3, 4]
    assert lin.late_deadlines == []


# ---------------------------------------------------------------- I/O over 8 bytes


class BigIoSlave:
    """A scripted Group 2 Only slave with 12-byte I/O (not a CFW-08): it answers the
    bring-up, reassembles our fragmented polls and answers with fragmented data."""

    MAC = 9
    SIZE = 12

    def __init__(self) -> None:
        self.received: list[bytes] = []
        self.io = IoReassembler()
        self.answers = {
            (1, 1): encode_value(CipType.UINT, 0x355),
            (1, 3): encode_value(CipType.UINT, 1),
            (1, 7): b"\x01X",
            (2, 7): encode_value(CipType.UINT, self.SIZE),
            (2, 8): encode_value(CipType.UINT, self.SIZE),
        }

    def on_frame(self, now: float, frame: CanFrame) -> list[CanFrame]:
        message_id = frame.arbitration_id & 7
        if message_id in (4, 6):  # explicit request, Allocate
            request = ExplicitMessage.decode(frame.data)
            reply = request.reply(self._answer(request))
            return [CanFrame(0x400 | self.MAC << 3 | 3, reply.encode())]
        if message_id == 5:  # poll: fragments of our output
            data = self.io.feed(now, frame.data).message
            if data is None:
                return []
            self.received.append(data)
            produced = bytes(range(100, 100 + self.SIZE))
            return [CanFrame(0x3C0 | self.MAC, f) for f in fragment_io(produced)]
        return []

    def _answer(self, request: ExplicitMessage) -> Response:
        body = request.body
        if isinstance(body, AllocateConnectionSet):
            return AllocateResponse(0)
        if isinstance(body, SetAttributeSingle):
            return SuccessResponse(0x10, body.value)
        assert isinstance(body, GetAttributeSingle)
        key = (body.instance_id, body.attribute_id)
        return SuccessResponse(0x0E, self.answers.get(key, encode_value(CipType.WORD, 0)))


def test_io_longer_than_a_frame_is_fragmented_both_ways() -> None:
    """Fact sheet 2.8: I/O messages over 8 bytes go as first/middle/last fragments."""
    slave = BigIoSlave()
    size = BigIoSlave.SIZE
    scanner = Scanner(
        FAST, [NodeConfig(slave.MAC, epr=0.05, produced_size=size, consumed_size=size)]
    )
    now, inputs, wire = 0.0, [], []
    pending: list[CanFrame] = []
    while now < 0.5:
        actions = scanner.step(now)
        if scanner.online and slave.MAC in scanner.online_macs():
            scanner.set_output(slave.MAC, bytes(range(size)))
        while actions:
            action = actions.pop(0)
            if isinstance(action, Send):
                wire.append(action.frame)
                pending.extend(slave.on_frame(now, action.frame))
            elif isinstance(action, InputData):
                inputs.append(action.data)
            while pending:
                actions.extend(scanner.step(now, FrameIn(pending.pop(0))))
        now += 0.005
    assert inputs and set(inputs) == {bytes(range(100, 100 + size))}
    assert bytes(range(size)) in slave.received
    polls = [f.data for f in wire if f.arbitration_id == 0x400 | slave.MAC << 3 | 5 and f.data]
    assert {len(p) for p in polls} == {8, 6}  # 1 + 7 bytes, then 1 + 5 bytes
    assert scanner.node_diagnostics(slave.MAC)["errors"] == 0


def test_other_allocate_refusals_name_the_additional_code() -> None:
    """Fact sheet 2.5: additional code 0x04, predefined-set resources unavailable."""
    lin = Line(FAST, [node(7)], [])
    lin.run(0.15)
    allocate = next(f for _, who, f in lin.frames if who == "scanner" and f.arbitration_id == 0x43E)
    reply = ExplicitMessage.decode(allocate.data).reply(ErrorResponse(0x02, 0x04)).encode()
    actions = lin.scanner.step(lin.now, FrameIn(CanFrame(0x43B, reply)))
    assert [a.text for a in actions if isinstance(a, Report)] == [
        "node 7: Allocate refused: Predefined Master/Slave Connection Set resources "
        "unavailable [0x02 Resource unavailable (additional 0x04)]"
    ]
    assert lin.scanner.nodes[7].phase is Phase.WAITING  # retried with back-off


@pytest.mark.parametrize("window", [4, 63])
def test_explicit_requests_in_flight_are_bounded(window: int) -> None:
    """A request to each of 63 drives at once (the adapter's status reads do this every
    ``status_interval``) would put 63 frames into one pass: more than a SocketCAN transmit
    queue of 10 takes (ENOBUFS), and on a slow host they all race their timeouts. At most
    ``explicit_window`` (4 by default) are in flight; every request is answered."""
    macs = list(range(1, 64))
    config = replace(FAST, explicit_window=window)
    lin = Line(config, [node(m) for m in macs], [sim(m) for m in macs])
    lin.power_on()
    lin.run(1.0)
    assert sorted(ups(lin)) == macs
    lin.take(ExplicitResult)
    tokens = {lin.scanner.submit(m, GetAttributeSingle(1, 1, 1)) for m in macs}
    sent = [a for a in lin.scanner.step(lin.now) if isinstance(a, Send)]
    requests = [a for a in sent if a.frame.arbitration_id & 0x607 == 0x404]  # G2 message 4
    if window == 4:
        assert ScannerConfig().explicit_window == 4
        assert len(requests) == 4
    else:
        assert len(requests) == 63  # what the window prevents
    lin._pending.extend((lin.scanner, a.frame) for a in sent)
    lin.run(0.5)
    results = lin.take(ExplicitResult)
    assert {r.token for r in results} >= tokens
    assert all(r.error is None for r in results if r.token in tokens)
    assert lin.late_deadlines == []


def test_link_down_takes_every_node_offline_at_once_with_the_reason() -> None:
    """SocketCAN ENETDOWN (``ip link set can0 down``): every connection is gone now, not
    after 4 x EPR; reported once per series; the nodes come back when frames pass."""
    lin = line(2, 3)
    lin.run(0.3)
    assert sorted(ups(lin)) == [2, 3]
    s = lin.scanner
    down = LinkDown("Failed to transmit: Network is down [Error Code 100]")
    actions = s.step(lin.now, down)
    reason = "CAN interface down (Failed to transmit: Network is down [Error Code 100])"
    assert sorted((a.mac, a.reason) for a in actions if isinstance(a, NodeDown)) == [
        (2, reason),
        (3, reason),
    ]
    assert [a.text for a in actions if isinstance(a, Report)] == [reason]
    again = s.step(lin.now, down)
    assert not [a for a in again if isinstance(a, Report | NodeDown)]  # once per series
    assert s.line_diagnostics()["link_down"] == 2
    lin.run(1.0)  # the interface is up again: allocated again, stopped
    assert sorted(ups(lin)) == [2, 3]
    assert lin.late_deadlines == []


@pytest.mark.parametrize("window", [4, 63])
def test_nodes_are_brought_up_a_few_at_a_time(window: int) -> None:
    """A node is allocated only when it can be configured at once: an allocated node left
    waiting would lose its explicit connection (EPR 2.5 s, fact sheet 2.9) on a busy line.
    With nobody answering, only ``bringup_window`` Allocates go out before they time out."""
    config = replace(FAST, bringup_window=window)
    s = Scanner(config, [node(m) for m in range(1, 11)])
    now, sent = 0.0, []
    while now < 2 * config.dupmac_timeout + config.allocate_timeout * 0.8:
        sent += [a.frame for a in s.step(now) if isinstance(a, Send)]
        deadline = s.next_deadline()
        assert deadline is not None
        now = max(deadline, now + 1e-4)
    allocates = [f for f in sent if f.arbitration_id & 0x607 == 0x406]  # G2 message 6
    assert len(allocates) == min(window, 10)
    assert ScannerConfig().bringup_window == 4


def test_a_request_in_flight_longer_than_the_keepalive_period_is_not_a_busy_loop() -> None:
    """An explicit timeout longer than half the explicit EPR (a slow line, or the rig's
    timers scaled on a slow machine): the keep-alive is due while a request is in flight,
    and must not leave a deadline in the past after every timer step."""
    config = replace(FAST, explicit_epr=0.1, explicit_timeout=0.3)
    lin = Line(config, [NodeConfig(2, epr=1.0, identity=CFW08)], [sim(2)])
    lin.power_on()
    lin.run(0.5)
    assert ups(lin) == [2]
    lin.sims[2].power_off()
    s = lin.scanner
    s.submit(2, GetAttributeSingle(1, 1, 1))
    t, end, steps = lin.now, lin.now + 0.25, 0  # past the keep-alive, before the timeout
    while t < end and steps < 1000:
        s.step(t)
        steps += 1
        deadline = s.next_deadline()
        assert deadline is not None
        t = max(deadline, t)
    assert steps < 100  # the poll cycles' steps, not one step after another at one instant
    s.leave(t)
    deadline = s.next_deadline()
    assert deadline is not None and deadline > t  # leaving: stale poll timeouts are gone


def test_an_explicit_connection_the_node_deleted_is_allocated_again() -> None:
    """Fact sheet 2.9: a node deletes its explicit connection after 4 x EPR of silence
    (auto delete) and keeps its poll connection. Requests waiting too long for the window
    on a slow machine did that to nodes in the VM; the scanner then sent explicit requests
    into nothing for good. After two unanswered in a row it allocates explicit again
    (choice 0x01 on G2 message 6), sets its EPR, and the node stays online throughout."""
    config = replace(FAST, explicit_epr=10.0)  # the scanner's keep-alive: every 5 s
    lin = line(2, config=config)
    lin.run(0.3)
    assert ups(lin) == [2]
    node = lin.sims[2]
    node.connections[ConnectionInstance.EXPLICIT].set_epr(100)  # the node's silence: 0.4 s
    lin.run(1.0)
    assert not node.allocation & AllocationChoice.EXPLICIT  # deleted by the node
    lin.run(12.0)  # two keep-alives unanswered, then the allocation
    again = [
        f.data.hex(" ")
        for _, who, f in lin.frames
        if who == "scanner" and f.arbitration_id == 0x416 and f.data[1] == 0x4B
    ]
    assert again[-1].endswith("4b 03 01 01 00")  # Allocate, choice explicit only, master 0
    assert node.allocation & AllocationChoice.EXPLICIT
    diag = lin.scanner.node_diagnostics(2)
    assert diag["explicit_reallocations"] == 1 and diag["explicit_timeouts"] == 2
    assert [r.text for r in lin.take(Report) if "again" in r.text] == [
        "node 2: 2 explicit requests unanswered: allocating its explicit connection again"
    ]
    ok = diag["explicit_ok"]
    lin.run(6.0)  # the next keep-alive is answered
    assert lin.scanner.node_diagnostics(2)["explicit_ok"] > ok
    assert not lin.take(NodeDown) and lin.scanner.nodes[2].phase is Phase.ONLINE
