"""Bring-up beside data exchange: low-priority work yields to the cycle (issue 25).

IEC 61158-4-3's target rotation time: cyclic data exchange first, low-priority work (a
slave's bring-up, probing absent slaves, DP-V1, the live-list probe) only while the cycle
has time for it. The engine is stepped in fake time against the simulated slaves, whose
watchdog runs as a real slave's does (1.6: T_WD after the last master telegram); a slow
turnaround (the master's loop busy elsewhere) makes every telegram expensive.
"""

from __future__ import annotations

import dataclasses
import itertools

from adapters.profibus.master import InputsReceived, Master, RecordDone, SlaveDown, SlaveState
from adapters.profibus.master.common import MAX_TURN
from adapters.profibus.master.scheduler import LOW_FLOOR, LOW_SHARE
from adapters.profibus.sim.echo import EchoSim
from adapters.profibus.sim.slave import DpSlave
from tests.profibus.wire import FAST_BUS, Wire, echo_line, echo_params

WATCHDOG = 0.5  # s
LAG = 0.002  # s: every request is written this late (the loop busy with other lines)
UP = list(range(3, 13))  # in data exchange when the others appear
STARTING = list(range(13, 53))  # switched on while the first ten exchange
ABSENT = [60, 61, 62, 63, 64]  # configured, never there
LONGEST = 32  # bytes: no telegram to or from the echo slaves is longer (Set_Prm is 19)


def _wire() -> Wire:
    configured = UP + STARTING + ABSENT
    master = Master(FAST_BUS, [echo_params(a, watchdog=WATCHDOG) for a in configured])
    w = Wire(master, echo_line(UP))
    w.write_lag = LAG
    return w


def _in(w: Wire, addresses: list[int], state: SlaveState = SlaveState.DATA_EXCHANGE) -> bool:
    return all(w.master.state_of(a) is state for a in addresses)


def _data_exchange_to(data: bytes) -> int | None:
    """The slave a Data_Exchange request (SD2 without SAPs: the echo slaves have outputs)
    is for; None for any other telegram."""
    if data[0] == 0x68 and not data[4] & 0x80:  # SD2, DA without the SAP bit
        return data[4]
    return None


def _cycle_bound(w: Wire, exchanging: int) -> float:
    """The longest a cycle may take: the budget's share of the watchdog, or the data
    exchange of ``exchanging`` slaves with the floor's share for low-priority work if that
    is longer, plus one grant's overrun and the Global_Control broadcast."""
    bus = w.bus
    exchange = LAG + 2 * bus.tx_time(13) + w.turnaround + bus.tsyn  # 4 bytes each way
    gc = LAG + bus.tx_time(LONGEST) + bus.tsyn
    return max(LOW_SHARE * WATCHDOG, (1 + LOW_FLOOR) * exchanging * exchange) + _turn_bound(w) + gc


def _turn_bound(w: Wire) -> float:
    """The most one low-priority grant can cost beyond the budget: a whole bring-up turn
    (MAX_TURN telegrams each way at their longest, with the slow turnaround and TSYN), or
    an unanswered Slave_Diag with its retries."""
    bus = w.bus
    telegram = LAG + 2 * bus.tx_time(LONGEST) + w.turnaround + bus.tsyn
    silent = (1 + bus.retries) * (LAG + bus.tx_time(LONGEST) + bus.reply_wait + bus.tsyn)
    return max(MAX_TURN * telegram, silent)


