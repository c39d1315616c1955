"""The scanner's receive hold (:meth:`Scanner.hold_until`, the driver's
:meth:`~adapters.link.candriver.CanProtocol.hold_until`): on a steady line only, until the
first half of the poll window can have been answered at the line's bit rate, at most
``HOLD_MAX``; None in every other state. And a steady line whose poll responses are held
as the driver holds them still polls every node in every cycle."""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import pytest

from adapters.can.bits import frame_bits_min
from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.explicit import GetAttributeSingle
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import match_predefined
from adapters.devicenet.codec.objects import IdentityAttribute
from adapters.devicenet.scanner import BusErrorIn, FrameIn, TxFailed
from adapters.devicenet.scanner.node import Phase
from adapters.devicenet.scanner.scheduler import HOLD_MAX
from adapters.link.canerror import LineCondition
from tests.devicenet.harness import Line
from tests.devicenet.test_scanner import FAST, node, sim

BITRATE = 500_000
HELD = replace(FAST, bitrate=BITRATE)
MACS = tuple(range(1, 21))  # 20 nodes: more than two poll windows a cycle
OUTPUT = bytes(4)  # the CFW-08's 4-byte output (assembly 21)


def steady(config: object = HELD, macs: tuple[int, ...] = MACS) -> Line:
    lin = Line(config, [node(m) for m in macs], [sim(m) for m in macs])  # type: ignore[arg-type]
    lin.outputs = dict.fromkeys(macs, OUTPUT)
    lin.power_on()
    lin.run(1.0)
    assert all(n.phase is Phase.ONLINE for n in lin.scanner.nodes.values())
    return lin


def start_cycle(lin: Line) -> None:
    """Step the scanner at its next poll cycle, the polls sent but not answered yet."""
    scanner = lin.scanner
    assert scanner.schedule.cycle_started is None
    lin.now = max(lin.now, scanner.schedule.cycle_due)
    scanner.step(lin.now)
    assert len(scanner.schedule.in_flight) == scanner.config.poll_window


def test_frame_bits_min_golden() -> None:
    # ISO 11898-1 data frame, 11-bit identifier, no stuff bit: 44 + 8n, and 3 bits of
    # intermission; 111 bits for 8 bytes (fact sheet 2.13's lower figure)
    assert [frame_bits_min(n) for n in (0, 4, 8)] == [47, 79, 111]
    assert frame_bits_min(20) == 111  # a fragmented message: its first frame


def test_a_steady_line_holds_until_half_the_window_can_be_answered() -> None:
    lin = steady()
    start_cycle(lin)
    scanner = lin.scanner
    half = (scanner.config.poll_window + 1) // 2
    bits = half * (frame_bits_min(len(OUTPUT)) + frame_bits_min(4))  # 4 bytes back (71)
    answers = (half - 1) * frame_bits_min(4) / BITRATE  # all but one response, after now
    sends = bits / BITRATE  # 4 x 158 bits: 1.264 ms
    at = scanner.hold_until(lin.now)
    assert at == pytest.approx(lin.now + max(sends, answers))
    assert at is not None and lin.now < at < lin.now + HOLD_MAX
    # a later pass with none of them answered yet: their responses are still to come
    assert scanner.hold_until(at) == pytest.approx(at + answers)
    # from the sends, when that is later
    assert scanner.hold_until(lin.now + 0.0001) == pytest.approx(at)  # from the sends
    # the cycle's last polls in flight, none left to send: no hold (the cycle's end and
    # the next cycle's start wait on their responses)
    queue, scanner.schedule.poll_queue = scanner.schedule.poll_queue, deque()
    assert queue and scanner.hold_until(lin.now) is None


def test_the_hold_is_capped() -> None:
    lin = steady(replace(FAST, bitrate=10_000))  # 4 polls: 63 ms at 10 kbit/s
    start_cycle(lin)
    assert lin.scanner.hold_until(lin.now) == pytest.approx(lin.now + HOLD_MAX)


