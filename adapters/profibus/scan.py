"""The live-list scan: an FDL status request to each address of a range (sans-IO).

Fact sheet 1.2 (``10 DA SA 49 FCS 16``) and 1.3 (the reply's FC carries the station type).
Used by ``drive-gateway profibus scan``; the master engine probes the live list of a running
line itself, one address at a time.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from .events import Event, LineNoise, Received, Transmit, Written
from .fdl import DataTelegram, RequestFc, RequestFunction, ResponseFc, StationType
from .linestats import LineStats
from .timing import BusParams


def status_request(address: int, master: int) -> bytes:
    """FDL status request ``10 DA SA 49 FCS 16`` (fact sheet 1.2 example)."""
    return DataTelegram(address, master, RequestFc(RequestFunction.FDL_STATUS)).encode()


@dataclass
class _Probe:
    address: int
    data: bytes
    tries: int = 0
    deadline: float = 0.0
    written: bool = False  # confirmed by Written: the reply wait counts from there


class Scanner:
    """FDL status requests to each address in turn (sans-IO, like the master).

    ``step(now, event) -> [Transmit]`` until :attr:`done`. Each address gets
    ``1 + retries`` tries, each waited for from the time the driver confirms it was written
    (:class:`Written`, as in the master); :attr:`found` maps the addresses that answered
    to the station type in their reply's FC (fact sheet 1.3).
    """

    def __init__(self, bus: BusParams, addresses: Iterable[int], now: float = 0.0) -> None:
        self.bus = bus
        self._todo = deque(a for a in addresses if a != bus.master_address)
        self.found: dict[int, StationType] = {}
        self.stats = LineStats()
        self._probe: _Probe | None = None
        self._idle_since = now - bus.tsyn

    @property
    def done(self) -> bool:
        return self._probe is None and not self._todo

    def next_deadline(self) -> float | None:
        probe = self._probe
        return probe.deadline if probe is not None and probe.written else None

    def awaiting_reply(self) -> bool:
        return self._probe is not None and self._probe.written

    def step(self, now: float, event: Event | None = None) -> list[Transmit]:
        out: list[Transmit] = []
        probe = self._probe
        if isinstance(event, Written):
            if probe is not None and not probe.written:
                probe.written = True
                end = event.at + self.bus.tx_time(len(probe.data))
                probe.deadline = end + self.bus.reply_wait
                self._idle_since = max(self._idle_since, end)
            return out
        if event is not None:  # 1.1: any byte received restarts the idle time
            self._idle_since = max(self._idle_since, now)
        if probe is not None and not probe.written:
            return out
        if probe is not None and isinstance(event, Received):
            t = event.telegram
            if isinstance(t, DataTelegram) and not t.is_request and t.sa == probe.address:
                if isinstance(t.fc, ResponseFc):
                    self.found[probe.address] = t.fc.station_type
                self._probe = None
                self._idle_since = now
        elif probe is not None and isinstance(event, LineNoise):
            self.stats.framing_errors += 1
            probe.deadline = max(probe.deadline, now + self.bus.reply_wait)
        probe = self._probe
        if probe is not None and now >= probe.deadline:
            self._probe = None
            self._idle_since = now
            if probe.tries < 1 + self.bus.retries:
                self.stats.retries += 1
                self._send(probe, now, out)
            else:
                self.stats.timeouts += 1
        if self._probe is None and self._todo:
            address = self._todo.popleft()
            self._send(_Probe(address, status_request(address, self.bus.master_address)), now, out)
        return out

    def _send(self, probe: _Probe, now: float, out: list[Transmit]) -> None:
        not_before = max(now, self._idle_since + self.bus.tsyn)
        probe.tries += 1
        probe.written = False
        self._probe = probe
        self.stats.telegrams += 1
        out.append(Transmit(probe.data, not_before, True))
