"""The driver loop of a byte-stream engine on a :class:`~adapters.link.serial.SerialLink`.

Everything happens in loop callbacks, which block only for an idle time under
:data:`SLEEP_LIMIT` (below): bytes from the link go
through the protocol's stream codec (:class:`StreamProtocol`) into ``engine.step(now,
event)``; each resulting transmission (:meth:`StreamProtocol.transmission`) is written once
its ``not_before`` has come and confirmed to the engine with
:meth:`StreamProtocol.written` carrying the time the write actually happened (a loop
callback can run late: the engine counts every idle time and reply deadline from that
time, never from the planned one); the other actions go to ``on_action`` once the step's
requests are on their way (a reply's handling is not part of the turnaround); a timer
steps the engine at ``engine.next_deadline()``. Before each request the codec is told the
line was idle (:meth:`StreamProtocol.idle`), so a reply cut short by noise cannot swallow
the next one.

Every other wait is slept on a precise timer the loop waits on like on a port
(:func:`adapters.link.timer.loop_timer`: a timerfd, armed at an absolute time of the
loop's clock): one for the engine's next deadline, one for the write whose ``not_before``
has not come. Nothing spins. An idle time ending within :data:`SLEEP_LIMIT` (Profibus TSYN
after a reply at 500 kbit/s: 66 us) is slept in the step itself, in a select on the port
(bytes that come meanwhile are stepped first): cheaper than the loop turn a timer costs,
holding the loop that long; a longer wait is a sleep on the timer and the wake-up that
follows, not a millisecond (the loop's own timers) nor a busy loop. A write never goes
before its ``not_before`` (the kernel never fires a timer early; the driver checks the
clock once more), and writes go in the order the engine gave them.
Bytes that arrived before a timer expired are read first (the loop's poller reports them
first); a reply deadline's timer reads the port once more before the engine judges it.

A reply deadline whose timer fires late (the process was not scheduled) is judged once more
that much later (:meth:`StreamDriver._postpone`): what could not run meanwhile includes a
simulated line's devices, which share the loop.

Where the far end answers apart from the loop (``bursts``), the replies an engine's steady
lane takes are taken back to back, each next request sent at once, without the loop's turn
between (:meth:`StreamDriver._burst`, at most :data:`BURST`; docs/decisions/0101).
"""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, Final, Generic, Protocol, TypeVar

from adapters.link import ring
from adapters.link.engine import Engine
from adapters.link.ringplan import RingPlan, RingResult, RingStop
from adapters.link.serial import SerialLink
from adapters.link.timer import (
    loop_clock,
    loop_next_timer,
    loop_ready,
    loop_timer,
    loop_wake,
    precise_sleeps,
)

log = logging.getLogger(__name__)

MAX_DUE_STEPS: Final = 8  # steps at once for deadlines already come, then the loop's turn
SLEEP_LIMIT: Final = 0.0001  # s: idle times this short are slept in the step (see _step)
NEAR: Final = 0.002  # s: a deadline this close has a timer of its own (see _arm)
LATE_TIMER: Final = 0.005  # s: a reply deadline's timer this late means the loop stood still
MAX_POSTPONE: Final = 0.25  # s: the longest a late reply deadline is postponed at once
MAX_POSTPONES: Final = 3  # postponements of one reply deadline (the loop late every time)
BURST: Final = 0.002  # s: the longest a burst of steady exchanges keeps the loop (_burst)
BURST_TURNS: Final = 64  # replies and idle times at most in one burst
RING_LIMIT: Final = 0.05  # s: no request of a steady ring goes out later than this (_ring)
RING_HOLD: Final = 0.1  # s: the longest a burst with rings keeps the loop

EventT = TypeVar("EventT")
EventT_co = TypeVar("EventT_co", covariant=True)
EventT_contra = TypeVar("EventT_contra", contravariant=True)


class ReplyEngine(Engine[EventT_contra, Any], Protocol[EventT_contra]):
    """A master's engine on a serial line: it also says whether it waits for a reply."""

    def awaiting_reply(self) -> bool:
        """True while the next deadline is a reply's (a late timer then postpones it)."""
        ...