def test_no_hold_without_polls_in_flight_or_a_bit_rate() -> None:
    lin = steady()
    assert lin.scanner.schedule.cycle_started is None
    assert lin.scanner.hold_until(lin.now) is None  # between cycles: the next is a deadline
    lin = steady(FAST)  # bit rate unknown
    start_cycle(lin)
    assert lin.scanner.hold_until(lin.now) is None


def test_no_hold_with_an_explicit_request_queued_or_in_flight() -> None:
    lin = steady()
    scanner = lin.scanner
    get = GetAttributeSingle(CipClass.IDENTITY, 1, IdentityAttribute.STATUS)
    scanner.submit(3, get)  # queued
    start_cycle(lin)
    assert scanner.hold_until(lin.now) is None
    assert scanner.schedule.explicit_busy == {3}  # the cycle's step sent it: in flight
    assert scanner.nodes[3].current is not None
    assert scanner.hold_until(lin.now) is None
    lin.run(0.05)  # answered
    assert not scanner.schedule.explicit_busy
    start_cycle(lin)
    assert scanner.hold_until(lin.now) is not None


def test_no_hold_while_a_node_is_lost_and_brought_up_again() -> None:
    lin = HeldLine(HELD, [node(m) for m in MACS], [sim(m) for m in MACS])
    lin.outputs = dict.fromkeys(MACS, OUTPUT)
    lin.power_on()
    lin.run(1.0)
    scanner = lin.scanner
    assert scanner.schedule.online == len(MACS)
    lin.sims[5].power_off()
    lost = False
    for _ in range(2000):  # inactivity: offline at 4 x EPR
        lin.run(0.0005)
        if scanner.nodes[5].phase is not Phase.ONLINE:
            lost = True
            if scanner.schedule.in_flight:
                break
    assert lost and scanner.schedule.in_flight
    assert scanner.hold_until(lin.now) is None  # a node lost
    lin.power_on(lin.sims[5])
    bringup = False
    for _ in range(4000):
        lin.run(0.0005)
        if scanner.schedule.in_bringup:
            bringup = True
            assert scanner.hold_until(lin.now) is None
        if scanner.nodes[5].phase is Phase.ONLINE:
            break
    assert bringup and scanner.nodes[5].phase is Phase.ONLINE
    holds = lin.holds
    lin.run(0.2)
    assert lin.holds > holds  # steady again: held again


def test_no_hold_when_leaving_the_line() -> None:
    lin = steady()
    start_cycle(lin)
    lin.scanner.leave(lin.now)
    assert lin.scanner.hold_until(lin.now) is None


def test_no_hold_on_an_unhealthy_line_or_in_a_send_hold() -> None:
    lin = steady()
    scanner = lin.scanner
    start_cycle(lin)
    scanner.step(lin.now, BusErrorIn(frozenset({LineCondition.ERROR_WARNING})))
    assert scanner.hold_until(lin.now) is None
    scanner.step(lin.now, BusErrorIn(frozenset({LineCondition.ERROR_ACTIVE})))
    assert scanner.hold_until(lin.now) is not None
    scanner.step(lin.now, TxFailed("Transmit buffer full", dropped=1))
    assert scanner.hold_until(lin.now) is None


