"""The CAN driver loop on a scripted link: what it steps, sends and tells the adapter."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from adapters.link.can import CanEvent, RxFrame, SendResult
from adapters.link.candriver import IDLE_WAIT, CanDriver, CanProtocol


@dataclass(frozen=True)
class Frame:
    arbitration_id: int
    data: bytes = b""


@dataclass
class Link:
    """Hands out scripted receive results; records the waits asked for and the sends."""

    script: list[list[CanEvent[Frame]]]
    fail: SendResult | None = None
    waits: list[float] = field(default_factory=list)
    holds: list[bool] = field(default_factory=list)
    sent: list[list[Any]] = field(default_factory=list)

    async def receive(self, wait: float, hold: bool = False) -> list[CanEvent[Frame]]:
        self.waits.append(wait)
        self.holds.append(hold)
        if not self.script:
            raise asyncio.CancelledError
        return self.script.pop(0)

    def send(self, frames: Sequence[Any]) -> SendResult:
        self.sent.append(list(frames))
        return self.fail or SendResult(len(frames))


class Engine:
    def __init__(self, deadline: float | None) -> None:
        self.deadline = deadline
        self.steps: list[tuple[float, Any]] = []

    def step(self, now: float, event: Any = None) -> list[Any]:
        self.steps.append((now, event))
        if isinstance(event, RxFrame):
            return [Frame(0x100 + event.frame.arbitration_id), f"got {event.frame.arbitration_id}"]
        return [Frame(0x1)] if event is None else []

    def next_deadline(self) -> float | None:
        return self.deadline


class Line(CanProtocol[Frame, Any, Any]):
    """Only the required hooks: the optional ones keep their defaults."""

    def __init__(self) -> None:
        self.handled: list[Any] = []

    def event(self, received: CanEvent[Frame]) -> Any:
        return received

    def frame(self, action: Any) -> Frame | None:
        return action if isinstance(action, Frame) else None

    def handle(self, now: float, action: Any) -> None:
        self.handled.append((now, action))

    def send_failed(self, result: SendResult) -> list[Any]:
        return [("failed", result.dropped)]


def driver(engine: Engine, link: Link, line: Line, now: float = 10.0) -> CanDriver[Any, Any, Any]:
    return CanDriver(engine, cast(Any, link), line, clock=lambda: now)


async def test_a_pass_steps_what_is_due_sends_it_and_steps_what_arrives() -> None:
    engine, line = Engine(deadline=9.0), Line()
    link = Link([[RxFrame(Frame(7))]])
    with pytest.raises(asyncio.CancelledError):
        await driver(engine, link, line).run()
    assert engine.steps[:3] == [(10.0, None), (10.0, RxFrame(Frame(7))), (10.0, None)]
    # the frame is stepped in the next pass, before the engine's own step: one batch
    assert link.sent[:2] == [[Frame(0x1)], [Frame(0x107), Frame(0x1)]]
    assert line.handled[0] == (10.0, "got 7")


async def test_without_a_deadline_it_waits_the_idle_bound_and_steps_anyway() -> None:
    engine, link = Engine(deadline=None), Link([[]])
    with pytest.raises(asyncio.CancelledError):
        await driver(engine, link, Line()).run()
    assert link.waits[0] == IDLE_WAIT and engine.steps[0] == (10.0, None)


async def test_a_deadline_not_due_is_waited_for_not_stepped() -> None:
    engine, link = Engine(deadline=10.25), Link([])
    with pytest.raises(asyncio.CancelledError):
        await driver(engine, link, Line()).run()
    assert engine.steps == [] and link.waits == [0.25]


def test_a_failed_send_goes_back_to_the_engine() -> None:
    engine, line = Engine(deadline=None), Line()
    link = Link([], fail=SendResult(0, 2, "Transmit buffer full"))
    d = driver(engine, link, line)
    d.act(1.0, [Frame(1), Frame(2)])
    d.flush(1.0)
    assert engine.steps == [(1.0, ("failed", 2))]
    d.flush(1.0)  # the frames dropped are not sent again
    assert len(link.sent) == 1


def test_frames_queued_from_elsewhere_go_with_the_next_batch_and_discard_forgets() -> None:
    link = Link([])
    d = driver(Engine(deadline=None), link, Line())
    d.queue(Frame(0x3F))
    d.act(1.0, [Frame(0x40)])
    d.flush(1.0)
    assert link.sent == [[Frame(0x3F), Frame(0x40)]]
    d.queue(Frame(0x41))
    d.discard()
    d.flush(1.0)
    assert len(link.sent) == 1


class Hooked(Line):
    """The optional hooks, recorded in the order the driver calls them."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[str] = []

    def before_step(self, now: float) -> None:
        self.calls.append("before")

    def after_step(self, now: float) -> None:
        self.calls.append("after")

    def wake_at(self) -> float | None:
        self.calls.append("wake")
        return 10.125

    def received(self, now: float, event: CanEvent[Frame]) -> None:
        self.calls.append(f"received {event}")