class Transmission(Protocol):
    """Bytes to write at ``not_before`` at the earliest (the line's idle time is in it)."""

    @property
    def data(self) -> bytes: ...

    @property
    def not_before(self) -> float: ...


class StreamProtocol(Protocol[EventT_co]):
    """What the driver needs of one byte-stream protocol: its stream codec (bytes ->
    engine events) and which of its engine's actions are transmissions."""

    def whole(self, data: bytes) -> EventT_co | None:
        """The event of ``data`` when it is one whole frame and nothing is held (one read,
        one reply: the common case); None: :meth:`feed` it."""
        ...

    def feed(self, data: bytes) -> Sequence[EventT_co]:
        """Take bytes off the line; the events of the frames (and noise) they complete."""
        ...

    def receiving(self) -> EventT_co | None:
        """The event saying a frame has begun (bytes held), or None when nothing is held."""
        ...

    def idle(self) -> Sequence[EventT_co]:
        """The line was idle (a request goes next): what is held is no frame; the events of
        what that flushed (noise), for ``on_flushed``."""
        ...

    def transmission(self, action: Any) -> Transmission | None:
        """``action`` as bytes to write, or None for an action ``on_action`` handles."""
        ...

    def written(self, at: float) -> EventT_co:
        """The event confirming the oldest unconfirmed transmission, written at ``at``."""
        ...