class HeldLine(Line):
    """The harness on a bus with bit times, and the driver's receive hold.

    Every frame takes its :func:`frame_bits_min` bit times on the one bus, after the
    frames before it (no arbitration: first sent, first carried). After each pass the
    scanner is asked for a hold; the frames the scanner receives during it are kept, and
    stepped at its end (or at the scanner's deadline, if sooner), all at that time, after
    the outputs are set, as :class:`~adapters.link.candriver.CanDriver` steps them."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.bitrate = self.scanner.config.bitrate
        self.wire: deque[tuple[float, object, CanFrame]] = deque()
        self.bus_free = 0.0
        self.hold_end: float | None = None
        self.kept: list[FrameIn[CanFrame]] = []
        self.holds = 0
        self.held_frames = 0

    def _ask_hold(self) -> None:
        if self.hold_end is not None or not self.scanner_enabled:
            return
        at = self.scanner.hold_until(self.now)
        if at is not None:
            deadline = self.scanner.next_deadline()
            self.hold_end = at if deadline is None else min(at, deadline)
            self.holds += 1

    def _flush(self) -> None:
        while True:
            while self._pending:  # onto the wire, one after the other
                sender, frame = self._pending.popleft()
                start = max(self.now, self.bus_free)
                self.bus_free = start + frame_bits_min(len(frame.data)) / self.bitrate
                self.wire.append((self.bus_free, sender, frame))
            if not self.wire or self.wire[0][0] > self.now:
                break
            _, sender, frame = self.wire.popleft()
            self.frames.append((self.now, "scanner" if sender is self.scanner else "node", frame))
            if sender is not self.scanner and self.scanner_enabled:
                if self.hold_end is not None and self.now < self.hold_end:
                    self.kept.append(FrameIn(frame))
                    self.held_frames += 1
                else:
                    self._scanner_actions(self.scanner.step(self.now, FrameIn(frame)))
            to = _to(frame)
            for station in self.stations:
                if station is not sender and to == station.mac:
                    for out in station.step(self.now, frame):
                        self._pending.append((station, out))
        self._ask_hold()

    def _deadlines(self) -> list[float]:
        times = super()._deadlines()
        if self.hold_end is not None:
            times.append(self.hold_end)
        if self.wire:
            times.append(self.wire[0][0])
        return times

    def _step_due(self) -> None:
        if self.hold_end is not None:
            if self.now < self.hold_end:  # held: only the nodes' timers
                for station in self.stations:
                    deadline = station.next_deadline()
                    if deadline is not None and deadline <= self.now:
                        for out in station.step(self.now):
                            self._pending.append((station, out))
                return
            self.hold_end = None
            kept, self.kept = self.kept, []
            for mac, data in self.outputs.items():  # before_step: the hub's outputs
                if mac in self.scanner.nodes:
                    self.scanner.set_output(mac, data)
            for event in kept:
                self._scanner_actions(self.scanner.step(self.now, event))
        if self.scanner_enabled:
            deadline = self.scanner.next_deadline()
            if deadline is not None and deadline > self.now:
                self.scanner_enabled = False  # not due: the nodes' timers only
                try:
                    super()._step_due()
                finally:
                    self.scanner_enabled = True
                return
        super()._step_due()


def _to(frame: CanFrame) -> int | None:
    found = match_predefined(frame.arbitration_id)
    return None if found is None else found.mac


@pytest.mark.parametrize("macs", [MACS, tuple(range(1, 64))])
def test_a_held_steady_line_polls_every_node_every_cycle(macs: tuple[int, ...]) -> None:
    config = replace(HELD, poll_interval=0.001)  # cycles back to back, as in the plant
    lin = HeldLine(config, [node(m) for m in macs], [sim(m) for m in macs])
    lin.outputs = dict.fromkeys(macs, OUTPUT)
    lin.power_on()
    lin.run(1.5)
    scanner = lin.scanner
    assert all(n.phase is Phase.ONLINE for n in scanner.nodes.values())
    holds, cycles = lin.holds, scanner.line.cycles
    before = {m: n.figures.rtt_count for m, n in scanner.nodes.items()}
    inputs = {m: len(lin.inputs(m)) for m in macs}
    lin.run(0.5)
    done = scanner.line.cycles - cycles
    assert lin.holds - holds >= done > 10  # held, and cycling
    for mac, n in scanner.nodes.items():
        # one poll answered a cycle (give or take the cycle under way at each end)
        assert abs(n.figures.rtt_count - before[mac] - done) <= 1, mac
        assert len(lin.inputs(mac)) - inputs[mac] >= done - 1, mac
        assert n.figures.poll_timeouts == 0, mac
    assert not lin.late_deadlines
    assert lin.held_frames > lin.holds  # a hold takes more than one response a pass


def test_the_adapter_line_asks_its_scanner() -> None:
    from adapters.can.adapter import AdapterLine as _Line

    lin = steady()
    start_cycle(lin)

    class Adapter:
        engine: object = lin.scanner

    line: _Line[CanFrame, object, object] = _Line(Adapter())  # type: ignore[arg-type]
    assert line.hold_until(lin.now) == lin.scanner.hold_until(lin.now) is not None
    Adapter.engine = None  # not running
    assert line.hold_until(lin.now) is None
