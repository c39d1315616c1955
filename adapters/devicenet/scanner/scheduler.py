"""The scanner's scheduler: the poll cycle and the windows that bound the line's load.

- the poll cycle: every ``poll_interval`` each polled node online gets its output, at
  most ``poll_window`` polls in flight at once, each answered within ``response_timeout``;
- the explicit window: at most ``explicit_window`` explicit requests in flight on the line,
  first come, first served: a request goes out before those queued after it, for any node
  (in the nodes' order, the lowest MACs took every freed place on a busy line and a
  bring-up of the highest ones waited until its explicit connection timed out);
- the bring-up window: at most ``bringup_window`` nodes allocating or configuring at once.
"""

from __future__ import annotations

from collections import deque
from itertools import islice
from typing import Final

from adapters.can.bits import frame_bits_min
from adapters.devicenet.scanner.context import LineContext
from adapters.devicenet.scanner.events import IoKind
from adapters.devicenet.scanner.node import EXPLICIT_PHASES, Node, Phase

_BRINGUP_PHASES = (Phase.ALLOCATING, Phase.CONFIGURING)  # counted in bringup_window

# Receive hold (Scanner.hold_until): never longer than this after the pass that asks
# (docs/devices.md, "DeviceNet timing": what it may delay is bounded by it).
HOLD_MAX: Final = 0.003  # s