def test_slaves_in_data_exchange_stay_served_while_forty_start_up_and_five_are_absent() -> None:
    w = _wire()
    # the first ten come up, and the others are found absent (each after Slave_Diag and
    # its retries, then probed once per absent_retry)
    assert w.run_until(lambda: _in(w, UP) and _in(w, STARTING + ABSENT, SlaveState.ABSENT), 5)
    w.clear()
    for a in STARTING:  # switched on at once
        w.line.add(DpSlave(a, EchoSim(4)))
    start = w.now
    assert w.run_until(lambda: _in(w, UP + STARTING), 10.0), "bring-up did not complete"
    up_at = w.now
    w.run(0.3)
    # no slave that was in data exchange ever left it
    assert [a for a in w.of(SlaveDown)] == []
    # each of the first ten was served within the budget's bound all along
    bound = _cycle_bound(w, len(UP + STARTING))
    assert bound < WATCHDOG / 2
    for a in UP:
        times = [start] + [t for t, d in w.sent if _data_exchange_to(d) == a]
        gaps = [b - t for t, b in itertools.pairwise(times)]
        assert max(gaps) <= bound, (a, max(gaps), bound)
    # and the others, once up, too (each from its first Data_Exchange on)
    for a in STARTING:
        times = [t for t, d in w.sent if _data_exchange_to(d) == a]
        gaps = [b - t for t, b in itertools.pairwise(times)]
        assert gaps and max(gaps) <= bound, (a, max(gaps), bound)
    assert w.master.figures.low_deferred > 0  # the budget did hold bring-up back
    assert up_at - start < 5.0
    assert {x.address for x in w.of(InputsReceived)} == set(UP + STARTING)


def test_slaves_without_a_watchdog_leave_bring_up_unbudgeted() -> None:
    """No watchdog to protect: every slave's bring-up goes on in the same cycle."""
    configured = list(range(3, 23))
    master = Master(FAST_BUS, [echo_params(a, watchdog=None) for a in configured])
    w = Wire(master, echo_line(configured))
    w.write_lag = LAG
    assert w.run_until(lambda: _in(w, configured), 5.0)
    assert w.master.figures.low_deferred == 0
    assert w.master.figures.cycles <= 3  # all of them started in the first cycle


def test_dpv1_jobs_wait_for_the_budget_but_none_expires_and_bring_up_goes_on() -> None:
    """Thirty slaves in data exchange take more than the budget's share of the watchdog
    (the floor's share is left for low-priority work); a DP-V1 read queued to each at once
    while five more slaves start up: every read completes within its deadline, the bring-up
    completes, and no slave in data exchange drops out."""
    up = list(range(3, 33))
    later = list(range(33, 38))
    watchdog = 0.2
    master = Master(FAST_BUS, [echo_params(a, watchdog=watchdog) for a in up + later])
    w = Wire(master, echo_line(up))
    w.write_lag = LAG
    assert w.run_until(lambda: _in(w, up) and _in(w, later, SlaveState.ABSENT), 5.0)
    w.master.write_record(up[0], 0, 1, b"\x12\x34", w.now)  # (a first job: the turn's time)
    assert w.run_until(lambda: bool(w.of(RecordDone)), 1.0)
    w.clear()
    for a in later:
        w.line.add(DpSlave(a, EchoSim(4)))
    jobs = {w.master.read_record(a, 0, 1, 240, w.now): a for a in up}
    w.poke()
    assert w.run_until(lambda: len(w.of(RecordDone)) == len(jobs) and _in(w, up + later), 5.0)
    assert all(d.failure is None and d.error is None for d in w.of(RecordDone))
    assert {d.job for d in w.of(RecordDone)} == set(jobs)
    assert w.of(SlaveDown) == []
    assert w.master.figures.low_deferred > 0


def test_a_dpv1_request_that_would_expire_before_the_next_turn_is_not_held() -> None:
    """Thirty reads queued at once with a deadline of a few cycles: the budget holds most
    of them at first, and each goes once its deadline could pass before the next turn of
    its slave (held by the budget all along, three expire unasked)."""
    up = list(range(3, 33))
    bus = dataclasses.replace(FAST_BUS, acyclic_timeout=0.4)
    master = Master(bus, [echo_params(a, watchdog=0.2) for a in up])
    w = Wire(master, echo_line(up))
    w.write_lag = LAG
    assert w.run_until(lambda: _in(w, up), 5.0)
    w.run(0.5)
    w.clear()
    jobs = {w.master.read_record(a, 0, 1, 240, w.now): a for a in up}
    w.poke()
    assert w.run_until(lambda: len(w.of(RecordDone)) == len(jobs), 2.0)
    assert [d for d in w.of(RecordDone) if d.failure is not None] == []
    assert w.master.figures.low_deferred > 0
    assert w.of(SlaveDown) == []
