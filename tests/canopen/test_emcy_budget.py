"""Each node's EMCY budget in the master engine (adapters/canopen/master/emcy.py): frames over
it are counted and not decoded, a new error code is taken when the budget allows, the drops
are reported once per period with their count, and the fault state still comes from the
statusword. The engine and a fake node on an ideal bus, stepped on a fake clock."""

from __future__ import annotations

import pytest

from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import State
from adapters.canopen.master import EmcyIn, FaultInfo, Report
from adapters.canopen.master.emcy import EMCY_BURST, EMCY_RATE, EMCY_REPORT_EVERY, EmcyBudget
from tests.canopen.test_master import up

FORGED = f.encode_emcy(5, f.Emcy(0x8110, 0x11))  # CAN overrun


def emcys(line: object) -> list[EmcyIn]:
    return [a for a in line.of(EmcyIn) if isinstance(a, EmcyIn)]  # type: ignore[attr-defined]


def drop_reports(line: object) -> list[str]:
    return [
        a.text
        for a in line.of(Report)  # type: ignore[attr-defined]
        if isinstance(a, Report) and "over its budget" in a.text
    ]


def test_a_flood_at_one_instant_gives_the_burst_and_counts_the_rest() -> None:
    line, _node = up()
    for _ in range(2000):
        line.inject(FORGED)
    assert len(emcys(line)) == EMCY_BURST
    assert line.master.figures["emcy_dropped"] == 2000 - EMCY_BURST
    diag = line.master.node_diagnostics(5)
    assert diag["emcy_rx"] == EMCY_BURST and diag["emcy_dropped"] == 2000 - EMCY_BURST
    assert line.master.online(5)


def test_a_flood_that_goes_on_is_taken_at_the_rate_and_reported_once_per_period() -> None:
    line, _node = up()
    start = line.now
    seconds = 30
    for _ in range(seconds * 200):  # 200 a second, the line stepped between them
        line.inject(FORGED)
        line.run(0.005)
    taken = len(emcys(line))
    assert taken <= EMCY_BURST + EMCY_RATE * (line.now - start) + 1
    assert taken >= EMCY_RATE * seconds * 0.9
    reports = drop_reports(line)
    assert len(reports) <= 1 + seconds / EMCY_REPORT_EVERY + 1
    line.run(EMCY_REPORT_EVERY)  # the flood stopped: what it left unsaid is reported
    reports = drop_reports(line)
    counted = sum(int(text.split(": ", 1)[1].split()[0]) for text in reports)
    assert counted == line.master.figures["emcy_dropped"] == seconds * 200 - taken
    assert reports[0].startswith("node 5: 1 EMCY frame(s) over its budget")  # at once
    assert line.master.online(5)


def test_a_new_error_code_is_taken_when_the_budget_allows() -> None:
    line, _node = up()
    for _ in range(100):
        line.inject(FORGED)
    line.run(1.0 / EMCY_RATE)  # one frame's worth of budget back
    line.inject(f.encode_emcy(5, f.Emcy(0x4310, 0x09)))
    assert emcys(line)[-1].emcy.error_code == 0x4310


def test_the_fault_state_comes_from_the_statusword_when_its_emcy_was_dropped() -> None:
    line, node = up()
    for _ in range(100):
        line.inject(FORGED)
    node.state = State.FAULT  # the genuine EMCY goes over the budget
    node.od[(0x603F, 0)] = (0x2310).to_bytes(2, "little")
    node.od[(0x1001, 0)] = b"\x03"
    line.inject(f.encode_emcy(5, f.Emcy(0x2310, 0x03)))
    assert all(e.emcy.error_code == 0x8110 for e in emcys(line))
    line.run(0.2)
    info = [a for a in line.of(FaultInfo) if isinstance(a, FaultInfo)]
    assert info and info[0].reads[(0x603F, 0)] == b"\x10\x23"  # the code read from the drive


def test_a_bad_emcy_over_the_budget_is_not_decoded_either() -> None:
    line, _node = up()
    for _ in range(50):
        line.inject(f.CanFrame(f.emcy_id(5), b"\x01\x02\x03"))
    bad = [a for a in line.of(Report) if isinstance(a, Report) and "bad EMCY" in a.text]
    assert len(bad) == EMCY_BURST
    assert line.master.figures["bad_frames"] == EMCY_BURST


def test_the_budget_is_a_token_bucket() -> None:
    budget = EmcyBudget(rate=2.0, burst=3)
    assert [budget.take(0.0) for _ in range(4)] == [True, True, True, False]
    assert not budget.take(0.4)  # half a token back
    assert budget.take(0.5) and not budget.take(0.5)
    assert [budget.take(10.0) for _ in range(4)] == [True, True, True, False]  # full again
    assert budget.dropped == 4
    with pytest.raises(ValueError):
        EmcyBudget(rate=0.0)