class Scheduler:
    """When polls, explicit requests and bring-ups may go out."""

    def __init__(self, ctx: LineContext) -> None:
        self.ctx = ctx
        self.poll_queue: deque[int] = deque()
        self.in_flight: dict[int, float] = {}
        self.explicit_busy: set[int] = set()  # nodes with an explicit request in flight
        self.in_bringup = 0  # nodes in bring-up now, kept by enter()
        self.online = 0  # nodes online now, kept by enter()
        self.bringing = 0  # nodes in bring-up at the step's start, plus those it started
        self.cycle_started: float | None = None
        self.cycle_due = 0.0
        # every node's explicit queue (the scan list is fixed): the window's counts, a hold
        self.queues = [n.queue for n in ctx.nodes.values()]

    # ------------------------------------------------------------ bring-up window

    def enter(self, node: Node, phase: Phase) -> None:
        """A node's new phase; every change of phase goes through here, so that the count
        of nodes in bring-up is kept (not counted over the line for every frame)."""
        self.in_bringup += (phase in _BRINGUP_PHASES) - (node.phase in _BRINGUP_PHASES)
        self.online += (phase is Phase.ONLINE) - (node.phase is Phase.ONLINE)
        if phase is not node.phase:  # a new phase: every input reported until told again
            node.quiet, node.last_inputs = False, None
        node.phase = phase

    def bringups(self) -> int:
        """The nodes allocating or configuring now."""
        return self.in_bringup

    def bringup_free(self) -> bool:
        """Whether another node may start its bring-up (``bringup_window``)."""
        return self.bringing < self.ctx.config.bringup_window

    # ------------------------------------------------------------ explicit window

    def explicit_free(self) -> bool:
        """Whether another explicit request may go out (``explicit_window``)."""
        return len(self.explicit_busy) < self.ctx.config.explicit_window

    def explicit_turn(self, node: Node) -> bool:
        """Whether the next request queued for ``node`` may go out now: the window has a
        place for it after every request queued before it for another node and waiting
        for the window (:attr:`Pending.order`), so each waits only for those ahead of it
        (``Scanner.explicit_turns_ahead``). The node must have a request queued."""
        free = self.ctx.config.explicit_window - len(self.explicit_busy)
        if free <= 0:
            return False
        if free >= sum(map(bool, self.queues)):  # fewer others queued than places: no count
            return True
        mine = node.queue[0].order
        for other in self.ctx.nodes.values():
            queue = other.queue
            if (
                queue
                and queue[0].order < mine
                and other.current is None
                and other.phase in EXPLICIT_PHASES
            ):
                free -= 1
                if not free:
                    return False
        return True

    def explicit_started(self, mac: int) -> None:
        self.explicit_busy.add(mac)

    def explicit_ended(self, mac: int) -> None:
        """A node's explicit request is over; a node waiting for the window may go."""
        full = not self.explicit_free()
        self.explicit_busy.discard(mac)
        if full:
            self.ctx.wake()  # the next step ticks every waiting node

    # ------------------------------------------------------------ poll cycle

    def any_polled_online(self) -> bool:
        return any(
            n.phase is Phase.ONLINE and n.cfg.io is IoKind.POLLED for n in self.ctx.nodes.values()
        )

    def polls(self, now: float) -> None:
        """Poll timeouts, the start of a cycle when due, and the polls the window allows."""
        ctx = self.ctx
        timeout = ctx.config.response_timeout
        in_flight = self.in_flight
        while in_flight:  # oldest first (sent in this order): the timed out ones lead
            mac = next(iter(in_flight))
            if now < in_flight[mac] + timeout:
                break
            del in_flight[mac]
            ctx.nodes[mac].figures.poll_timeouts += 1
        if self.cycle_started is None and now >= self.cycle_due and ctx.tx_ok(now):
            self.cycle_due = now + ctx.config.poll_interval
            macs = [
                m
                for m, n in ctx.nodes.items()
                if n.phase is Phase.ONLINE and n.cfg.io is IoKind.POLLED
            ]
            if macs:
                self.cycle_started = now
                self.poll_queue = deque(macs)
        while self.poll_queue and len(self.in_flight) < ctx.config.poll_window and ctx.tx_ok(now):
            node = ctx.nodes[self.poll_queue.popleft()]
            if node.phase is Phase.ONLINE:
                ctx.send_poll(node)
                node.poll_open = True
                self.in_flight.pop(node.mac, None)  # (never there: kept in send order)
                self.in_flight[node.mac] = now
        if self.cycle_started is not None and not self.poll_queue and not self.in_flight:
            self._cycle_done(now - self.cycle_started)
            self.cycle_started = None

    def _cycle_done(self, seconds: float) -> None:
        f = self.ctx.figures
        f.cycles += 1
        f.cycle_last = seconds
        f.cycle_sum += seconds
        f.cycle_max = max(f.cycle_max, seconds)

    def answered(self, mac: int) -> float | None:
        """A poll response came: when its poll was sent (None: no poll in flight)."""
        return self.in_flight.pop(mac, None)

    def forget(self, mac: int) -> None:
        """The node went offline: its poll in flight no longer matters."""
        self.in_flight.pop(mac, None)

    def stop(self) -> None:
        """Leaving the line: polls are over, their timeouts no longer matter."""
        self.in_flight.clear()

    # ------------------------------------------------------------ receive hold

    def hold_until(self, now: float) -> float | None:
        """The earliest time the first half (``ceil(poll_window / 2)``) of the polls in
        flight can have been answered, never more than :data:`HOLD_MAX` after ``now``;
        None when no poll is in flight, the bit rate is unknown or that time has passed,
        and at the end of a cycle: with no poll left to send in it, the next cycle
        starts when the last response is stepped, and a hold would leave the line idle
        until then (measured: the plant's cycle was 4-6 % longer with such holds).

        ``now`` is a pass of the driver, which has just stepped every frame received, so
        none of the polls in flight had its response received then. Two lower bounds,
        the later one taken, from the polls' frames at least :func:`frame_bits_min` bit
        times each on the one bus, one after the other:

        - from when they were sent: the first half's request and response frames all
          follow the oldest request (``in_flight`` keeps the send order);
        - from now: their responses are still to come, all but one (which may be on the
          wire already) wholly after now.

        Meanwhile the other half of the window keeps the line busy."""
        in_flight = self.in_flight
        bitrate = self.ctx.config.bitrate
        if not in_flight or not self.poll_queue or bitrate <= 0:
            return None  # the cycle's last polls: its end (and the next cycle) waits on them
        half = (self.ctx.config.poll_window + 1) // 2
        nodes = self.ctx.nodes
        first = now
        sent_bits = answer_bits = last = 0
        for mac, sent in islice(in_flight.items(), half):
            if not sent_bits:
                first = sent
            node = nodes[mac]
            last = frame_bits_min(node.cfg.produced_size)
            sent_bits += frame_bits_min(len(node.output)) + last
            answer_bits += last
        until = max(first + sent_bits / bitrate, now + (answer_bits - last) / bitrate)
        if until <= now:
            return None
        return until if until < now + HOLD_MAX else now + HOLD_MAX

    # ------------------------------------------------------------ deadlines

    def deadlines(self) -> list[float]:
        """The poll timeouts and the next cycle (the full recomputation)."""
        ctx = self.ctx
        times = [sent + ctx.config.response_timeout for sent in self.in_flight.values()]
        if self.cycle_started is None and not ctx.leaving and self.any_polled_online():
            times.append(ctx.gated(self.cycle_due))
        return times

    def after_frame(self, now: float) -> None:
        """After a received frame: the polls it allows, and their deadlines folded in."""
        ctx = self.ctx
        self.polls(now)
        in_flight = self.in_flight
        if in_flight:  # the oldest poll's timeout is the soonest of them
            ctx.fold((in_flight[next(iter(in_flight))] + ctx.config.response_timeout,))
        if self.cycle_started is None:
            ctx.fold((ctx.gated(self.cycle_due),))
