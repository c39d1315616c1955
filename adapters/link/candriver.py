"""The driver loop of a frame engine on a :class:`~adapters.link.can.CanLink`.

One pass of :meth:`CanDriver.run`: the adapter's work before the step
(:meth:`CanProtocol.before_step`: new outputs from the hub, once per poll), the events the
last wait received stepped (each shown to :meth:`CanProtocol.received` after its step), a
step of the engine when its deadline has come (or when it has none), the adapter's work
after it (:meth:`CanProtocol.after_step`: a second engine sharing the line), the frames
asked for sent in one batch; then a wait for frames until the earliest of the engine's
deadline, the adapter's (:meth:`CanProtocol.wake_at`) and the end of a receive hold.

Receive hold (:meth:`CanProtocol.hold_until`): when the protocol says received frames need
not be handled before a time, the wait is held (``CanLink.receive(wait, hold=True)``):
frames arriving meanwhile do not end it; it ends at the earliest of the times above (a
deadline of the engine or the adapter is never put off by a hold), or at once on
:meth:`~adapters.link.can.CanLink.wake` (frames queued from elsewhere, an SDO asked for)
or a receive failure. Then everything waiting is drained and stepped in the next pass
*at the drain time* (the pass's ``now``), after ``before_step``, before the engine's own
step: a frame that arrived during the hold is stepped as if it had arrived at the hold's
end. Without a hold (None, the default) each frame ends the wait as before.

Burst (:class:`Burst`, docs/decisions/0108): a wait that is not held, while the loop has
nothing else to do, is first made on the bus's descriptor itself (``CanLink.burst``), so
a steady line's responses are taken without a turn of the loop each; a callback handed to
the loop ends it at once, and the loop gets a turn at least every :data:`BURST_HOLD`.

A send that fails (a full transmit queue, the interface down) goes back to the engine as
the events :meth:`CanProtocol.send_failed` makes of it, so it backs off; the frames not
sent are dropped, never retried here. The clock is injected (``time.monotonic`` unless a
test gives another).
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Callable, Sequence
from typing import Final, Generic, Protocol, TypeVar

from adapters.link.can import CanEvent, CanLink, Frame, FrameT, SendResult
from adapters.link.engine import Engine
from adapters.link.timer import loop_next_timer, loop_ready, loop_wake

IDLE_WAIT: Final = 1.0  # s: the longest wait for frames when nothing else is due
BURST: Final = 0.002  # s: the longest a burst waits on the bus for the next frames
BURST_HOLD: Final = 0.05  # s: the longest a run of bursts keeps the loop from a turn

EventT = TypeVar("EventT")
ActionT = TypeVar("ActionT")
FrameT_contra = TypeVar("FrameT_contra", bound=Frame, contravariant=True)
EventT_co = TypeVar("EventT_co", covariant=True)
ActionT_contra = TypeVar("ActionT_contra", contravariant=True)


class CanProtocol(Protocol[FrameT_contra, EventT_co, ActionT_contra]):
    """What the driver needs of one protocol on CAN and of its adapter; the hooks with a
    body are optional (their default does nothing)."""

    def event(self, received: CanEvent[FrameT_contra]) -> EventT_co:
        """A link event as the engine's event."""
        ...

    def frame(self, action: ActionT_contra) -> Frame | None:
        """The frame ``action`` sends, or None for an action :meth:`handle` takes."""
        ...

    def handle(self, now: float, action: ActionT_contra) -> None:
        """An action that is no frame (a report for the adapter)."""
        ...

    def send_failed(self, result: SendResult) -> Sequence[EventT_co]:
        """The events telling the engine a send failed (it backs off)."""
        ...

    def before_step(self, now: float) -> None:
        """Each pass, before the engine's step."""
        return

    def after_step(self, now: float) -> None:
        """Each pass, after the engine's step, before the frames go out."""
        return

    def wake_at(self) -> float | None:
        """When the adapter wants a pass without a frame (None: only the engine decides)."""
        return None

    def received(self, now: float, event: CanEvent[FrameT_contra]) -> None:
        """A link event, after the engine stepped it (a second engine on the line)."""
        return

    def hold_until(self, now: float) -> float | None:
        """Received frames need not be handled before this time (the link does not wake
        the loop for them until then; a deadline, a wake or a failure still ends the wait
        at once); None: each frame is handled as it comes."""
        return None


