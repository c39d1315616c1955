"""The scanner keeps the count of nodes in bring-up (allocating or configuring) as phases
change, instead of counting them over the line for every frame: the kept count equals the
full count before and after every step of lines that come up, refuse a node, time out on
a silent one, lose nodes and get them back, go down and leave; and the bring-up window
holds."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.scanner import IdentityCheck, LinkDown, NodeConfig, Phase, Scanner
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import FAST, node, sim

WINDOW2 = replace(FAST, bringup_window=2)


def full_count(scanner: Scanner) -> int:
    return sum(n.phase in (Phase.ALLOCATING, Phase.CONFIGURING) for n in scanner.nodes.values())


def install_checks(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Scanner.step and Scanner.leave check the count before and after."""
    seen: dict[str, Any] = {"steps": 0, "counts": set()}
    step, leave = Scanner.step, Scanner.leave

    def check(scanner: Scanner) -> None:
        count = full_count(scanner)
        assert scanner.schedule.bringups() == count
        assert count <= scanner.config.bringup_window
        seen["counts"].add(count)

    def checking_step(self: Scanner, now: float, event: Any = None) -> Any:
        check(self)
        actions = step(self, now, event)
        check(self)
        seen["steps"] += 1
        return actions

    def checking_leave(self: Scanner, now: float) -> Any:
        check(self)
        actions = leave(self, now)
        check(self)
        return actions

    monkeypatch.setattr(Scanner, "step", checking_step)
    monkeypatch.setattr(Scanner, "leave", checking_leave)
    return seen


@pytest.fixture
def checked(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    return install_checks(monkeypatch)


def mixed_line() -> Line:
    """Six CFW-08s, one answering with another identity (refused), one MAC configured
    with nothing there (its Allocate times out, again and again); window of two."""
    wrong = IdentityCheck(0x123, None, "not a CFW-08")
    nodes = [*(node(m) for m in range(1, 7)), NodeConfig(7, epr=0.05, identity=wrong), node(8)]
    sims = [sim(m) for m in range(1, 8)]
    lin = Line(WINDOW2, nodes, sims)
    lin.power_on()
    return lin


def down(lin: Line) -> None:
    lin._scanner_actions(lin.scanner.step(lin.now, LinkDown("Network is down")))


def test_kept_count_equals_the_full_count_through_a_lines_life(checked: dict[str, Any]) -> None:
    lin = mixed_line()
    lin.run(1.0)
    online = sorted(m for m, n in lin.scanner.nodes.items() if n.phase is Phase.ONLINE)
    assert online == [1, 2, 3, 4, 5, 6]
    assert lin.scanner.nodes[7].phase is Phase.REFUSED
    for mac in (2, 5):
        lin.sims[mac].power_off()  # inactivity, then back
    lin.run(0.4)
    for mac in (2, 5):
        lin.power_on(lin.sims[mac])
    lin.run(0.15)  # some of them allocating or configuring again
    down(lin)  # the interface goes down in the middle of it
    lin.bus_down = True
    lin.run(0.2)
    lin.bus_down = False
    lin.run(1.2)
    online = sorted(m for m, n in lin.scanner.nodes.items() if n.phase is Phase.ONLINE)
    assert online == [1, 2, 3, 4, 5, 6]
    lin.run(0.02)
    lin.leave()
    lin.run(0.5)
    assert lin.scanner.left
    assert checked["steps"] > 500 and checked["counts"] >= {0, 1, 2}


OPS = st.one_of(
    st.tuples(st.just("run"), st.floats(0.001, 0.3)),
    st.tuples(st.just("off"), st.integers(1, 7)),
    st.tuples(st.just("on"), st.integers(1, 7)),
    st.tuples(st.just("link_down"), st.just(0)),
    st.tuples(st.just("bus"), st.booleans()),
)


@settings(max_examples=25, deadline=None)
@given(st.lists(OPS, min_size=1, max_size=12), st.floats(0.0, 0.3))
def test_kept_count_equals_the_full_count_whatever_happens(
    ops: list[tuple[str, Any]], before_leaving: float
) -> None:
    with pytest.MonkeyPatch.context() as mp:
        seen = install_checks(mp)
        lin = mixed_line()
        lin.run(0.3)
        for op, arg in ops:
            if op == "run":
                lin.run(arg)
            elif op == "off":
                lin.sims[arg].power_off()
            elif op == "on":
                lin.power_on(lin.sims[arg])
            elif op == "link_down":
                down(lin)
            else:
                lin.bus_down = arg
        lin.bus_down = False
        lin.run(before_leaving)
        lin.leave()
        lin.run(0.5)
        assert seen["steps"] > 0
