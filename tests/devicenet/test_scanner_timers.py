"""Timer steps that look only at the nodes due or busy (``SteadyTimers``) do what the
full pass over every node does: the same frames at the same times, the same reports and
the same deadlines, on lines that come up, poll, keep their explicit connections alive,
carry explicit requests and change-of-state outputs, lose nodes and get them back, cannot
send for a while, go down and leave. And on a steady line most timer steps are such
steps, so the short cut is really taken."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.cfw08 import Out21
from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.explicit import GetAttributeSingle
from adapters.devicenet.codec.objects import IdentityAttribute
from adapters.devicenet.scanner import IoKind, LinkDown, NodeUnavailable, Phase, Scanner
from adapters.devicenet.scanner.node import Node
from adapters.devicenet.scanner.timers import SteadyTimers
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import FAST, node, sim

KEEPALIVES = replace(FAST, explicit_epr=0.1)  # keep-alives every 50 ms
MACS = tuple(range(1, 9))
GET = GetAttributeSingle(CipClass.IDENTITY, 1, IdentityAttribute.STATUS)
RUN = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=300).encode()
STOP = Out21().encode()

Op = tuple[str, Any]


def make_line(lazy: bool) -> Line:
    """Eight CFW-08s: six polled, one change-of-state, one cyclic without acknowledge."""
    nodes = [node(m) for m in MACS[:6]]
    nodes += [node(7, io=IoKind.COS), node(8, io=IoKind.CYCLIC, ack=False)]
    lin = Line(KEEPALIVES, nodes, [sim(m) for m in MACS])
    lin.scanner.lazy_timers = lazy
    lin.power_on()
    return lin


def _request(lin: Line, mac: int) -> None:
    with contextlib.suppress(NodeUnavailable):  # a node not online refuses it
        lin.scanner.submit(mac, GET)


def _link_down(lin: Line, _: object) -> None:
    lin._scanner_actions(lin.scanner.step(lin.now, LinkDown("Network is down")))


PLAY: dict[str, Callable[[Line, Any], None]] = {
    "run": Line.run,
    "off": lambda lin, mac: lin.sims[mac].power_off(),
    "on": lambda lin, mac: lin.power_on(lin.sims[mac]),
    "request": _request,
    "output": lambda lin, run: lin.scanner.set_output(7, RUN if run else STOP),
    "link_down": _link_down,
    "bus": lambda lin, down: setattr(lin, "bus_down", down),
}


def play(lin: Line, ops: list[Op]) -> None:
    for op, arg in ops:
        PLAY[op](lin, arg)


def record(lin: Line) -> dict[str, Any]:
    scanner = lin.scanner
    return {
        "frames": [(round(t, 9), who, f.arbitration_id, f.data) for t, who, f in lin.frames],
        "actions": [repr(a) for a in lin.actions],
        "timer_steps": lin.timer_steps,
        "late": lin.late_deadlines,
        "phases": {m: n.phase for m, n in scanner.nodes.items()},
        "deadline": scanner.next_deadline(),
    }


def both(ops: list[Op], before_leaving: float = 0.1) -> tuple[dict[str, Any], dict[str, Any]]:
    out = []
    for lazy in (False, True):
        lin = make_line(lazy)
        lin.run(0.4)
        play(lin, ops)
        lin.bus_down = False
        lin.run(before_leaving)
        lin.leave()
        # the Releases wait out a send hold left by the bus being down (up to
        # tx_backoff_max after the last failure: a hypothesis example left the bus down
        # 0.66 s and the leave at once, with the hold 0.61 s ahead)
        lin.run(0.5 + lin.scanner.config.tx_backoff_max)
        assert lin.scanner.left
        out.append(record(lin))
    return out[0], out[1]


def test_a_lines_life_is_the_same_with_the_short_cut() -> None:
    ops: list[Op] = [
        ("run", 0.5),
        ("request", 3),
        ("output", True),
        ("run", 0.3),
        ("off", 2),
        ("off", 7),
        ("run", 0.5),
        ("on", 2),
        ("on", 7),
        ("request", 5),
        ("request", 6),
        ("run", 0.4),
        ("bus", True),
        ("run", 0.3),
        ("bus", False),
        ("run", 0.6),
        ("link_down", 0),
        ("run", 0.8),
        ("output", False),
        ("run", 0.3),
    ]
    full, lazy = both(ops)
    assert len(full["frames"]) > 1000
    assert lazy == full


OPS = st.one_of(
    st.tuples(st.just("run"), st.floats(0.001, 0.4)),
    st.tuples(st.just("off"), st.sampled_from(MACS)),
    st.tuples(st.just("on"), st.sampled_from(MACS)),
    st.tuples(st.just("request"), st.sampled_from(MACS)),
    st.tuples(st.just("output"), st.booleans()),
    st.tuples(st.just("link_down"), st.just(0)),
    st.tuples(st.just("bus"), st.booleans()),
)


@settings(max_examples=20, deadline=None)
@given(st.lists(OPS, min_size=1, max_size=10), st.floats(0.0, 0.3))
def test_the_short_cut_changes_nothing_whatever_happens(ops: list[Op], leaving: float) -> None:
    full, lazy = both(ops, leaving)
    assert lazy == full


def test_a_steady_line_takes_the_short_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    """Once every node is up, few timer steps pass over every node: those after a
    request queued or a window freed (each keep-alive is one), not the poll cycles'."""
    full = {"passes": 0}
    tick = Scanner._tick

    def counting(self: Scanner, now: float) -> None:
        full["passes"] += 1
        tick(self, now)

    monkeypatch.setattr(Scanner, "_tick", counting)
    lin = Line(FAST, [node(m) for m in MACS], [sim(m) for m in MACS])  # keep-alives 1.25 s
    lin.power_on()
    lin.run(0.5)
    assert all(n.phase is Phase.ONLINE for n in lin.scanner.nodes.values())
    steps, passes = lin.timer_steps, full["passes"]
    lin.run(3.0)
    steps, passes = lin.timer_steps - steps, full["passes"] - passes
    assert steps > 100
    assert passes < steps / 4