class StreamDriver(Generic[EventT]):
    """Glue between one engine and one serial link (see the module docstring)."""

    def __init__(
        self,
        engine: ReplyEngine[EventT],
        link: SerialLink,
        protocol: StreamProtocol[EventT],
        *,
        on_action: Callable[[Any], None] = lambda action: None,
        on_flushed: Callable[[EventT], None] = lambda event: None,
        on_stepped: Callable[[], None] = lambda: None,
        bursts: bool = False,
        ring_priority: int = 0,
    ) -> None:
        self.engine = engine
        self.link = link
        self.protocol = protocol
        self.loop = link.loop
        self._time = loop_clock(self.loop)  # bound once: several reads of the clock per message
        self.on_action = on_action
        self.on_flushed = on_flushed
        self.on_stepped = on_stepped
        # the engine's next deadline: one timer for those within NEAR (TSYN, an idle time),
        # one for the later ones (a reply wait), kept armed while it is no later than due
        self._near = loop_timer(self.loop, lambda: self._on_timer(self._near_at))
        self._far = loop_timer(self.loop, lambda: self._on_timer(self._far_at))
        self._near_at = self._far_at = 0.0  # the time each was last armed for
        self._write_timer = loop_timer(self.loop, self._on_write_due)
        self._writes: deque[Transmission] = deque()  # waiting for their not_before, in order
        self._stepping = False
        self._queued: deque[EventT | None] = deque()
        self._postponed_for: float | None = None
        self._postpones = 0
        self.postponed = 0  # reply deadlines judged later because their timer ran late
        self._stopped = False
        # an engine's steady lane, if it has one: ``lane(data, now, horizon)``, a reply
        # taken by its bytes (the actions, a request among them only if it may go within
        # ``horizon`` s; None: not such a reply, nothing changed); every whole read is
        # offered to it first (docs/decisions/0096)
        lane = getattr(engine, "lane", None)
        self._lane: Callable[[bytes, float, float], Sequence[Any] | None] | None = lane
        self.lane_taken = 0  # replies the steady lane took
        # the steady lane's replies taken back to back (_burst): asked for where the far
        # end answers apart from this loop, on a port with a descriptor
        self._bursts = bursts and lane is not None and link.has_descriptor
        self.burst_taken = 0  # replies taken in a burst (in lane_taken too)
        self.bursts_yielded = 0  # bursts ended by a callback waiting in the loop
        self._loop_ready = loop_ready(self.loop)
        # the steady ring (docs/decisions/0103): where bursts are, an engine that plans one
        self._ring_plan: Callable[[float, float], RingPlan | None] | None = getattr(
            engine, "ring_plan", None
        )
        self._ring_done: Callable[[RingResult], Sequence[Any]] | None = getattr(
            engine, "ring_done", None
        )
        self._rings = (
            self._bursts
            and ring.enabled()
            and self._ring_done is not None
            and self._time is time.monotonic  # the ring's clock is the loop's
        )
        self._wake = loop_wake(self.loop)
        self._ring_priority = ring_priority  # SCHED_FIFO of the rings (0: none; 0104)
        self._refused = False  # the priority was refused (said once)
        self.ring_taken = 0  # replies taken by steady rings (not in lane_taken)
        self.rings = 0  # rings run
        self.rings_woken = 0  # rings ended by a callback handed to the loop (a command)
        link.on_data = self._on_data
        precise_sleeps()  # the short idle times slept in _step end on time (1 us slack)

    def start(self) -> None:
        self.poke()

    def stop(self) -> None:
        """No more stepping (the link stays open: the caller closes it)."""
        self._stopped = True
        self._writes.clear()
        self._near.close()
        self._far.close()
        self._write_timer.close()

    def poke(self) -> None:
        """Step the engine now (after a command: new outputs, an acyclic job...)."""
        self._step(None)

    # ------------------------------------------------------------------ stepping

    def _step(self, event: EventT | None) -> None:
        if self._stopped:
            return
        if self._stepping:  # from inside a step (a callback, the port read at a deadline)
            self._queued.append(event)
            return
        self._stepping = True
        try:
            self._queued.append(event)
            self._drain()
            deadline = self.engine.next_deadline()
            due = 0
            slept = 0.0
            # A deadline already come (12 Mbit/s TSYN is 2.75 us: over before the step
            # ends) is stepped at once: a timer would cost a sleep and a wake-up for nothing.
            # An idle time ending within SLEEP_LIMIT (500 kbit/s TSYN after a reply: 66 us)
            # is slept here, in a select on the port: cheaper than the loop turn a timer
            # costs, and bytes that come meanwhile are stepped first, as on the timer's
            # path. The loop is held that long at most (plus the kernel's wake-up); never
            # a reply wait (docs/decisions/0023-short-idle-slept-in-step.md).
            while deadline is not None and due < MAX_DUE_STEPS:
                wait = deadline - self._time()
                if wait > 0:
                    if slept + wait > SLEEP_LIMIT or self.engine.awaiting_reply():
                        break
                    slept += wait
                    if self.link.wait_readable(wait):
                        self.link.read_now()  # queued: stepped before the deadline's step
                due += 1
                self._queued.append(None)
                self._drain()
                deadline = self.engine.next_deadline()
        finally:
            self._stepping = False
        self._arm(deadline)
        self.on_stepped()

    def _drain(self) -> None:
        queued, step, now = self._queued, self.engine.step, self._time
        while queued and not self._stopped:
            actions = step(now(), queued.popleft())
            if actions:
                self._run(actions)

    def _run(self, actions: Sequence[Any]) -> None:
        """Requests first, then the other actions in their order.

        What a request carries was fixed by the engine when it built it, so nothing a
        handler does can change it; the line must not wait while the adapter decodes a
        reply's inputs and updates the hub (the master's turnaround).
        """
        others: list[Any] = []
        todo = actions
        transmission = self.protocol.transmission
        i = 0
        while i < len(todo):
            action = todo[i]
            i += 1
            out = transmission(action)
            if out is None:
                others.append(action)
                continue
            at = self._transmit(out)
            if at is not None:  # confirmed at once: what the engine does next comes first
                more = self.engine.step(self._time(), self.protocol.written(at))
                if more:
                    todo, i = [*todo[i:], *more], 0
        for action in others:
            try:
                self.on_action(action)
            except Exception:  # a profile bug must not stop the line
                log.exception("handling %r failed", action)

    def _arm(self, deadline: float | None) -> None:
        """A timer for the engine's next deadline.

        A timer already armed for an earlier time is kept: it fires early, the step finds
        nothing due and arms again. The reply deadline moves on with every message, so
        the far timer is armed about once per reply wait, not once per message; the near
        one (the idle time before the next request) once per message.
        """
        if self._stopped or deadline is None:
            return  # nothing due: an armed timer only causes one idle step
        if deadline - self._time() <= NEAR:
            armed = self._near.at
            if armed is None or armed > deadline:
                self._near_at = deadline
                self._near.set(deadline)
            return
        armed = self._far.at
        if armed is None or armed > deadline:
            self._far_at = deadline
            self._far.set(deadline)

    def _on_timer(self, armed: float) -> None:
        if self.engine.awaiting_reply():
            self.link.read_now()  # a reply that came meanwhile is judged first
            if self._stopped or not self.engine.awaiting_reply() or self._postpone(armed):
                return
        self._step(None)

    def _postpone(self, armed: float) -> bool:
        """A reply deadline whose timer ran late (the loop did not run meanwhile) is judged
        as much later, at most :data:`MAX_POSTPONES` times: a device simulated on the same
        loop, and the pty between, could not answer while the loop stood still. (On a real
        line the reply is in the port by then and read first: :meth:`_on_timer` reads the
        port before it judges a reply deadline.)"""
        deadline = self.engine.next_deadline()
        if deadline is None or not self.engine.awaiting_reply():
            return False
        if deadline != self._postponed_for:
            self._postponed_for, self._postpones = deadline, 0
        lag = self.loop.time() - max(armed, deadline)
        if lag <= LATE_TIMER or self._postpones >= MAX_POSTPONES:
            return False
        self._postpones += 1
        self.postponed += 1
        self._far_at = self.loop.time() + min(lag, MAX_POSTPONE)
        self._far.set(self._far_at)
        return True

    # ------------------------------------------------------------------ receiving

    def _on_data(self, data: bytes, now: float) -> None:
        protocol = self.protocol
        lane = self._lane
        if (
            lane is not None
            and not self._stepping
            and not self._writes
            and protocol.receiving() is None
        ):
            actions = lane(data, now, SLEEP_LIMIT)  # a longer idle time: a timer, as _step
            if actions is not None:
                self._lane_run(actions)
                return
        whole = protocol.whole(data)
        if whole is not None:
            self._step(whole)
            return
        for event in protocol.feed(data):
            self._step(event)
        receiving = protocol.receiving()
        if receiving is not None:
            self._step(receiving)

    def _lane_run(self, actions: Sequence[Any]) -> None:
        """The steady lane's actions: its request written once its idle time is over (a
        short one slept here, as :meth:`_step` sleeps it), the replies that follow taken
        in a burst (:meth:`_burst`), then what :meth:`_step` does after a step (anything
        queued meanwhile is stepped, the timer armed)."""
        self._lane_turn(actions)
        if self._bursts and not self._queued:
            self._burst()
        if self._queued:
            self._step(self._queued.popleft())
            return
        self._arm(self.engine.next_deadline())

    def _lane_turn(self, actions: Sequence[Any]) -> None:
        self.lane_taken += 1
        self._stepping = True
        try:
            first = self.protocol.transmission(actions[0]) if actions else None
            if first is not None:
                wait = first.not_before - self._time()
                if 0 < wait <= SLEEP_LIMIT:
                    self.link.wait_readable(wait)  # bytes meanwhile: read after the write
            self._run(actions)
        finally:
            self._stepping = False
        self.on_stepped()

    def _burst(self) -> None:
        """Steady exchanges back to back without a loop turn between (docs/decisions/0101).

        After a steady lane's request, the reply is waited for here, on the port, and a
        reply the lane takes sends the next request at once, and so on: the loop's poll,
        its callback and the driver's timers are left out of each exchange. The burst ends
        at anything else, each left to the loop as it would be without a burst (an idle
        time before the next request within :data:`BURST` is slept here, as the step's
        short idle times are, and the request sent by the step at its end): a reply
        the lane does not take (stepped here as any reply), no reply by its deadline or
        by the end of :data:`BURST` (the timer or the next read sees to it), an error or
        hang-up on the port (the loop's reader reports it), and a callback waiting in the
        loop (a command relayed from the hub: the reply read meanwhile is handed to the
        loop after it, so the next request carries what the command changed)."""
        engine, link, lane, protocol = self.engine, self.link, self._lane, self.protocol
        waiting = self._loop_ready
        end = self._time() + BURST
        hold = end - BURST + RING_HOLD
        for _ in range(BURST_TURNS):
            if lane is None or self._stopped or self._writes or waiting:
                return
            if self._rings and engine.awaiting_reply():
                went_on = self._ring()
                if went_on is not None:
                    if not went_on:
                        return
                    end = min(self._time() + BURST, hold)
                    continue
            deadline = engine.next_deadline()
            if deadline is None or self._queued:
                return
            if not engine.awaiting_reply():  # an idle time before the next request
                if deadline > end:
                    return
                wait = deadline - self._time()
                if wait > 0 and link.wait_readable(wait):
                    return  # bytes in an idle time: the loop's reader takes them
                if waiting:  # a command came meanwhile: it goes first, the timer steps
                    return
                self._step(None)  # the request, as the timer's step would send it
                continue
            wait = min(deadline, end) - self._time()
            if wait <= 0 or not link.wait_readable(wait):
                return
            data = link.take()
            if not data:
                return
            now = self._time()
            if waiting:
                self.bursts_yielded += 1
                self.loop.call_soon(self._on_data, data, now)
                return
            actions = lane(data, now, SLEEP_LIMIT) if protocol.receiving() is None else None
            if actions is None:
                self._on_data(data, now)
                return
            self.burst_taken += 1
            self._lane_turn(actions)

    def _ring(self) -> bool | None:
        """A steady ring from the request on the line (docs/decisions/0103): the engine's
        plan run on the port (:mod:`adapters.link.ring`), the engine brought up to date,
        what the ring stopped at left as the burst leaves it. True: the last reply was
        taken and the ring's plan was over (the burst goes on); False: the burst ends;
        None: no ring (the burst takes the reply itself)."""
        plan_of, done = self._ring_plan, self._ring_done
        if plan_of is None or done is None or self.protocol.receiving() is not None:
            return None
        now = self._time()
        plan = plan_of(now, min(now + RING_LIMIT, loop_next_timer(self.loop)))
        if plan is None:
            return None
        link = self.link
        result = ring.run(link.descriptor, self._wake, plan, self._ring_priority)
        if result.realtime < 0 and not self._refused:
            self._refused = True
            log.warning(
                "%s: steady rings at ordinary priority: SCHED_FIFO %d not permitted (%s);"
                " allow it with LimitRTPRIO=%d in the unit (docs/operations.md) or set"
                " ring_priority = 0",
                link.name,
                self._ring_priority,
                os.strerror(-result.realtime),
                self._ring_priority,
            )
        link.counted(result.bytes_in, result.bytes_out)
        actions = done(result)
        self.rings += 1
        self.ring_taken += result.taken - result.left_out
        if result.written:
            for event in self.protocol.idle():  # the line was idle before each request
                self.on_flushed(event)
        if actions:  # (never a request: inputs and the like, for the adapter)
            self._run(actions)
        stop = result.stop
        if stop is RingStop.WRITE:  # the rest of a request the port took only in part
            link.write(plan.requests[result.written - 1][result.partial :])
        elif stop is RingStop.WAKE:
            self.rings_woken += 1
        if result.rest:  # not taken: as any reply
            self._on_data(result.rest, result.rest_at)
            return False
        return stop is RingStop.END

    # ------------------------------------------------------------------ sending

    def _transmit(self, out: Transmission) -> float | None:
        """Write ``out`` when due; the time it was written, or None if it waits for its
        time (confirmed to the engine from :meth:`_on_write_due`)."""
        for event in self.protocol.idle():  # the line was idle before this request
            self.on_flushed(event)
        if self._writes or out.not_before > self._time():
            self._writes.append(out)  # after any still waiting: writes keep their order
            if self._write_timer.at is None:
                self._write_timer.set(self._writes[0].not_before)
            return None
        self.link.write(out.data)
        return self._time()

    def _on_write_due(self) -> None:
        """The first waiting write's time has come: write what is due, in order, each
        confirmed with the time it really went, however late."""
        writes = self._writes
        while writes and not self._stopped:
            out = writes[0]
            if out.not_before > self.loop.time():  # never early (a fallback timer may be)
                self._write_timer.set(out.not_before)
                return
            writes.popleft()
            self.link.write(out.data)
            self._step(self.protocol.written(self.loop.time()))