class CanDriver(Generic[FrameT, EventT, ActionT]):
    """Glue between one engine and one CAN link (see the module docstring)."""

    def __init__(
        self,
        engine: Engine[EventT, ActionT],
        link: CanLink[FrameT],
        protocol: CanProtocol[FrameT, EventT, ActionT],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.engine = engine
        self.link = link
        self.protocol = protocol
        self.clock = clock
        self._outbox: list[Frame] = []

    async def run(self) -> None:
        """Pass after pass until cancelled (see the module docstring)."""
        engine, protocol, clock, link = self.engine, self.protocol, self.clock, self.link
        next_deadline, wake_at, hold_until = (
            engine.next_deadline,
            protocol.wake_at,
            protocol.hold_until,
        )
        events: Sequence[CanEvent[FrameT]] = ()
        burst = Burst.of(asyncio.get_running_loop(), clock)
        while True:
            now = clock()
            protocol.before_step(now)
            if events:  # what the last wait received, at the drain time
                self.take(now, events)
            deadline = next_deadline()
            if deadline is None or now >= deadline:
                self.act(now, engine.step(now))
            protocol.after_step(now)
            if self._outbox:  # also frames queued from elsewhere meanwhile
                self.flush(now)
            # the wait: until the earliest of the engine's deadline (after its step), the
            # adapter's and a hold's end, IDLE_WAIT when none has one
            deadline = next_deadline()
            other = wake_at()
            if other is not None and (deadline is None or other < deadline):
                deadline = other
            held = hold_until(now)
            if held is not None and held > now:
                if deadline is None or held < deadline:
                    deadline = held
                wait = deadline - clock()
                events = await link.receive(wait if wait > 0.0 else 0.0, True)
            else:
                burst_got = burst.wait(link, deadline) if burst is not None else None
                if burst_got is not None:
                    events = burst_got
                else:  # no burst: the loop's turn
                    wait = IDLE_WAIT if deadline is None else deadline - clock()
                    events = await link.receive(wait if wait > 0.0 else 0.0)

    def take(self, now: float, events: Sequence[CanEvent[FrameT]]) -> None:
        """Step each received event (then show it to the adapter)."""
        step, event_of, received, act = (
            self.engine.step,
            self.protocol.event,
            self.protocol.received,
            self.act,
        )
        for event in events:
            act(now, step(now, event_of(event)))
            received(now, event)

    def act(self, now: float, actions: Sequence[ActionT]) -> None:
        """Frames to the outbox, the rest to the adapter, in order."""
        for action in actions:
            frame = self.protocol.frame(action)
            if frame is not None:
                self._outbox.append(frame)
            else:
                self.protocol.handle(now, action)

    def queue(self, frame: Frame) -> None:
        """A frame from elsewhere (a second engine on the line) for the next send."""
        self._outbox.append(frame)

    def discard(self) -> None:
        """Forget the frames not sent yet (leaving the line)."""
        self._outbox.clear()

    def flush(self, now: float) -> None:
        """Send what was asked for; a failure goes back to the engine (it backs off)."""
        frames, self._outbox = self._outbox, []
        if not frames:
            return
        result = self.link.send(frames)
        if result.error is None:
            return
        for event in self.protocol.send_failed(result):
            self.act(now, self.engine.step(now, event))


class Burst:
    """The driver's burst (docs/decisions/0108): the next frames waited for on the bus's
    descriptor itself, without a turn of the line's loop, while the loop has nothing else
    to do: no callback waiting, its next timer not before the wait's end, its wake
    descriptor (a callback handed from another thread: a command) watched beside the
    bus. Each wait lasts at most :data:`BURST`, and a run of them at most
    :data:`BURST_HOLD` before the loop gets a turn whatever happens."""

    def __init__(self, loop: asyncio.AbstractEventLoop, ready: object, wake: int) -> None:
        self.loop = loop
        self.ready = ready  # true while callbacks wait in the loop (timer.loop_ready)
        self.wake = wake
        self.since: float | None = None  # the run of bursts began (None: after a turn)

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop, clock: Callable[[], float]) -> Burst | None:
        """The burst of a driver on ``loop``; None where it cannot be kept: a clock other
        than the loop's (a test's), or ``DRIVE_GATEWAY_CAN_BURST=off`` (a comparison)."""
        if clock is not time.monotonic or os.environ.get("DRIVE_GATEWAY_CAN_BURST") == "off":
            return None
        return cls(loop, loop_ready(loop), loop_wake(loop))

    def wait(self, link: CanLink[FrameT], deadline: float | None) -> list[CanEvent[FrameT]] | None:
        """Frames that came by the earliest of ``deadline``, :data:`BURST` and the loop's
        next timer; ``[]`` when ``deadline`` came with none; None: the loop's turn (the
        caller awaits the link)."""
        now = time.monotonic()
        if self.ready or (deadline is not None and deadline <= now):
            self.since = None  # (a deadline already past: the loop's turn, as before)
            return None
        if self.since is None:
            self.since = now
        elif now - self.since > BURST_HOLD:
            self.since = None
            return None
        until = min(now + BURST, loop_next_timer(self.loop))
        due = False
        if deadline is not None and deadline <= until:
            until, due = deadline, True
        events = link.burst(until, self.wake)
        if events is None or (not events and not due):
            self.since = None
            return None
        return events