# ---------------------------------------------------------------- the heap itself


class Clock:
    """Nodes whose idle time is set directly (the test plays the engine)."""

    def __init__(self, macs: list[int]) -> None:
        self.nodes = {m: Node(node(m), backoff=0.1) for m in macs}
        self.idle = dict.fromkeys(macs, 0.0)
        self.steady = dict.fromkeys(macs, True)
        self.timers = SteadyTimers(
            self.nodes, lambda n: self.steady[n.mac], lambda n: self.idle[n.mac]
        )


EDITS = st.lists(
    st.tuples(
        st.integers(0, 5),  # node
        st.booleans(),  # steady
        st.floats(0.0, 10.0),  # how much later its idle time moves (only later: steady)
        st.floats(0.0, 3.0),  # how far the clock moves
    ),
    min_size=1,
    max_size=40,
)


@settings(max_examples=60, deadline=None)
@given(EDITS)
def test_due_and_soonest_agree_with_a_pass_over_every_node(edits: list[Any]) -> None:
    macs = [10, 11, 12, 13, 14, 15]
    c = Clock(macs)
    c.timers.rebuild()
    now = 0.0
    for index, steady, later, advance in edits:
        mac = macs[index]
        was = c.steady[mac]
        c.steady[mac] = steady
        # a steady node's idle time only moves later; a node becoming steady may have any
        c.idle[mac] = c.idle[mac] + later if was and steady else now + later
        c.timers.track(c.nodes[mac])
        assert c.timers.soonest() == min((c.idle[m] for m in macs if c.steady[m]), default=None)
        now += advance
        expected = [m for m in macs if not c.steady[m] or c.idle[m] <= now]
        due = c.timers.due(now)
        assert [n.mac for n in due] == expected
        for n in due:  # the engine ticks them: each becomes busy or idle again
            if c.steady[n.mac]:
                c.idle[n.mac] = now + 1.0
            c.timers.track(n)
        assert c.timers.soonest() == min((c.idle[m] for m in macs if c.steady[m]), default=None)
