"""Runs a sans-IO engine (the master or a live-list scan) on a :class:`SerialLink`.

Everything happens in loop callbacks, never in a blocking call: bytes from the link go
through the streaming decoder into ``engine.step(now, event)``; each resulting
:class:`~adapters.profibus.master.Transmit` is written once its ``not_before`` has come and
confirmed to the engine with :class:`~adapters.profibus.master.Written` carrying the time
the write actually happened (a loop callback can run late: the engine counts every idle
time and reply deadline from that time, never from the planned one); the other actions go
to ``on_action`` once the step's requests are on their way (a reply's handling is not part
of the turnaround); a timer steps the engine at ``engine.next_deadline()``. Before each
request the decoder is told the line was idle, so a reply cut short by noise cannot swallow
the next one.

A deadline closer than :data:`SPIN_LIMIT` (TSYN is 66 us at 500 kbit/s) is waited for on
the port itself (``select`` with a sub-millisecond timeout) instead of a loop timer, which
cannot sleep less than a millisecond: bytes arriving meanwhile are read and stepped at once,
so a stray reply restarts the idle time before the next request is decided (1.1). At most
:data:`MAX_SHORT_WAITS` such waits per step, so the rest of the loop always gets its turn.

A reply deadline whose timer fires late (the process was not scheduled) is judged once more
that much later (:meth:`LineDriver._postpone`): what could not run meanwhile includes the
simulated slaves of ``simulate = true``, which share the loop.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, Final, Protocol

from .fdl import DataTelegram, Discarded, NeedMore, ShortAck, TelegramDecoder, TokenTelegram
from .link import SerialLink
from .master import Event, LineNoise, Received, Receiving, Transmit, Written

log = logging.getLogger(__name__)

SPIN_LIMIT: Final = 0.001  # s: shorter waits are spent watching the port, longer ones slept
MAX_SHORT_WAITS: Final = 8  # short waits in one step before the loop gets its turn back
LATE_TIMER: Final = 0.005  # s: a reply deadline's timer this late means the loop stood still
MAX_POSTPONE: Final = 0.25  # s: the longest a late reply deadline is postponed at once
MAX_POSTPONES: Final = 3  # postponements of one reply deadline (the loop late every time)
_TELEGRAMS: Final = (DataTelegram, ShortAck, TokenTelegram)


class Engine(Protocol):
    def step(self, now: float, event: Event | None = None) -> Sequence[Any]: ...

    def next_deadline(self) -> float | None: ...


class LineDriver:
    """Glue between one engine and one link (see the module docstring)."""

    def __init__(
        self,
        engine: Engine,
        link: SerialLink,
        on_action: Callable[[Any], None] = lambda action: None,
        on_noise: Callable[[LineNoise], None] = lambda noise: None,
        on_stepped: Callable[[], None] = lambda: None,
    ) -> None:
        self.engine = engine
        self.link = link
        self.loop = link.loop
        self.on_action = on_action
        self.on_noise = on_noise
        self.on_stepped = on_stepped
        self.decoder = TelegramDecoder()
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        self._delayed: asyncio.TimerHandle | None = None
        self._stepping = False
        self._queued: deque[Event | None] = deque()
        self._postponed_for: float | None = None
        self._postpones = 0
        self.postponed = 0  # reply deadlines judged later because their timer ran late
        self._stopped = False
        link.on_data = self._on_data

    def start(self) -> None:
        self.poke()

    def stop(self) -> None:
        """No more stepping (the link stays open: the caller closes it)."""
        self._stopped = True
        for handle in (self._timer, self._delayed):
            if handle is not None:
                handle.cancel()
        self._timer = self._delayed = None

    def poke(self) -> None:
        """Step the engine now (after a command: new outputs, a DP-V1 job...)."""
        self._step(None)

    # ------------------------------------------------------------------ stepping

    def _step(self, event: Event | None) -> None:
        if self._stopped:
            return
        if self._stepping:  # from inside a step (a callback, bytes read in a short wait)
            self._queued.append(event)
            return
        self._stepping = True
        try:
            self._queued.append(event)
            self._drain()
            waits = 0
            while waits < MAX_SHORT_WAITS and self._short_wait():
                waits += 1
                self._drain()
        finally:
            self._stepping = False
        self._arm()
        self.on_stepped()

    def _drain(self) -> None:
        while self._queued and not self._stopped:
            self._run(self.engine.step(self.loop.time(), self._queued.popleft()))

    def _short_wait(self) -> bool:
        """Wait for a deadline closer than SPIN_LIMIT on the port itself; True if it came
        (or bytes did, read and queued meanwhile) and the engine wants stepping again."""
        if self._stopped:
            return False
        deadline = self.engine.next_deadline()
        if deadline is None or deadline - self.loop.time() > SPIN_LIMIT:
            return False
        if self.link.wait_readable(deadline - self.loop.time()):
            self.link.read_now()  # -> _on_data -> queued events
        if not self._queued:
            self._queued.append(None)
        return True

    def _run(self, actions: Sequence[Any]) -> None:
        """Requests first, then the other actions in their order.

        What a request carries was fixed by the engine when it built it, so nothing a
        handler does can change it; the line must not wait while the adapter decodes a
        reply's inputs and updates the hub (the master's turnaround).
        """
        others: list[Any] = []
        todo = deque(actions)
        while todo:
            action = todo.popleft()
            if not isinstance(action, Transmit):
                others.append(action)
                continue
            at = self._transmit(action)
            if at is not None:  # confirmed at once: what the engine does next comes first
                todo.extend(self.engine.step(self.loop.time(), Written(at)))
        for action in others:
            try:
                self.on_action(action)
            except Exception:  # a profile bug must not stop the line
                log.exception("handling %r failed", action)

    def _arm(self) -> None:
        """A timer for the engine's next deadline.

        A timer already armed for an earlier time is kept: it fires early, the step finds
        nothing due and arms again. The deadline of a request moves on with every message,
        so this saves a timer per message; a later deadline is rescheduled only when due.
        """
        if self._stopped:
            return
        deadline = self.engine.next_deadline()
        if deadline is None:
            return  # nothing due: an armed timer only causes one idle step
        if self._timer is not None and self._timer_at is not None and self._timer_at <= deadline:
            return
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = deadline
        self._timer = self.loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        armed = self._timer_at
        self._timer = None
        self._timer_at = None
        if armed is not None and self._postpone(armed):
            return
        self._step(None)

    def _postpone(self, armed: float) -> bool:
        """A reply deadline whose timer ran late (the loop did not run meanwhile) is judged
        as much later, at most :data:`MAX_POSTPONES` times: a slave simulated on the same
        loop, and the pty between, could not answer while the loop stood still. (On a real
        line the reply is in the port by then and read first: the loop runs its I/O
        callbacks before its timers.)"""
        deadline = self.engine.next_deadline()
        awaiting = getattr(self.engine, "awaiting_reply", None)
        if deadline is None or not callable(awaiting) or not awaiting():
            return False
        if deadline != self._postponed_for:
            self._postponed_for, self._postpones = deadline, 0
        lag = self.loop.time() - max(armed, deadline)
        if lag <= LATE_TIMER or self._postpones >= MAX_POSTPONES:
            return False
        self._postpones += 1
        self.postponed += 1
        self._timer_at = self.loop.time() + min(lag, MAX_POSTPONE)
        self._timer = self.loop.call_at(self._timer_at, self._on_timer)
        return True

    # ------------------------------------------------------------------ receiving

    def _on_data(self, data: bytes, now: float) -> None:
        telegram = self.decoder.whole(data)
        if telegram is not None:
            self._step(Received(telegram))
            return
        self.decoder.feed(data)
        for event in self._events():
            self._step(event)
        if self.decoder.buffered:
            self._step(Receiving())

    def _events(self) -> list[Event]:
        out: list[Event] = []
        while True:
            item = self.decoder.next_frame()
            if isinstance(item, NeedMore):
                return out
            if isinstance(item, Discarded):
                out.append(LineNoise(item.error))
            elif isinstance(item, _TELEGRAMS):
                out.append(Received(item))

    # ------------------------------------------------------------------ sending

    def _transmit(self, action: Transmit) -> float | None:
        """Write ``action`` when due; the time it was written, or None if it waits for a
        timer (confirmed to the engine from there)."""
        # 1.1: the line was idle before this request; nothing before it is a telegram
        self.decoder.mark_idle()
        if self.decoder.buffered:
            for event in self._events():
                if isinstance(event, LineNoise):
                    self.on_noise(event)
        wait = action.not_before - self.loop.time()
        if wait > SPIN_LIMIT:
            self._delayed = self.loop.call_at(action.not_before, self._write, action.data)
            return None
        while time.monotonic() < action.not_before:  # the loop's clock is time.monotonic
            pass
        self.link.write(action.data)
        return self.loop.time()

    def _write(self, data: bytes) -> None:
        self._delayed = None
        if self._stopped:
            return
        self.link.write(data)
        self._step(Written(self.loop.time()))  # the time it really went, however late
