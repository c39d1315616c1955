"""A simulated Profibus line (sans-IO): several DP slaves behind one port, as on a real bus.

Bytes from the master go in with :meth:`SimLine.receive`; the replies come out as
:class:`Outgoing` (bytes and the time they are due). Requests are dispatched by destination
address; a broadcast (Global_Control) reaches every slave.

Fault injection: :attr:`SimLine.faults` (a seeded :class:`gateway.sim.FaultInjector`) flips
bits at ``bit_error_rate`` per byte in both directions, loses replies at ``drop_rate`` and
makes them ``delay`` s late; each slave's own injector (``DpSlave.injector``, the device's
``faults`` when it has one) does the same for that slave's replies. Slave-level faults
(power cycle, wrong configuration, Prm_Req forever, silence) are on :class:`DpSlave`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from adapters.profibus.codec.fdl import (
    DataTelegram,
    Discarded,
    NeedMore,
    TelegramDecoder,
)
from adapters.profibus.sim.slave import DpSlave
from gateway.sim import FaultInjector


@dataclass(frozen=True)
class Outgoing:
    """Bytes to put on the line at ``at`` (seconds, the caller's clock)."""

    data: bytes
    at: float


@dataclass
class LineCounters:
    requests: int = 0
    replies: int = 0
    dropped: int = 0
    garbage: int = 0  # undecodable runs received


class SimLine:
    """The slave side of one line."""

    def __init__(self, slaves: Iterable[DpSlave] = (), faults: FaultInjector | None = None) -> None:
        self.slaves: dict[int, DpSlave] = {}
        self.faults = faults if faults is not None else FaultInjector()
        self.counters = LineCounters()
        self.decoder = TelegramDecoder()
        for slave in slaves:
            self.add(slave)

    def add(self, slave: DpSlave) -> None:
        if slave.address in self.slaves:
            raise ValueError(f"two simulated slaves at address {slave.address}")
        self.slaves[slave.address] = slave

    def __getitem__(self, address: int) -> DpSlave:
        return self.slaves[address]

    def tick(self, now: float) -> None:
        for slave in self.slaves.values():
            slave.tick(now)

    def stood_still(self, seconds: float) -> None:
        """The process running the line was not scheduled for ``seconds``: no slave counts
        that time against its DP watchdog (see :mod:`.port`)."""
        for slave in self.slaves.values():
            slave.stood_still(seconds)

    def idle(self) -> None:
        """The line was quiet: a partial telegram in the buffer will never complete."""
        self.decoder.mark_idle()

    def receive(self, data: bytes, now: float) -> list[Outgoing]:
        """Bytes from the master; the replies of the addressed slaves."""
        self.decoder.feed(self.faults.corrupt(data))
        out: list[Outgoing] = []
        while True:
            event = self.decoder.next_frame()
            if isinstance(event, NeedMore):
                return out
            if isinstance(event, Discarded):
                self.counters.garbage += 1
                continue
            if isinstance(event, DataTelegram) and event.is_request:
                self._dispatch(event, now, out)

    def _dispatch(self, request: DataTelegram, now: float, out: list[Outgoing]) -> None:
        self.counters.requests += 1
        targets = self.slaves.values() if request.da == 127 else [self.slaves.get(request.da)]
        for slave in targets:
            if slave is None:
                continue
            slave.tick(now)
            reply = slave.handle(request, now)
            if reply is None:
                continue
            if self.faults.drop() or slave.injector.drop():
                self.counters.dropped += 1
                continue
            wire = slave.injector.corrupt(self.faults.corrupt(reply.encode()))
            self.counters.replies += 1
            out.append(Outgoing(wire, now + self.faults.delay + slave.injector.delay))
