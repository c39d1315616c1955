"""The master's receive hold (:meth:`Master.hold_until`, the driver's
:meth:`~adapters.link.candriver.CanProtocol.hold_until`): only on a steady line, until
just before the next SYNC (and before any other deadline of the engine); None in every
other state."""

from __future__ import annotations

import dataclasses

import pytest

from adapters.canopen.master import Master
from adapters.canopen.master.engine import HOLD_MARGIN, HOLD_MIN
from adapters.canopen.master.node import Phase
from tests.canopen.test_steady_line import MAX_STEP, SteadyLine


def after_sync(line: SteadyLine) -> None:
    """Run the line on to just after a SYNC (the master's cycle step)."""
    cycle = line.master.next_cycle
    while line.master.next_cycle == cycle:
        line.run(MAX_STEP / 5)


@pytest.fixture
def line() -> SteadyLine:
    line = SteadyLine()
    line.run(3.0)
    assert line.online()
    after_sync(line)
    return line


def test_a_steady_line_holds_until_just_before_the_next_sync(line: SteadyLine) -> None:
    master = line.master
    at = master.hold_until(line.now)
    due = master.next_deadline()
    assert at is not None and master.next_cycle is not None and due is not None
    margin = min(HOLD_MARGIN, master.config.cycle / 4)
    assert at == min(master.next_cycle, due) - margin
    assert line.now + HOLD_MIN <= at < master.next_cycle
    assert master.hold_until(at) is None  # the hold is over: frames are taken as they come


def test_the_hold_ends_before_any_other_deadline_of_the_engine(line: SteadyLine) -> None:
    master = line.master
    assert master.next_cycle is not None
    master._due = line.now + 0.004  # a node's heartbeat loss due before the next SYNC
    at = master.hold_until(line.now)
    margin = min(HOLD_MARGIN, master.config.cycle / 4)
    assert at == pytest.approx(line.now + 0.004 - margin)
    master._due = line.now + 0.003  # too soon for a hold worth its wake-up
    assert master.hold_until(line.now) is None


def test_no_hold_with_an_sdo_in_flight_or_queued(line: SteadyLine) -> None:
    master = line.master
    master.submit(1, 0x6041, 0, None)  # queued
    assert master.hold_until(line.now) is None
    request = master.step(line.now)  # sent: in flight until the answer is stepped
    node = master.nodes[1]
    assert node.current is not None and master.hold_until(line.now) is None
    line._deliver(request)  # on the line, answered
    line.run(0.05)
    assert node.current is None and not node.jobs
    after_sync(line)
    assert master.hold_until(line.now) is not None


def test_no_hold_in_bring_up_of_any_node(line: SteadyLine) -> None:
    master = line.master
    master.nodes[2].phase = Phase.CONFIGURE
    assert master.hold_until(line.now) is None
    master.nodes[2].phase = Phase.ONLINE  # (as it was)
    assert master.hold_until(line.now) is not None


def test_no_hold_when_a_node_is_lost_and_brought_up_again() -> None:
    line = SteadyLine()
    line.run(3.0)
    line.sims[0].power_off()
    line.run(1.0)  # its heartbeat stops: lost, probed again
    assert not line.master.online(1)
    assert line.master.hold_until(line.now) is None


def test_no_hold_when_leaving_the_line(line: SteadyLine) -> None:
    master = line.master
    master.release(line.now)
    assert master.hold_until(line.now) is None
    master.leave(line.now)
    assert master.hold_until(line.now) is None


def test_no_hold_without_sync(line: SteadyLine) -> None:
    master = line.master
    unsynced = Master(dataclasses.replace(master.config, sync_period=0.0, pdo_period=0.01), [])
    assert unsynced.hold_until(0.0) is None