async def test_the_adapters_hooks_come_around_the_step_and_its_wake_time_counts() -> None:
    engine, line = Engine(deadline=11.0), Hooked()
    link = Link([[RxFrame(Frame(2))]])
    with pytest.raises(asyncio.CancelledError):
        await driver(engine, link, line).run()
    assert line.calls[:5] == ["before", "after", "wake", "before", f"received {RxFrame(Frame(2))}"]
    assert link.waits[0] == 0.125  # the adapter's time, before the engine's
    assert engine.steps == [(10.0, RxFrame(Frame(2)))]  # its deadline had not come


class Counting(Engine):
    def __init__(self, deadline: float | None) -> None:
        super().__init__(deadline)
        self.asked = 0

    def next_deadline(self) -> float | None:
        self.asked += 1
        return self.deadline


async def test_a_pass_asks_each_time_once_and_reads_the_clock_only_when_it_needs_it() -> None:
    """The pass is cheap: the engine's deadline once before its step and once after, the
    adapter's wake time once, no list; an idle pass (no deadline, nothing received,
    nothing queued) reads the clock once, a pass with a deadline once more for the wait,
    and one that received something once more to step it."""
    reads = 0

    def clock() -> float:
        nonlocal reads
        reads += 1
        return 10.0

    engine, line = Counting(deadline=None), Hooked()
    line.wake_at = lambda: None  # type: ignore[method-assign]
    link = Link([[], []])
    with pytest.raises(asyncio.CancelledError):
        await CanDriver(engine, cast(Any, link), line, clock=clock).run()
    passes = 3  # two whole, the third ends in the receive that is cancelled
    assert engine.asked == 2 * passes and reads == passes
    assert link.waits == [IDLE_WAIT] * passes

    reads = 0
    engine = Counting(deadline=10.5)
    link = Link([[RxFrame(Frame(1))]])
    with pytest.raises(asyncio.CancelledError):
        await CanDriver(engine, cast(Any, link), Line(), clock=clock).run()
    # pass 1: now, the wait; pass 2: now (the frame's step and the engine's), the wait
    assert reads == 4 and engine.asked == 4
    assert link.waits == [0.5, 0.5]


class Holding(Hooked):
    """A protocol that holds received frames until ``until`` (None: no hold)."""

    def __init__(self, until: float | None, wake: float | None = None) -> None:
        super().__init__()
        self.until, self.wake = until, wake
        self.asked_hold: list[float] = []

    def wake_at(self) -> float | None:
        wake, self.wake = self.wake, None  # once
        return wake

    def hold_until(self, now: float) -> float | None:
        self.asked_hold.append(now)
        return self.until


class Ticking(Engine):
    """An engine whose deadline moves on by ``period`` at each timer step."""

    def __init__(self, deadline: float | None, period: float = 1.0) -> None:
        super().__init__(deadline)
        self.period = period

    def step(self, now: float, event: Any = None) -> list[Any]:
        if event is None and self.deadline is not None and now >= self.deadline:
            self.deadline += self.period
        return super().step(now, event)


class Clock:
    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


@dataclass
class TimedLink:
    """A link on an injected clock: frames arrive at given times; a held wait is not
    ended by them (only by its time or a wake), an unheld one ends at the first."""

    clock: Clock
    arrivals: list[tuple[float, Frame]]
    wakes: list[float] = field(default_factory=list)  # times wake() is called
    sent: list[tuple[float, list[Any]]] = field(default_factory=list)
    received_at: list[tuple[float, list[int]]] = field(default_factory=list)
    calls: list[tuple[float, bool]] = field(default_factory=list)
    end: float = 2.0

    async def receive(self, wait: float, hold: bool = False) -> list[CanEvent[Frame]]:
        now = self.clock.now
        self.calls.append((wait, hold))
        until = now + wait
        woken = [t for t in self.wakes if now <= t <= until]
        if woken:
            until = woken[0]
            self.wakes.remove(until)
        elif not hold:
            first = [t for t, _ in self.arrivals if t <= until]
            if first:
                until = max(now, first[0])
        if until >= self.end:
            raise asyncio.CancelledError
        self.clock.now = until
        got = [f for t, f in self.arrivals if t <= until]
        self.arrivals = [(t, f) for t, f in self.arrivals if t > until]
        self.received_at.append((until, [f.arbitration_id for f in got]))
        return [RxFrame(f) for f in got]

    def send(self, frames: Sequence[Any]) -> SendResult:
        self.sent.append((self.clock.now, list(frames)))
        return SendResult(len(frames))


