"""What a frame engine's line on CAN shares, whatever its protocol: the link's events as
the engine's events, send failures as events, and leaving the line bounded in time.

The CAN link (:mod:`.can`) reports what it received as :class:`~.can.RxFrame`,
:class:`~.can.RxError` (a SocketCAN error frame), :class:`~.can.RxBad` (a frame the bus
cannot carry) and :class:`~.can.RxFailed` (receiving failed), and a send as a
:class:`~.can.SendResult`. Every engine on CAN has an event for each of those; the engine
brings its own classes as a :class:`LinkEvents` (their constructors), and :class:`CanLine`
is the part of the :class:`~.candriver.CanProtocol` made of them: ``event`` and
``send_failed``. The adapter's line subclasses it and adds the action side (which actions
are frames, the handlers of the others) and its hooks.

`leave_line` is the end of a line's life (DeviceNet: the Releases; CANopen: the heartbeat
consumers switched off by SDO): the frames not sent yet dropped, the engine's leaving
actions sent, then the engine stepped with what comes back and its deadlines until it is
done or the time is up.

Nothing here knows a protocol: the engines' classes come in as constructors.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from adapters.link.can import CanEvent, FrameT, RxBad, RxError, RxFailed, RxFrame, SendResult
from adapters.link.candriver import CanDriver, CanProtocol
from adapters.link.canerror import LineCondition
from gateway.errors import AdapterError

EventT = TypeVar("EventT")
ActionT = TypeVar("ActionT")


@dataclass(frozen=True, slots=True)
class LinkEvents(Generic[FrameT, EventT]):
    """An engine's events for what the CAN link reports: their constructors."""

    frame_in: Callable[[FrameT], EventT]
    """A data frame from the line."""
    bus_error: Callable[[frozenset[LineCondition]], EventT]
    """A SocketCAN error frame's conditions (:mod:`.canerror`)."""
    bad_frame: Callable[[str], EventT]
    """A frame the bus cannot carry, or a receive failure on a link still up: the reason."""
    link_down: Callable[[str], EventT]
    """The interface is down (a receive or a send said so): every connection is gone."""
    tx_failed: Callable[[str, int], EventT]
    """A send failed: the reason and the frames dropped (the engine backs off)."""

    def send_failed(self, result: SendResult) -> list[EventT]:
        """A failed send: the link down first when it is (every connection gone), then the
        send failure (what was dropped)."""
        error = result.error or ""
        failed = [self.link_down(error)] if result.link_down else []
        return [*failed, self.tx_failed(error, result.dropped)]


class _EventSide(Generic[FrameT, EventT]):
    """:class:`CanLine`'s own part. ``event`` is an attribute (the closure of
    :func:`event_of`), not a method: a base apart from :class:`~.candriver.CanProtocol`,
    as mypy refuses an attribute in place of the protocol's method in its own subclass."""

    event: Callable[[CanEvent[FrameT]], EventT]
    """A link event as the engine's (:func:`event_of`)."""

    def __init__(self, events: LinkEvents[FrameT, EventT]) -> None:
        self.events = events
        self.event = event_of(events)

    def send_failed(self, result: SendResult) -> list[EventT]:
        return self.events.send_failed(result)


class CanLine(_EventSide[FrameT, EventT], CanProtocol[FrameT, EventT, ActionT]):
    """The event side of an engine's :class:`~.candriver.CanProtocol`, from its
    :class:`LinkEvents`: ``event`` (:func:`event_of`) and ``send_failed``; a subclass
    gives ``frame``, ``handle`` and its hooks."""


def event_of(events: LinkEvents[FrameT, EventT]) -> Callable[[CanEvent[FrameT]], EventT]:
    """The function turning a link event into the engine's (a receive failure on a link
    that is down: ``link_down``; on one still up: ``bad_frame``). Every frame received
    passes here: a frame first, by an exact type test (the link's classes are final
    dataclasses), and no call but the engine's constructor; the constructors are held in
    the closure (as cheap as module globals; an attribute of the line, ``self.x(...)``,
    costs a few percent more per frame on Python 3.11)."""
    frame_in, bus_error, bad_frame, link_down = (
        events.frame_in,
        events.bus_error,
        events.bad_frame,
        events.link_down,
    )

    def event(received: CanEvent[FrameT]) -> EventT:
        if type(received) is RxFrame:
            return frame_in(received.frame)
        if isinstance(received, RxError):
            return bus_error(received.conditions)
        if isinstance(received, RxBad):
            return bad_frame(received.reason)
        if isinstance(received, RxFailed):
            return link_down(received.reason) if received.link_down else bad_frame(received.reason)
        raise TypeError(received)

    return event


def act_quietly(
    driver: CanDriver[FrameT, EventT, ActionT], now: float, actions: Sequence[ActionT]
) -> None:
    """``actions`` done by the driver; an adapter error of a handler (the hub gone while
    leaving) does not stop the leaving."""
    with contextlib.suppress(AdapterError):
        driver.act(now, actions)


def _nothing(now: float) -> None:
    return


async def leave_line(
    driver: CanDriver[FrameT, EventT, ActionT],
    start: Callable[[float], Sequence[ActionT]],
    done: Callable[[], bool],
    *,
    bound: float,
    longest_wait: float,
    before_step: Callable[[float], None] = _nothing,
) -> None:
    """Leave the line, bounded in time: the frames not sent yet dropped, the actions of
    ``start(now)`` (the engine's leaving) done and sent; then, until ``done()`` or ``bound``
    seconds after the start, a wait for frames (until the engine's deadline, at most
    ``longest_wait``), each received event stepped, a step of the engine, its frames sent.
    ``before_step(now)`` comes first in each pass and before ``start``. The driver's loop
    must not be running (this is its last pass)."""
    engine, link, clock, event_of = driver.engine, driver.link, driver.clock, driver.protocol.event
    now = clock()
    before_step(now)
    driver.discard()
    act_quietly(driver, now, start(now))
    driver.flush(now)
    end = now + bound
    while not done() and (now := clock()) < end:
        before_step(now)
        deadline = engine.next_deadline()
        wait = longest_wait if deadline is None else deadline - now
        events = await link.receive(min(max(wait, 0.0), longest_wait))
        now = clock()
        for event in events:
            act_quietly(driver, now, engine.step(now, event_of(event)))
        act_quietly(driver, now, engine.step(now))
        driver.flush(now)
