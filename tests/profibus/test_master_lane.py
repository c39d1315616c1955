"""The steady lane (Master.lane, docs/decisions/0096) against the engine's steps.

A reply identical to the slave's last plain Data_Exchange reply, from a slave whose caller
is quiet, is taken by its bytes without decoding, and the next turn is built for the moment
the line is free. These tests run the same scripted lines (noise, power cycles, diagnosis,
DP-V1 jobs, Clear and Operate, replies lost, new outputs from a command) once with the lane
and once through the steps only, and find every telegram (bytes and time), every action
and every counter equal; and they show that a quiet caller, told of its commands, puts on
the line exactly what a caller handling every reply does.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial
from typing import Any

from hypothesis import example, given, settings
from hypothesis import strategies as st

from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.master import InputsReceived, LineMode, Master
from adapters.profibus.master.station import INPUTS_REFRESH
from adapters.profibus.sim.echo import EchoSim
from gateway.sim import FaultInjector
from tests.profibus.wire import FAST_BUS, Wire, echo_line, echo_params

Command = tuple[str, int]
commands: st.SearchStrategy[Command] = st.tuples(
    st.sampled_from(
        ["read", "write", "clear", "operate", "sync", "power", "diag", "drop", "outputs"]
    ),
    st.integers(0, 3),
)
EXT_DIAG = bytes([0x03, 0x01, 0x02])


class Caller:
    """A caller as the Profibus adapter is one: outputs from a table a command changes (set
    at once, the next reply wanted), quiet after each reply it handled when ``quiet``."""

    def __init__(self, w: Wire, addresses: list[int], quiet: bool) -> None:
        self.w = w
        self.quiet = quiet
        self.table = {a: bytes([a, 0, 0, 0]) for a in addresses}
        self.handled = 0

    def on_action(self, action: object) -> None:
        if not isinstance(action, InputsReceived):
            return
        self.handled += 1
        master = self.w.master
        if not master.outputs_pending(action.address):
            master.set_outputs(action.address, self.table[action.address])
            master.quiet_inputs(action.address, self.quiet)
        else:
            master.quiet_inputs(action.address, False)

    def command(self, address: int, n: int) -> None:
        """New outputs at once (a table without pulses: replacing outputs not yet carried
        loses nothing), the next reply wanted."""
        master = self.w.master
        self.table[address] = bytes([address, n, n, n])
        master.quiet_inputs(address, False)
        master.set_outputs(address, self.table[address])


def _apply(w: Wire, caller: Caller, addresses: list[int], command: Command) -> None:
    what, n = command
    address = addresses[n % len(addresses)]
    w.settle()  # a command comes when the driver is back on its loop
    device = w.line[address].device
    assert isinstance(device, EchoSim)
    actions: dict[str, Callable[[], object]] = {
        "read": lambda: w.master.read_record(address, 0, 1 + n, 4, w.now),
        "write": lambda: w.master.write_record(address, 0, 1, bytes([n] * 4), w.now),
        "clear": lambda: w.master.set_mode(LineMode.CLEAR, w.now),
        "operate": lambda: w.master.set_mode(LineMode.OPERATE, w.now),
        "sync": lambda: w.master.global_control(GlobalControl(sync=True)),
        "power": lambda: w.line[address].power_cycle(w.now, off_time=0.01),
        "diag": lambda: setattr(device, "diag", b"" if device.diag else EXT_DIAG),
        "drop": lambda: setattr(w, "drop_replies", n),
        "outputs": lambda: caller.command(address, n),
    }
    actions[what]()
    w.poke()


def _trace(
    *,
    lane: bool,
    ring: bool = False,
    quiet: bool,
    addresses: list[int],
    noise: float,
    seed: int,
    script: list[tuple[float, Command]],
    cycle_time: float = 0.0,
) -> tuple[Any, ...]:
    bus = dataclasses.replace(FAST_BUS, live_list_period=0.0, cycle_time=cycle_time)
    master = Master(bus, [echo_params(a) for a in addresses])
    line = echo_line(addresses)
    line.faults = FaultInjector(seed=seed, bit_error_rate=noise)
    w = Wire(master, line)
    w.whole, w.lane, w.ring = True, lane, ring
    caller = Caller(w, addresses, quiet)
    w.on_action = caller.on_action
    w.run(0.2)
    for wait, command in script:
        w.run(wait)
        _apply(w, caller, addresses, command)
    w.run(0.5)
    w.settle()  # as a driver ends its step: the lane's last turn is the steps' too
    slaves = [master.slave_diagnostics(a) for a in addresses]
    actions = [a for a in w.actions if not isinstance(a, InputsReceived)]
    taken = w.lane_taken + w.ring_taken
    return (
        *(w.sent, actions, master.line_diagnostics(), slaves, taken, caller.handled),
        *(w.ring_taken, master._ring.crossed, w.ring_closed, w.rings, w.ring_left_out),
    )


scripts = st.lists(st.tuples(st.floats(0.001, 0.03), commands), max_size=10)


@settings(max_examples=30, deadline=None)
@given(
    addresses=st.lists(st.integers(3, 9), min_size=1, max_size=4, unique=True),
    noise=st.sampled_from([0.0, 0.0, 1e-3, 1e-2]),
    seed=st.integers(0, 99),
    script=scripts,
)
@example(  # a reply stepped with new inputs (a DP-V1 job waiting), then the one before
    # again: the lane took it as the steady reply and left its inputs unreported
    addresses=[3, 4, 5, 6],
    noise=0.01,
    seed=38,
    script=[(0.015625, ("clear", 0)), (0.0234375, ("read", 0)), (0.0078125, ("read", 0))],
)
def test_the_lane_sends_and_reports_what_the_steps_do(
    addresses: list[int], noise: float, seed: int, script: list[tuple[float, Command]]
) -> None:
    trace = partial(_trace, quiet=True, addresses=addresses, noise=noise, seed=seed, script=script)
    with_lane, steps = trace(lane=True), trace(lane=False)
    assert with_lane[:4] == steps[:4]
    assert with_lane[5] == steps[5]  # the caller handled the same replies
    assert steps[4] == 0
    assert len(steps[0]) > 50  # telegrams went out: the comparison compared something


@settings(max_examples=30, deadline=None)
@given(
    addresses=st.lists(st.integers(3, 9), min_size=2, max_size=5, unique=True),
    noise=st.sampled_from([0.0, 0.0, 1e-3, 1e-2]),
    seed=st.integers(0, 99),
    script=scripts,
    cycle_time=st.sampled_from([0.0, 0.0, 0.004, 0.02]),
)
def test_the_steady_ring_sends_and_reports_what_the_steps_do(
    addresses: list[int],
    noise: float,
    seed: int,
    script: list[tuple[float, Command]],
    cycle_time: float,
) -> None:
    """The steady ring (docs/decisions/0103): what the master plans and enters after a
    ring equals the steps' telegrams (bytes and times), actions and counters, back to back
    and with a cycle time (rings then end with the cycle's Global_Control)."""
    trace = partial(
        _trace,
        quiet=True,
        addresses=addresses,
        noise=noise,
        seed=seed,
        script=script,
        cycle_time=cycle_time,
    )
    with_ring, steps = trace(lane=True, ring=True), trace(lane=False)
    assert with_ring[:4] == steps[:4]
    assert with_ring[5] == steps[5]  # the caller handled the same replies
    assert len(steps[0]) > 50


def test_a_quiet_line_goes_round_in_rings() -> None:
    trace = _trace(
        lane=True, ring=True, quiet=True, addresses=[3, 4, 5], noise=0.0, seed=0, script=[]
    )
    slaves, ring_taken, crossed = trace[3], trace[6], trace[7]
    assert ring_taken > 0.9 * sum(s["exchanges"] for s in slaves)
    cycles = trace[2]["cycles"]
    assert crossed > 0.5 * cycles  # rings go on into the next cycle (its Global_Control too)


def test_a_ring_goes_on_past_a_global_control_not_due_and_sends_it_where_it_is() -> None:
    """Each cycle's end in a ring has the Global_Control in its plan; the ring writes it
    only where it is due (every 20 ms on this bus, a cycle of 3 slaves about 2 ms), as the
    steps do (the property test above compares every telegram), so a ring is no longer cut
    where it may fall due: rings of up to RING_MAX exchanges (docs/decisions/0110)."""
    trace = _trace(
        lane=True, ring=True, quiet=True, addresses=[3, 4, 5], noise=0.0, seed=0, script=[]
    )
    ring_taken, rings, left_out = trace[6], trace[9], trace[10]
    assert ring_taken / rings > 50  # before: cut where it could fall due, about 15 a ring
    assert left_out > 5 * rings  # several cycle ends a ring with no Global_Control due
    broadcasts = [data for _, data in trace[0] if data[0] == 0x68 and data[4] & 0x7F == 127]
    assert 0 < len(broadcasts) < trace[2]["cycles"] / 5  # one every 20 ms, not every cycle


def test_with_a_cycle_time_a_ring_ends_with_the_cycles_global_control() -> None:
    """A cycle time not over: the ring cannot go on into the next cycle, and ends with
    the end's Global_Control, which the line's Python would otherwise send after taking
    the whole ring back (its delay, at every cycle's end, was the turnaround's p99)."""
    trace = _trace(
        lane=True,
        ring=True,
        quiet=True,
        addresses=[3, 4, 5],
        noise=0.0,
        seed=0,
        script=[],
        cycle_time=0.03,  # the Global_Control (every 20 ms on this bus) due at every end
    )
    cycles, crossed, closed = trace[2]["cycles"], trace[7], trace[8]
    assert crossed == 0  # a cycle time: never into the next cycle
    assert closed > 0.8 * cycles


@settings(max_examples=30, deadline=None)
@given(
    addresses=st.lists(st.integers(3, 9), min_size=1, max_size=4, unique=True),
    seed=st.integers(0, 99),
    script=scripts,
)
def test_a_quiet_caller_puts_on_the_line_what_a_caller_of_every_reply_does(
    addresses: list[int], seed: int, script: list[tuple[float, Command]]
) -> None:
    trace = partial(_trace, lane=True, addresses=addresses, noise=0.0, seed=seed, script=script)
    quiet, every = trace(quiet=True), trace(quiet=False)
    assert quiet[0] == every[0]  # the telegrams, bytes and times
    assert quiet[1] == every[1]  # the actions other than inputs
    assert every[4] == 0  # a caller of every reply: the lane never taken


def test_a_quiet_slave_goes_the_lane_and_still_reports_its_inputs_every_refresh() -> None:
    trace = _trace(lane=True, quiet=True, addresses=[3, 4], noise=0.0, seed=0, script=[])
    slaves, taken, handled = trace[3:6]
    exchanges = sum(s["exchanges"] for s in slaves)
    assert taken > 0.8 * exchanges  # the steady exchange went the lane
    # 0.7 s of data exchange: the inputs reported at start and at least every refresh
    assert 2 * 0.7 / INPUTS_REFRESH <= handled < 0.2 * exchanges


def test_changed_inputs_leave_the_lane() -> None:
    """A reply whose bytes differ (new inputs) is stepped and its inputs reported."""
    master = Master(FAST_BUS, [echo_params(3)])
    w = Wire(master, echo_line([3]))
    w.whole = w.lane = True
    seen: list[bytes] = []

    def caller(action: object) -> None:
        if isinstance(action, InputsReceived):
            seen.append(action.data)
            master.quiet_inputs(3, True)

    w.on_action = caller
    w.run(0.1)
    assert w.lane_taken > 0
    master.set_outputs(3, b"\x01\x02\x03\x04")  # the echo slave answers with its outputs
    w.poke()
    w.run(0.01)
    assert seen[-1] == b"\x01\x02\x03\x04"