async def run_timed(
    engine: Engine, link: TimedLink, line: Line, clock: Clock
) -> CanDriver[Any, Any, Any]:
    d = CanDriver(engine, cast(Any, link), line, clock=clock)
    with pytest.raises(asyncio.CancelledError):
        await d.run()
    return d


async def test_frames_arriving_during_a_hold_are_stepped_after_it_at_the_drain_time() -> None:
    clock = Clock(1.0)
    engine = Ticking(deadline=1.5)
    line = Holding(until=1.25)
    link = TimedLink(clock, [(1.01, Frame(1)), (1.02, Frame(2)), (1.10, Frame(3))], end=1.4)
    await run_timed(engine, link, line, clock)
    assert link.calls[0] == (0.25, True)  # held, until the hold's end (before the deadline)
    # one wake-up for the three frames, at the hold's end; all three stepped then
    assert link.received_at[0] == (1.25, [1, 2, 3])
    assert [(t, e.frame.arbitration_id) for t, e in engine.steps if e is not None] == [
        (1.25, 1),
        (1.25, 2),
        (1.25, 3),
    ]
    # the drained frames come after the adapter's before_step, each shown to it after its step
    received = [f"received {RxFrame(Frame(i))}" for i in (1, 2, 3)]
    assert line.calls[:7] == ["before", "after", "before", *received, "after"]


async def test_a_hold_never_puts_off_the_engines_deadline_nor_the_adapters() -> None:
    clock = Clock(1.0)
    engine = Ticking(deadline=1.1)
    link = TimedLink(clock, [(1.01, Frame(1))], end=1.2)
    await run_timed(engine, link, Holding(until=1.5), clock)
    wait, hold = link.calls[0]
    assert wait == pytest.approx(0.1) and hold  # the engine's deadline first
    at, got = link.received_at[0]
    assert at == pytest.approx(1.1) and got == [1]
    clock = Clock(1.0)
    link = TimedLink(clock, [(1.01, Frame(1))], end=1.2)
    await run_timed(Ticking(deadline=None), link, Holding(until=1.5, wake=1.05), clock)
    wait, hold = link.calls[0]
    assert wait == pytest.approx(0.05) and hold  # the adapter's wake time first


async def test_a_wake_during_a_hold_still_sends_at_once() -> None:
    clock = Clock(1.0)
    engine = Ticking(deadline=1.5)
    line = Holding(until=1.25)
    link = TimedLink(clock, [(1.01, Frame(1))], wakes=[1.05], end=1.2)
    d = CanDriver(engine, cast(Any, link), line, clock=clock)

    async def run() -> None:
        await d.run()

    d.queue(Frame(0x3F))  # queued from elsewhere (a second engine): it woke the link
    with pytest.raises(asyncio.CancelledError):
        await run()
    # the first pass sends it; a frame queued during the hold goes at the wake
    assert link.sent[0] == (1.0, [Frame(0x3F)])
    assert link.received_at[0] == (1.05, [1])


async def test_a_frame_queued_during_a_hold_goes_out_at_the_wake() -> None:
    clock = Clock(1.0)
    engine = Ticking(deadline=1.5)
    line = Holding(until=1.25)
    link = TimedLink(clock, [], wakes=[1.05], end=1.2)
    d = CanDriver(engine, cast(Any, link), line, clock=clock)
    original = link.receive

    async def receive(wait: float, hold: bool = False) -> list[CanEvent[Frame]]:
        if clock.now == 1.0:
            d.queue(Frame(0x40))  # as another engine does while the driver waits
        return await original(wait, hold)

    link.receive = receive  # type: ignore[method-assign]
    with pytest.raises(asyncio.CancelledError):
        await d.run()
    assert link.calls[0] == (0.25, True)
    assert link.sent == [(1.05, [Frame(0x40)])]


async def test_a_hold_of_none_or_in_the_past_waits_as_before() -> None:
    for until in (None, 1.0, 0.5):
        clock = Clock(1.0)
        engine = Ticking(deadline=1.5)
        link = TimedLink(clock, [(1.01, Frame(1)), (1.02, Frame(2))], end=1.4)
        await run_timed(engine, link, Holding(until=until), clock)
        assert link.calls[0] == (0.5, False)
        # each frame ends its wait and is stepped at its own time
        assert link.received_at[:2] == [(1.01, [1]), (1.02, [2])]
        assert [t for t, e in engine.steps if e is not None] == [1.01, 1.02]
