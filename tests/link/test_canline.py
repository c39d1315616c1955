"""The CAN line glue both CAN adapters share (adapters/link/canline.py): link events as the
engine's events, send failures, and the bounded leave loop on a scripted link."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.link.can import CanEvent, RxBad, RxError, RxFailed, RxFrame, SendResult
from adapters.link.candriver import CanDriver
from adapters.link.canerror import LineCondition
from adapters.link.canline import CanLine, LinkEvents, act_quietly, event_of, leave_line
from gateway.errors import AdapterError


@dataclass(frozen=True)
class Frame:
    arbitration_id: int
    data: bytes = b""


Event = tuple[Any, ...]


def tagged(kind: str) -> Callable[..., Event]:
    """An engine's event constructor: here a tuple of its kind and its arguments."""
    return lambda *args: (kind, *args)


FrameIn, BusErrorIn, BadFrame = tagged("frame in"), tagged("bus error"), tagged("bad frame")
LinkDown, TxFailed = tagged("link down"), tagged("tx failed")
EVENTS: LinkEvents[Frame, Event] = LinkEvents(FrameIn, BusErrorIn, BadFrame, LinkDown, TxFailed)


class Line(CanLine[Frame, Event, Any]):
    """The shared event side, with the action side of a test engine: a Frame is sent,
    anything else handled (an "unplugged" action raises as a hub gone would)."""

    def __init__(self) -> None:
        super().__init__(EVENTS)
        self.handled: list[Any] = []

    def frame(self, action: Any) -> Frame | None:
        return action if isinstance(action, Frame) else None

    def handle(self, now: float, action: Any) -> None:
        if action == "unplugged":
            raise AdapterError("the adapter is not running")
        self.handled.append(action)


reasons = st.text(max_size=20)


@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_a_received_frame_is_the_engines_frame_in(can_id: int, data: bytes) -> None:
    frame = Frame(can_id, data)
    assert Line().event(RxFrame(frame)) == FrameIn(frame)


@given(st.frozensets(st.sampled_from(LineCondition)))
def test_an_error_frame_is_the_engines_bus_error(conditions: frozenset[LineCondition]) -> None:
    assert Line().event(RxError(conditions)) == BusErrorIn(conditions)


@given(reasons)
def test_a_frame_the_bus_cannot_carry_is_a_bad_frame(reason: str) -> None:
    assert Line().event(RxBad(reason)) == BadFrame(reason)


@given(reasons)
def test_a_receive_failure_is_link_down_only_when_the_link_is_down(reason: str) -> None:
    line = Line()
    assert line.event(RxFailed(reason, link_down=True)) == LinkDown(reason)
    assert line.event(RxFailed(reason, link_down=False)) == BadFrame(reason)


def test_anything_else_is_refused() -> None:
    with pytest.raises(TypeError):
        event_of(EVENTS)(cast(Any, "not a link event"))


def test_a_send_failure_with_the_link_down_gives_link_down_then_tx_failed() -> None:
    failed = SendResult(1, 3, "Network is down", link_down=True)
    assert Line().send_failed(failed) == [
        LinkDown("Network is down"),
        TxFailed("Network is down", 3),
    ]


def test_a_send_failure_with_the_link_up_gives_tx_failed_alone() -> None:
    assert Line().send_failed(SendResult(0, 2, "Transmit buffer full")) == [
        TxFailed("Transmit buffer full", 2)
    ]
    assert Line().send_failed(SendResult(0, 1)) == [TxFailed("", 1)]  # no error text


# ---------------------------------------------------------------- the leave loop

ANSWER = Frame(0x580)


@dataclass
class Clock:
    now: float = 100.0

    def __call__(self) -> float:
        return self.now


@dataclass
class Link:
    """Hands out scripted receive results (then nothing), each wait passing on the clock."""

    clock: Clock
    script: list[list[CanEvent[Frame]]]
    waits: list[float] = field(default_factory=list)
    sent: list[list[Any]] = field(default_factory=list)

    async def receive(self, wait: float, hold: bool = False) -> list[CanEvent[Frame]]:
        self.waits.append(wait)
        self.clock.now += wait
        return self.script.pop(0) if self.script else []

    def send(self, frames: Sequence[Any]) -> SendResult:
        self.sent.append(list(frames))
        return SendResult(len(frames))


