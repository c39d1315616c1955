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
    sent: list[list[Any]] = field(default_factory=list)

    async def receive(self, wait: float) -> list[CanEvent[Frame]]:
        self.waits.append(wait)
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
    assert engine.steps[:2] == [(10.0, None), (10.0, RxFrame(Frame(7)))]
    assert link.sent[:2] == [[Frame(0x1)], [Frame(0x107)]]
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
    assert line.calls[:4] == ["before", "after", "wake", f"received {RxFrame(Frame(2))}"]
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
    # pass 1: now, the wait, the frame's step; pass 2: now, the wait (then cancelled)
    assert reads == 5 and engine.asked == 4
    assert link.waits == [0.5, 0.5]
