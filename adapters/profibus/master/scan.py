"""The live-list scan: an FDL status request to each address of a range (sans-IO).

Fact sheet 1.2 (``10 DA SA 49 FCS 16``) and 1.3 (the reply's FC carries the station type).
A station that answers as a slave is then asked for its diagnosis (1.8: bytes 4-5 are its
Ident_Number, byte 3 the master that holds it) and its configuration (Get_Cfg, 1.7), both
read-only services that change nothing in the slave. Used by ``drive-gateway profibus
scan``; the master engine probes the live list of a running line itself.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from adapters.profibus.codec.diag import SlaveDiag
from adapters.profibus.codec.dp import GetCfgRequest, SlaveDiagRequest, SlaveSap, build_request
from adapters.profibus.codec.fdl import (
    DataTelegram,
    FcbState,
    RequestFc,
    RequestFunction,
    ResponseFc,
    StationType,
)
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.master.events import Event, FrameIn, LineNoise, Transmit, Written
from adapters.profibus.master.figures import LineFigures
from adapters.profibus.master.timing import BusParams


def status_request(address: int, master: int) -> bytes:
    """FDL status request ``10 DA SA 49 FCS 16`` (fact sheet 1.2 example)."""
    return DataTelegram(address, master, RequestFc(RequestFunction.FDL_STATUS)).encode()


def diag_request(address: int, master: int) -> bytes:
    """Slave_Diag request to SAP 60 (1.4, 1.8), the first SRD after a restart (FCB 1, FCV 0)."""
    fc = FcbState.reset().fc(RequestFunction.SRD_HIGH)
    return build_request(SlaveDiagRequest(), da=address, sa=master, fc=fc).encode()


def get_cfg_request(address: int, master: int) -> bytes:
    """Get_Cfg request to SAP 59 (1.4, 1.7)."""
    fc = FcbState.reset().fc(RequestFunction.SRD_HIGH)
    return build_request(GetCfgRequest(), da=address, sa=master, fc=fc).encode()


@dataclass
class _Probe:
    address: int
    data: bytes
    kind: str = "status"  # "status", "diag", "cfg"
    tries: int = 0
    deadline: float = 0.0
    written: bool = False  # confirmed by Written: the reply wait counts from there


@dataclass(frozen=True)
class SlaveInfo:
    """What a slave's diagnosis and Get_Cfg said (None: it did not answer that)."""

    ident_number: int | None = None
    master_address: int | None = None  # 255: no master holds it
    cfg: bytes | None = None


class Scanner:
    """FDL status requests to each address in turn (sans-IO, like the master).

    ``step(now, event) -> [Transmit]`` until :attr:`done`. Each address gets
    ``1 + retries`` tries, each waited for from the time the driver confirms it was written
    (:class:`Written`, as in the master); :attr:`found` maps the addresses that answered to
    the station type in their reply's FC (fact sheet 1.3); :attr:`slaves` what each slave's
    diagnosis and Get_Cfg said (with ``identify``). :attr:`probed` counts the addresses done.
    """

    def __init__(
        self, bus: BusParams, addresses: Iterable[int], now: float = 0.0, *, identify: bool = True
    ) -> None:
        self.bus = bus
        self._todo: deque[_Probe] = deque(
            _Probe(a, status_request(a, bus.master_address))
            for a in addresses
            if a != bus.master_address
        )
        self.total = len(self._todo)
        self.probed = 0
        self.identify = identify
        self.found: dict[int, StationType] = {}
        self.slaves: dict[int, SlaveInfo] = {}
        self.figures = LineFigures()
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
        if probe is not None and isinstance(event, FrameIn):
            t = event.telegram
            if isinstance(t, DataTelegram) and not t.is_request and t.sa == probe.address:
                self._answered(probe, t)
                self._probe = None
                self._idle_since = now
        elif probe is not None and isinstance(event, LineNoise):
            self.figures.framing_errors += 1
            probe.deadline = max(probe.deadline, now + self.bus.reply_wait)
        probe = self._probe
        if probe is not None and now >= probe.deadline:
            self._probe = None
            self._idle_since = now
            if probe.tries < 1 + self.bus.retries:
                self.figures.retries += 1
                self._send(probe, now, out)
            else:
                self.figures.timeouts += 1
                self._finished(probe)
        if self._probe is None and self._todo:
            self._send(self._todo.popleft(), now, out)
        return out

    def _answered(self, probe: _Probe, t: DataTelegram) -> None:
        if probe.kind == "status":
            if isinstance(t.fc, ResponseFc):
                self.found[probe.address] = t.fc.station_type
                if t.fc.station_type is StationType.SLAVE and self.identify:
                    master = self.bus.master_address
                    self._todo.appendleft(
                        _Probe(probe.address, get_cfg_request(probe.address, master), "cfg")
                    )
                    self._todo.appendleft(
                        _Probe(probe.address, diag_request(probe.address, master), "diag")
                    )
            self._finished(probe)
            return
        info = self.slaves.get(probe.address, SlaveInfo())
        if probe.kind == "diag" and t.ssap == SlaveSap.SLAVE_DIAG:
            try:
                diag = SlaveDiag.decode(t.data)
            except ProfibusDecodeError:
                return
            info = SlaveInfo(diag.ident_number, diag.master_address, info.cfg)
        elif probe.kind == "cfg" and t.ssap == SlaveSap.GET_CFG:
            info = SlaveInfo(info.ident_number, info.master_address, bytes(t.data))
        self.slaves[probe.address] = info

    def _finished(self, probe: _Probe) -> None:
        if probe.kind == "status":
            self.probed += 1

    def _send(self, probe: _Probe, now: float, out: list[Transmit]) -> None:
        not_before = max(now, self._idle_since + self.bus.tsyn)
        probe.tries += 1
        probe.written = False
        self._probe = probe
        self.figures.telegrams += 1
        out.append(Transmit(probe.data, not_before, True))
