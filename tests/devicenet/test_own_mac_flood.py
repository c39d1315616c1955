"""A flood of Duplicate MAC ID requests for the scanner's own MAC (adapters/devicenet/scanner/
ownmac.py): at most one answer per ANSWER_EVERY, the rest counted, one report per
REPORT_EVERY with the count; a genuine claimant is still kept off the scanner's MAC. The
scanner and simulated CFW-08s on the ideal bus of tests/devicenet/harness.py, stepped on a
fake clock."""

from __future__ import annotations

import itertools

from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.scanner import FrameIn, NodeDown, Report, ReportKind
from adapters.devicenet.scanner.ownmac import ANSWER_EVERY, REPORT_EVERY, OwnMacDefence
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig, SimPhase
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import line

FORGED = CanFrame(0x407, bytes.fromhex("00 55 03 01 00 00 00"))  # a request for MAC 0


def flood(lin: Line, seconds: float, every: float = 0.001) -> int:
    """Forged requests for MAC 0 to the scanner, one per ``every``; its answers go on the
    line. How many were sent."""
    count = round(seconds / every)
    for _ in range(count):
        lin._scanner_actions(lin.scanner.step(lin.now, FrameIn(FORGED)))
        lin.run(every)
    return count


def answers(lin: Line) -> list[float]:
    return [
        t
        for t, who, frame in lin.frames
        if who == "scanner" and frame.arbitration_id == 0x407 and frame.data[0] & 0x80
    ]


def figure(report: Report, name: str) -> int:
    value = report.data[name]
    assert isinstance(value, int)
    return value


def claim_reports(lin: Line) -> list[Report]:
    return [r for r in lin.take(Report) if r.kind is ReportKind.DUPLICATE_MAC]


def test_a_flood_gets_one_answer_per_interval_and_one_report_per_period() -> None:
    lin = line(5)
    lin.run(0.3)
    seconds = 25.0
    sent = flood(lin, seconds, every=0.002)
    times = answers(lin)
    assert 1 <= len(times) <= seconds / ANSWER_EVERY + 1
    assert all(b - a >= ANSWER_EVERY - 1e-9 for a, b in itertools.pairwise(times))
    diag = lin.scanner.line_diagnostics()
    assert diag["own_mac_claims"] == sent
    assert diag["own_mac_claims_unanswered"] == sent - len(times)
    reports = claim_reports(lin)
    assert len(reports) <= 1 + seconds / REPORT_EVERY + 1
    assert reports[0].text.endswith("tried to claim the scanner's MAC ID 0")  # at once
    assert "answered" in reports[1].text and figure(reports[1], "unanswered") > 0
    lin.run(REPORT_EVERY)  # the flood is over: the rest is reported once
    reports += claim_reports(lin)
    assert sum(figure(r, "claims") for r in reports) == sent
    assert sum(figure(r, "answered") for r in reports) == len(times)
    lin.run(REPORT_EVERY)
    assert not claim_reports(lin)  # nothing left to tell
    assert not lin.take(NodeDown)  # the drive was polled throughout
    assert lin.scanner.online_macs() == [5]


def test_a_genuine_claimant_is_kept_off_the_scanners_mac_during_a_flood() -> None:
    """Its two requests, 1 s apart (fact sheet 2.3), meet at least one answer."""
    lin = line(5)
    lin.run(0.3)
    claimant = Cfw08Node(SimNodeConfig(0, dupmac_timeout=1.0, serial_number=77))
    lin.sims[0] = claimant
    flood(lin, 0.3)
    lin.power_on(claimant)
    flood(lin, 3.0)
    assert claimant.phase is SimPhase.MAC_FAULT


def test_the_defence_alone() -> None:
    defence = OwnMacDefence(0)
    one, two = FORGED.data, bytes.fromhex("00 55 03 02 00 00 00")
    assert defence.claim(0.0, one) == (True, True)  # answered, reported at once
    report = defence.report(0.0, "vendor 0x0355 serial 1")
    assert report.data == {"claims": 1, "answered": 1, "unanswered": 0}
    assert report.text == "a device (vendor 0x0355 serial 1) tried to claim the scanner's MAC ID 0"
    assert defence.claim(0.1, one) == (False, False)
    assert defence.due_at == REPORT_EVERY
    assert defence.claim(ANSWER_EVERY, two) == (True, False)
    assert defence.last == two  # the claimant the next report names
    report = defence.report(REPORT_EVERY, "vendor 0x0355 serial 2")
    assert report.data == {"claims": 2, "answered": 1, "unanswered": 1}
    assert "serial 2" in report.text and "2 time(s)" in report.text and "1 not" in report.text
    assert defence.due_at is None
    assert (defence.claims, defence.unanswered) == (3, 1)


def test_only_a_well_formed_request_is_a_claim() -> None:
    lin = line(5)
    lin.run(0.3)
    lin.scanner.step(lin.now, FrameIn(FORGED))
    before = lin.scanner.line_diagnostics()["errors"]
    # a malformed request for the scanner's MAC is a bad frame, a response nothing
    lin.scanner.step(lin.now, FrameIn(CanFrame(0x407, bytes(3))))
    lin.scanner.step(lin.now, FrameIn(CanFrame(0x407, bytes.fromhex("80 55 03 01 00 00 00"))))
    assert lin.scanner.line_diagnostics()["own_mac_claims"] == 1
    assert lin.scanner.line_diagnostics()["errors"] == before + 1
