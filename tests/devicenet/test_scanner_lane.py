"""The steady lane (docs/decisions/0097): a quiet node's unchanged poll response is taken by
its bytes, and the line is the same as through the full step.

The same scripted lines (outputs changed, nodes quiet and not, faults, power cycles, nodes
lost and back, explicit requests, forged second answers, a line that cannot send) run with
the lane and with every frame through the full step: every frame on the bus, every action,
every figure and the next deadline are equal. A quiet node's unchanged inputs are reported
every ``INPUTS_REFRESH``, not on every poll; any change is reported at once."""

from __future__ import annotations

import contextlib
import dataclasses
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.explicit import GetAttributeSingle
from adapters.devicenet.codec.ids import PredefinedMessage
from adapters.devicenet.scanner import InputData, NodeUnavailable, Phase, ScannerConfig
from adapters.devicenet.scanner.machine import INPUTS_REFRESH
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import FAST, node, sim

MACS = (1, 2, 3)
CONFIG = dataclasses.replace(FAST, poll_interval=0.005, bitrate=500_000)
RUN = bytes.fromhex("61 00 00 07")  # Out21: run forward from the net, 1792 rpm
STOP = bytes(4)

Op = tuple[str, int, float]
KINDS = (
    "run", "quiet", "loud", "output", "stop", "fault", "reset", "power", "lose", "explicit",
    "forge", "bus_down", "bus_up",
)  # fmt: skip
ops = st.lists(
    st.tuples(st.sampled_from(KINDS), st.sampled_from(MACS), st.floats(0.001, 0.3)),
    min_size=1,
    max_size=25,
)


def make_line(lane: bool, config: ScannerConfig = CONFIG) -> Line:
    lin = Line(config, [node(m) for m in MACS], [sim(m) for m in MACS])
    lin.scanner.lane = lane
    lin.power_on()
    lin.run(1.5)
    return lin


def quiet_all(lin: Line, quiet: bool) -> None:
    for mac, n in lin.scanner.nodes.items():
        if n.phase is Phase.ONLINE:
            lin.scanner.quiet_inputs(mac, quiet)


def apply(lin: Line, op: Op) -> None:
    kind, mac, t = op
    scanner, sim_node = lin.scanner, lin.sims[mac]
    if kind == "run":
        lin.run(t)
    elif kind == "quiet":
        quiet_all(lin, True)
    elif kind == "loud":
        scanner.quiet_inputs(mac, False)
    elif kind == "output" and scanner.nodes[mac].phase is Phase.ONLINE:
        scanner.set_output(mac, RUN)
    elif kind == "stop" and scanner.nodes[mac].phase is Phase.ONLINE:
        scanner.set_output(mac, STOP)
    elif kind == "fault":
        sim_node.inject_fault(21, lin.now)
    elif kind == "reset":
        for frame in sim_node.keypad_reset(lin.now):
            lin._pending.append((sim_node, frame))
    elif kind == "power":
        sim_node.power_off()
        lin.run(t)
        lin.power_on(sim_node)
    elif kind == "lose":
        sim_node.power_off()
    elif kind == "explicit":
        with contextlib.suppress(NodeUnavailable):
            scanner.submit(mac, GetAttributeSingle(CipClass.IDENTITY, 1, 1))
    elif kind == "forge" and scanner.nodes[mac].last_inputs is not None:
        forged = sim_node._frame(PredefinedMessage.SLAVE_POLL_RESPONSE, bytes(4))
        lin._pending.append((sim_node, forged))
    elif kind == "bus_down":
        lin.bus_down = True
    elif kind == "bus_up":
        lin.bus_down = False


def seen(lin: Line) -> dict[str, Any]:
    scanner = lin.scanner
    return {
        "frames": [(round(t, 9), who, f.arbitration_id, f.data) for t, who, f in lin.frames],
        "actions": [repr(a) for a in lin.actions],
        "line": scanner.line_diagnostics(),
        "nodes": {m: scanner.node_diagnostics(m) for m in MACS},
        "deadline": scanner.next_deadline(),
        "phases": {m: n.phase for m, n in scanner.nodes.items()},
    }


@settings(max_examples=40, deadline=None)
@given(script=ops)
def test_the_lane_puts_on_the_line_what_the_full_step_does(script: list[Op]) -> None:
    lines = {lane: make_line(lane) for lane in (True, False)}
    for lin in lines.values():
        quiet_all(lin, True)
    for op in [*script, ("run", 1, 0.5)]:
        for lin in lines.values():
            apply(lin, op)
        assert seen(lines[True]) == seen(lines[False]), op


def lane_hits(lin: Line) -> list[int]:
    hits: list[int] = []
    steady_reply = lin.scanner._steady_reply

    def counted(n: Any, now: float, frame: Any) -> bool:
        taken = steady_reply(n, now, frame)
        if taken:
            hits.append(n.mac)
        return taken

    lin.scanner._steady_reply = counted  # type: ignore[method-assign,assignment]
    return hits


def test_a_quiet_steady_node_is_polled_by_its_bytes_and_reported_every_refresh() -> None:
    lin = make_line(True)
    hits = lane_hits(lin)
    quiet_all(lin, True)
    lin.actions.clear()
    polls_before = {m: n.figures.rtt_count for m, n in lin.scanner.nodes.items()}
    span = 10 * INPUTS_REFRESH
    lin.run(span)
    for mac, n in lin.scanner.nodes.items():
        polls = n.figures.rtt_count - polls_before[mac]
        reported = len(lin.inputs(mac))
        assert polls >= 100 * span  # every 5 ms
        assert span / INPUTS_REFRESH - 1 <= reported <= span / INPUTS_REFRESH + 1
        assert hits.count(mac) >= polls - reported - 1  # the rest by the lane


def test_a_node_not_quiet_reports_every_poll() -> None:
    lin = make_line(True)
    hits = lane_hits(lin)
    lin.actions.clear()
    polls_before = {m: n.figures.rtt_count for m, n in lin.scanner.nodes.items()}
    lin.run(0.5)
    assert hits == []
    for mac, n in lin.scanner.nodes.items():
        assert len(lin.inputs(mac)) == n.figures.rtt_count - polls_before[mac]


def test_a_changed_input_of_a_quiet_node_is_reported_with_its_poll() -> None:
    lin = make_line(True)
    quiet_all(lin, True)
    lin.run(0.05)
    lin.actions.clear()
    before = lin.scanner.nodes[1].last_inputs
    lin.sims[1].inject_fault(21, lin.now)  # the drive trips: its status word changes
    lin.run(0.02)  # four polls, far less than the refresh
    reported = [a for a in lin.actions if isinstance(a, InputData) and a.mac == 1]
    assert reported and reported[0].data != before  # at once, not at the refresh


def test_quiet_ends_with_the_nodes_phase() -> None:
    lin = make_line(True)
    quiet_all(lin, True)
    lin.sims[2].power_off()
    lin.run(1.0)  # 4 x EPR without data: offline, then allocated again
    n = lin.scanner.nodes[2]
    assert n.figures.offline_count >= 1
    assert not n.quiet
    lin.scanner.quiet_inputs(2, True)
    assert n.quiet is (n.phase is Phase.ONLINE)