class Leaving:
    """An engine leaving the line: a request out at the start, done on its answer; due
    every 0.25 s from the start (times in binary fractions: exact sums)."""

    def __init__(self, start_actions: list[Any]) -> None:
        self.start_actions = start_actions
        self.done = False
        self.steps: list[tuple[float, Any]] = []
        self.deadline: float | None = None

    def leave(self, now: float) -> list[Any]:
        self.deadline = now + 0.25
        return self.start_actions

    def step(self, now: float, event: Any = None) -> list[Any]:
        self.steps.append((now, event))
        if event is None and self.deadline is not None and now >= self.deadline:
            self.deadline = now + 0.25
        if event == FrameIn(ANSWER):
            self.done = True
            return ["answered"]
        return []

    def next_deadline(self) -> float | None:
        return self.deadline


def driver(engine: Leaving, link: Link, line: Line, clock: Clock) -> CanDriver[Frame, Any, Any]:
    return CanDriver(engine, cast(Any, link), line, clock)


async def leave(engine: Leaving, link: Link, bound: float, longest_wait: float) -> None:
    d = driver(engine, link, Line(), link.clock)
    await leave_line(d, engine.leave, lambda: engine.done, bound=bound, longest_wait=longest_wait)


async def test_leaving_sends_the_start_and_steps_until_the_engine_is_done() -> None:
    clock, line = Clock(), Line()
    engine = Leaving([Frame(0x600), Frame(0x601), "unplugged"])
    link = Link(clock, [[], [RxFrame(ANSWER)], [RxFrame(Frame(0x700))]])
    d = driver(engine, link, line, clock)
    d.queue(Frame(0x123))  # not sent yet when the leaving starts: dropped
    befores: list[float] = []
    await leave_line(
        d,
        engine.leave,
        lambda: engine.done,
        bound=1.0,
        longest_wait=0.125,
        before_step=befores.append,
    )
    # the start's frames in one batch; a handler failing (the hub gone) stopped nothing
    assert link.sent == [[Frame(0x600), Frame(0x601)]]
    assert engine.done and line.handled == ["answered"]
    assert link.waits == [0.125, 0.125]  # the answer came with the second wait: no third
    assert engine.steps == [
        (100.125, None),
        (100.25, FrameIn(ANSWER)),
        (100.25, None),
    ]
    assert befores == [100.0, 100.0, 100.125]  # before the start, then before each wait


async def test_leaving_ends_at_the_bound_without_an_answer() -> None:
    clock = Clock()
    engine = Leaving([Frame(0x600)])
    link = Link(clock, [])
    await leave(engine, link, bound=0.5, longest_wait=0.1875)
    assert not engine.done
    # at most longest_wait a wait, and never past the engine's deadline (every 0.25 s)
    assert link.waits == [0.1875, 0.0625, 0.1875, 0.0625]
    assert clock.now == 100.5
    assert [now for now, _ in engine.steps] == [100.1875, 100.25, 100.4375, 100.5]


async def test_an_engine_done_at_once_is_not_waited_for() -> None:
    clock = Clock()
    engine = Leaving([])
    engine.done = True
    link = Link(clock, [])
    await leave(engine, link, bound=1.0, longest_wait=0.05)
    assert link.waits == [] and link.sent == [] and engine.steps == []


def test_act_quietly_swallows_an_adapter_error_and_nothing_else() -> None:
    clock = Clock()
    line = Line()
    d = driver(Leaving([]), Link(clock, []), line, clock)
    act_quietly(d, 1.0, ["unplugged", "after"])  # the rest of that batch is not done
    assert line.handled == []
    act_quietly(d, 1.0, ["later"])
    assert line.handled == ["later"]

    class Broken(Line):
        def handle(self, now: float, action: Any) -> None:
            raise RuntimeError("a bug")

    with pytest.raises(RuntimeError):
        act_quietly(driver(Leaving([]), Link(clock, []), Broken(), clock), 1.0, ["x"])


def test_the_adapters_give_their_engines_classes() -> None:
    """Each CAN adapter's line maps every link event to its own engine's event."""
    from adapters.can import adapter as co
    from adapters.can import adapter as dn
    from adapters.canopen import master as com
    from adapters.devicenet import scanner as dns

    for events, engine in ((co.LINK_EVENTS, com), (dn.LINK_EVENTS, dns)):
        convert = event_of(cast(Any, events))
        conditions = frozenset({LineCondition.BUS_OFF})
        frame = cast(Any, object())
        assert convert(RxFrame(frame)) == engine.FrameIn(frame)
        assert convert(RxError(conditions)) == engine.BusErrorIn(conditions)
        assert convert(RxBad("ext id")) == engine.BadFrame("ext id")
        assert convert(RxFailed("down", link_down=True)) == engine.LinkDown("down")
        assert convert(RxFailed("odd", link_down=False)) == engine.BadFrame("odd")
        assert events.send_failed(SendResult(0, 2, "down", link_down=True)) == [
            engine.LinkDown("down"),
            engine.TxFailed("down", 2),
        ]
