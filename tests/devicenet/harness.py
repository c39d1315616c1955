"""A DeviceNet line without I/O: the scanner engine and simulated CFW-08 nodes on an
ideal bus (zero latency, every frame to the scanner and to the nodes of the MAC in its
identifier), stepped with a fake clock.

``bus_down`` makes the line fail as a SocketCAN interface that is off or full does: every
send of the scanner fails (a TxFailed event, as the link reports it) and nothing is
delivered. ``timer_steps`` counts the scanner's timer steps and ``late_deadlines``
records every timer step after which the scanner asked to be stepped again at once
(a busy loop in a real event loop)."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from typing import Any

from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import match_predefined
from adapters.devicenet.scanner import (
    Action,
    FrameIn,
    InputData,
    NodeConfig,
    Scanner,
    ScannerConfig,
    Send,
    TxFailed,
)
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig

MIN_STEP = 1e-4


class Line:
    def __init__(
        self,
        scanner: ScannerConfig,
        nodes: Iterable[NodeConfig],
        sims: Iterable[SimNodeConfig],
        *,
        outputs: dict[int, bytes] | None = None,
    ) -> None:
        self.now = 0.0
        self.scanner = Scanner(scanner, nodes)
        self.sims: dict[int, Cfw08Node] = {}
        self.extra: list[Cfw08Node] = []  # nodes sharing a MAC with another (duplicate tests)
        for cfg in sims:
            node = Cfw08Node(cfg)
            if cfg.mac in self.sims:
                self.extra.append(node)
            else:
                self.sims[cfg.mac] = node
        self.actions: list[Action] = []
        self.frames: list[tuple[float, str, CanFrame]] = []
        self._pending: deque[tuple[object, CanFrame]] = deque()
        self.outputs = outputs or {}
        self.scanner_enabled = True
        self.bus_down = False
        self.timer_steps = 0
        self.late_deadlines: list[tuple[float, float]] = []

    @property
    def stations(self) -> list[Cfw08Node]:
        return [*self.sims.values(), *self.extra]

    def power_on(self, node: Cfw08Node | None = None) -> None:
        for n in [node] if node is not None else self.stations:
            for frame in n.power_on(self.now):
                self._pending.append((n, frame))

    def leave(self) -> None:
        """The scanner's shutdown: its Releases go on the line like any other frame."""
        self._scanner_actions(self.scanner.leave(self.now))

    def _scanner_actions(self, actions: list[Action]) -> None:
        sends = [a.frame for a in actions if isinstance(a, Send)]
        self.actions.extend(a for a in actions if not isinstance(a, Send))
        if sends and self.bus_down:
            failed = TxFailed("Transmit buffer full", dropped=len(sends))
            self._scanner_actions(self.scanner.step(self.now, failed))
            return
        self._pending.extend((self.scanner, frame) for frame in sends)

    def _flush(self) -> None:
        if self.bus_down:
            self._pending.clear()
        while self._pending:
            sender, frame = self._pending.popleft()
            self.frames.append((self.now, "scanner" if sender is self.scanner else "node", frame))
            if sender is not self.scanner and self.scanner_enabled:
                self._scanner_actions(self.scanner.step(self.now, FrameIn(frame)))
            found = match_predefined(frame.arbitration_id)
            for node in self.stations:  # a station only listens to its own MAC's identifiers
                if node is not sender and found is not None and node.mac == found.mac:
                    for out in node.step(self.now, frame):
                        self._pending.append((node, out))

    def _deadlines(self) -> list[float]:
        times = [n.next_deadline() for n in self.stations]
        if self.scanner_enabled:
            times.append(self.scanner.next_deadline())
        return [t for t in times if t is not None]

    def _step_due(self) -> None:
        for mac, data in self.outputs.items():
            if mac in self.scanner.nodes:
                self.scanner.set_output(mac, data)
        if self.scanner_enabled:
            self.timer_steps += 1
            self._scanner_actions(self.scanner.step(self.now))
            deadline = self.scanner.next_deadline()
            if deadline is not None and deadline <= self.now:
                self.late_deadlines.append((self.now, deadline))
        for node in self.stations:
            deadline = node.next_deadline()
            if deadline is not None and deadline <= self.now:
                for out in node.step(self.now):
                    self._pending.append((node, out))

    def run(self, duration: float) -> None:
        end = self.now + duration
        self._flush()
        while True:
            self._step_due()
            self._flush()
            upcoming = [t for t in self._deadlines() if t > self.now]
            nxt = min(upcoming, default=end)
            if any(t <= self.now for t in self._deadlines()):
                nxt = min(nxt, self.now + MIN_STEP)
            if nxt >= end:
                self.now = end
                self._step_due()
                self._flush()
                return
            self.now = nxt

    def take(self, kind: type) -> list[Any]:
        found = [a for a in self.actions if isinstance(a, kind)]
        self.actions = [a for a in self.actions if not isinstance(a, kind)]
        return found

    def inputs(self, mac: int) -> list[bytes]:
        return [a.data for a in self.actions if isinstance(a, InputData) and a.mac == mac]
