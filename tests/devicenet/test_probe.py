"""The line probe of ``devicenet scan``, sans-IO: golden frames, timeouts, refusal."""

from __future__ import annotations

from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.scanner.probe import Finished, LineProbe, ProbeConfig, Progress, Refused


def test_check_then_allocate_then_absent() -> None:
    probe = LineProbe(ProbeConfig(mac=0, macs=(5,), timeout=0.2, dupmac_timeout=1.0))
    first = probe.step(0.0)
    # Duplicate MAC ID check request of MAC 0 on G2 message 7 (fact sheet 2.3)
    assert first == [CanFrame(0x407, bytes.fromhex("00 ff ff 00 53 47 44"))]
    assert probe.next_deadline() == 1.0
    assert probe.step(1.0) == first
    assert probe.step(1.5) == []
    # Allocate (4Bh) explicit (choice 01h) by MAC 0 on MAC 5's unconnected port, G2 msg 6
    assert probe.step(2.0) == [CanFrame(0x42E, bytes.fromhex("40 4b 03 01 01 00"))]
    assert probe.next_deadline() == 2.2
    assert probe.step(2.2) == [Progress(1, 1, 5, None), Finished(())]
    assert probe.finished and probe.next_deadline() is None


def test_an_answered_check_refuses_the_scan() -> None:
    probe = LineProbe(ProbeConfig(mac=0, macs=(5,)))
    probe.step(0.0)
    answer = DupMacCheck(0, DupMacKind.RESPONSE, 0, 0xFFFF, 0x44470000).to_frame()
    (refused,) = probe.step(0.1, answer)
    assert isinstance(refused, Refused) and "MAC ID 0 is taken on the line" in refused.text
    assert probe.step(5.0) == [] and probe.next_deadline() is None


def test_another_macs_check_is_not_a_refusal() -> None:
    probe = LineProbe(ProbeConfig(mac=0, macs=(5,)))
    probe.step(0.0)
    other = DupMacCheck(9, DupMacKind.REQUEST, 0, 0x355, 1).to_frame()
    assert probe.step(0.1, other) == []
    assert probe.refused is None
