"""A generic DP slave (sans-IO): the FDL responder and the slave state machine around a device.

Written from the fact sheet (``reference/protocol-facts.md``): 1.2/1.3 telegrams, FC and
FCB (a repeated FCB gets the previous reply again), 1.4 SAPs, 1.5 slave states Wait_Prm ->
Wait_Cfg -> Data_Exch, 1.6 Set_Prm (lock, watchdog, group), 1.7 Chk_Cfg/Get_Cfg, 1.8
Slave_Diag with the flags a real slave sets, 1.9 Global_Control, 1.10 DP-V1 on SAP 51 (the
request is acknowledged with E5, polls get E5 until the answer is ready, then DL with it).

The device behind it is any :class:`adapters.profibus.contract.SimDevice`; the hooks it may
leave to :class:`adapters.profibus.contract.SimDeviceBase`: ``dpv1`` (False: Set_Prm without
the DP-V1 status bytes, SAP 51 inactive), ``check_cfg(cfg) -> bool`` (Chk_Cfg),
``handles_clear`` and ``clear_mode(now, active)`` (Global_Control Clear and the Operate after
it; by default a Clear is ``comm_lost``), ``global_control(control, now)`` (every Global_Control:
Sync, Freeze, the MCD 600's quick stop on Clear), ``alerts(ext)`` (whether the current
extended diagnosis is worth a DH reply), ``faults`` (a :class:`gateway.sim.FaultInjector`
whose drop/delay/noise apply to this slave's replies).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Final

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.chkcfg import Configuration
from adapters.profibus.codec.diag import NO_MASTER, SlaveDiag
from adapters.profibus.codec.dp import GlobalControl, SetPrm, SlaveSap
from adapters.profibus.codec.fdl import (
    BROADCAST,
    SHORT_ACK,
    DataTelegram,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    ShortAck,
    SlaveFcbMemory,
)
from adapters.profibus.contract import RecordAccessError, SimDevice
from adapters.profibus.errors import ProfibusDecodeError
from gateway.sim import FaultInjector

log = logging.getLogger(__name__)

Reply = DataTelegram | ShortAck

_SRD: Final = frozenset({RequestFunction.SRD_HIGH, RequestFunction.SRD_LOW})
GLOBAL_CONTROLS_KEPT: Final = 256  # Global_Control telegrams a slave's counters remember


class SlaveMode(Enum):
    """The slave's states (fact sheet 1.5, VPC3 WAIT_PRM, WAIT_CFG, DATA_EX)."""

    WAIT_PRM = "wait_prm"
    WAIT_CFG = "wait_cfg"
    DATA_EXCH = "data_exch"


@dataclass
class SlaveFaults:
    """Faults of the slave itself (line noise and lost replies are the line's business)."""

    wrong_cfg: bytes | None = None  # the slave has this configuration: Chk_Cfg -> Cfg_Fault
    prm_req_forever: bool = False  # takes Set_Prm, then asks for parameters again
    silent: bool = False  # answers nothing (a missing or dead station)
    record_delay: float = 0.0  # s before a DP-V1 answer is ready (polls get E5 meanwhile)
    dpv1_silent: bool = False  # answers no MSAC_C1 telegram (Data_Exchange still answered)
    not_ready: bool = False  # Station_Not_Ready in every diagnosis (its application is down)
    stat_diag: bool = False  # Stat_Diag in every diagnosis: "keep reading it" (1.8 Status_2)


@dataclass
class SlaveCounters:
    """What the slave saw (tests look at these)."""

    requests: int = 0
    repeats: int = 0  # FCB repeats answered with the previous reply
    set_prm: int = 0
    chk_cfg: int = 0
    exchanges: int = 0
    diag_reads: int = 0
    records: int = 0
    # the last GLOBAL_CONTROLS_KEPT only: Operate comes every 50 x TSL, for ever
    global_controls: deque[GlobalControl] = field(
        default_factory=lambda: deque(maxlen=GLOBAL_CONTROLS_KEPT)
    )
    clears: int = 0  # Global_Control Clear received in data exchange
    comm_lost: int = 0  # watchdog expiries and Clears passed to the device
    power_cycles: int = 0
    watchers: list[Callable[[], None]] = field(default_factory=list, repr=False, compare=False)
    """Called after each telegram the slave took (a test awaits a count with them)."""

    def heard(self) -> None:
        for watcher in tuple(self.watchers):
            watcher()


class DpSlave:
    """One simulated DP slave at ``address`` hosting ``device``."""

    def __init__(self, address: int, device: SimDevice, baudrate: int | None = None) -> None:
        """``baudrate``: the line's (bit/s), which the slave detects and gives its device at
        each Set_Prm; None: not known (a test's line)."""
        self.address = address
        self.device = device
        self.baudrate = baudrate
        self.dpv1: bool = device.dpv1
        self.injector = device.faults if device.faults is not None else FaultInjector()
        self.faults = SlaveFaults()
        self.counters = SlaveCounters()
        self.off_until = -math.inf
        self._reset_bus_state()

    def _reset_bus_state(self) -> None:
        self.mode = SlaveMode.WAIT_PRM
        self.master: int | None = None
        self.watchdog: float | None = None
        self.group = 0
        self.prm_fault = False
        self.cfg_fault = False
        self.clear = False
        self.sync = False
        self.freeze = False
        self.dpv1_active = self.dpv1
        self.last_contact = 0.0
        self.output_len = 0
        self.last_outputs = b""
        self.last_inputs = b""
        self._fcb = SlaveFcbMemory()
        self._last_reply: Reply | None = None
        self._diag_delivered = b""
        self._acyclic: bytes | None = None
        self._acyclic_ready = 0.0

    # ------------------------------------------------------------------ views

    @property
    def expected_cfg(self) -> bytes:
        if self.faults.wrong_cfg is not None:
            return self.faults.wrong_cfg
        return self.device.expected_cfg()

    # ------------------------------------------------------------------ time

    def tick(self, now: float) -> None:
        """Device physics and the DP watchdog (1.6: T_WD after the last master telegram)."""
        if now < self.off_until:
            return
        self.device.tick(now)
        if (
            self.watchdog is not None
            and self.mode is not SlaveMode.WAIT_PRM
            and now - self.last_contact > self.watchdog
        ):
            log.info("sim slave %d: watchdog expired", self.address)
            if self.mode is SlaveMode.DATA_EXCH:
                self._comm_lost(now)
            self.mode = SlaveMode.WAIT_PRM
            self.master = None

    def stood_still(self, seconds: float) -> None:
        """The simulator's process stood still ``seconds``: the watchdog does not count it."""
        self.last_contact += seconds

    def power_cycle(self, now: float, off_time: float = 0.0) -> None:
        """Power off for ``off_time`` s (silent), then back in Wait_Prm (parameters kept)."""
        self.device.power_cycle(now)
        self.counters.power_cycles += 1
        self._reset_bus_state()
        self.off_until = now + off_time

    def _comm_lost(self, now: float) -> None:
        self.counters.comm_lost += 1
        self.device.comm_lost(now)

    # ------------------------------------------------------------------ requests

    def handle(self, request: DataTelegram, now: float) -> Reply | None:
        """The reply to one request telegram, or None (not for us, SDN, switched off)."""
        reply = self._handle(request, now)
        if self.counters.watchers:
            self.counters.heard()
        return reply

    def _handle(self, request: DataTelegram, now: float) -> Reply | None:
        if now < self.off_until or self.faults.silent or not isinstance(request.fc, RequestFc):
            return None
        if request.da == BROADCAST or request.fc.function not in _SRD:
            if request.dsap == SlaveSap.GLOBAL_CONTROL and request.da in (BROADCAST, self.address):
                self._global_control(request, now)
            elif request.da == self.address and request.fc.function is RequestFunction.FDL_STATUS:
                return DataTelegram(request.sa, self.address, ResponseFc(ResponseStatus.OK))
            return None
        if request.da != self.address:
            return None
        self.counters.requests += 1
        if request.sa == self.master:
            self.last_contact = now
        repeat, self._fcb = self._fcb.receive(request.fc)
        if repeat and self._last_reply is not None:
            self.counters.repeats += 1  # 1.3: a retry; answer again, do not act twice
            return self._last_reply
        handler = _HANDLERS.get(request.dsap, DpSlave._unknown_sap)
        reply = handler(self, request, now)
        self._last_reply = reply
        return reply

    def _unknown_sap(self, request: DataTelegram, now: float) -> Reply:
        return request.reply(status=ResponseStatus.RS)  # 1.3: SAP not activated

    # 1.8 -----------------------------------------------------------------

    def _diagnosis(self, request: DataTelegram, now: float) -> Reply:
        self.counters.diag_reads += 1
        ext = self.device.ext_diag()
        self._diag_delivered = ext
        diag = SlaveDiag(
            ident_number=self.device.ident_number,
            station_not_ready=self.mode is not SlaveMode.DATA_EXCH or self.faults.not_ready,
            cfg_fault=self.cfg_fault,
            ext_diag=self.device.alerts(ext),
            prm_fault=self.prm_fault,
            prm_req=self.mode is SlaveMode.WAIT_PRM,
            wd_on=self.watchdog is not None,
            freeze_mode=self.freeze,
            sync_mode=self.sync,
            stat_diag=self.faults.stat_diag,
            master_address=NO_MASTER if self.master is None else self.master,
        )
        return request.reply(diag.encode() + ext)

    def _diag_waiting(self) -> bool:
        """DH in a data exchange reply: new extended diagnosis worth the master's read."""
        ext = self.device.ext_diag()
        if not ext:
            self._diag_delivered = b""
            return False
        return ext != self._diag_delivered and self.device.alerts(ext)

    # 1.6 -----------------------------------------------------------------

    def _set_prm(self, request: DataTelegram, now: float) -> Reply:
        self.counters.set_prm += 1
        if self.master is not None and request.sa != self.master:
            return SHORT_ACK  # locked to another master: ignored (diag shows Master_Add)
        try:
            prm = SetPrm.decode(request.data, dpv1=self.dpv1)
        except ProfibusDecodeError:
            return self._refuse_prm()
        if prm.ident_number != self.device.ident_number or not self.device.set_prm(
            prm.user_prm_data
        ):
            return self._refuse_prm()
        if self.mode is SlaveMode.DATA_EXCH:
            self._comm_lost(now)  # re-parameterised: it leaves data exchange
        self.prm_fault = False
        self.mode = SlaveMode.WAIT_CFG
        self.master = request.sa if prm.lock_req and not prm.unlock_req else None
        self.watchdog = prm.watchdog_time if prm.wd_on else None
        self.group = prm.group_ident
        self.dpv1_active = self.dpv1 and (prm.dpv1 is None or prm.dpv1.dpv1_enable)
        self.last_contact = now
        if self.baudrate is not None:
            self.device.baud_detected(self.baudrate)
        if self.faults.prm_req_forever:
            self.mode = SlaveMode.WAIT_PRM
        return SHORT_ACK

    def _refuse_prm(self) -> Reply:
        self.prm_fault = True
        self.mode = SlaveMode.WAIT_PRM
        return SHORT_ACK

    # 1.7 -----------------------------------------------------------------

    def _chk_cfg(self, request: DataTelegram, now: float) -> Reply:
        self.counters.chk_cfg += 1
        if self.mode is SlaveMode.WAIT_PRM or request.sa != self.master:
            return SHORT_ACK
        if self._cfg_ok(bytes(request.data)):
            self.output_len = _lengths(self.expected_cfg)[1]
            self.cfg_fault = False
            self.mode = SlaveMode.DATA_EXCH
            self.clear = False
        else:
            self.cfg_fault = True
            self.mode = SlaveMode.WAIT_PRM
        return SHORT_ACK

    def _cfg_ok(self, cfg: bytes) -> bool:
        if self.faults.wrong_cfg is not None:
            return cfg == self.faults.wrong_cfg
        return self.device.check_cfg(cfg)

    def _get_cfg(self, request: DataTelegram, now: float) -> Reply:
        return request.reply(self.expected_cfg)

    # 1.5 step 6 ----------------------------------------------------------

    def _data_exchange(self, request: DataTelegram, now: float) -> Reply:
        if self.mode is not SlaveMode.DATA_EXCH or request.sa != self.master:
            return request.reply(status=ResponseStatus.RS)
        outputs = bytes(request.data)
        if len(outputs) != self.output_len:
            return request.reply(status=ResponseStatus.RS)
        self.counters.exchanges += 1
        inputs = self.device.exchange(outputs, now)
        self.last_outputs, self.last_inputs = outputs, inputs
        status = ResponseStatus.DH if self._diag_waiting() else ResponseStatus.DL
        if not inputs and status is ResponseStatus.DL:
            return SHORT_ACK
        return request.reply(inputs, status)

    def _read_inputs(self, request: DataTelegram, now: float) -> Reply:
        return request.reply(self.last_inputs)

    def _read_outputs(self, request: DataTelegram, now: float) -> Reply:
        return request.reply(self.last_outputs)

    # 1.9 -----------------------------------------------------------------

    def _global_control(self, request: DataTelegram, now: float) -> None:
        try:
            control = GlobalControl.decode(request.data)
        except ProfibusDecodeError:
            return
        if self.mode is not SlaveMode.DATA_EXCH or request.sa != self.master:
            return
        if control.group_select and not control.group_select & self.group:
            return
        self.last_contact = now
        self.counters.global_controls.append(control)
        if control.clear_data:
            self.counters.clears += 1
            if not self.clear:
                self.clear = True
                if self.device.handles_clear:
                    self.device.clear_mode(now, True)
                else:
                    self._comm_lost(now)
        elif self.clear:
            self.clear = False
            if self.device.handles_clear:
                self.device.clear_mode(now, False)
        self.sync = (self.sync or control.sync) and not control.unsync
        self.freeze = (self.freeze or control.freeze) and not control.unfreeze
        self.device.global_control(control, now)

    # 1.10 ----------------------------------------------------------------

    def _msac_c1(self, request: DataTelegram, now: float) -> Reply | None:
        if self.faults.dpv1_silent:
            return None
        if not self.dpv1_active or self.mode is not SlaveMode.DATA_EXCH:
            return request.reply(status=ResponseStatus.RS)
        if not request.data:  # a poll
            if self._acyclic is None or now < self._acyclic_ready:
                return SHORT_ACK
            answer, self._acyclic = self._acyclic, None
            return request.reply(answer)
        self.counters.records += 1
        self._acyclic = self._record_answer(bytes(request.data), now).encode()
        self._acyclic_ready = now + self.faults.record_delay
        return SHORT_ACK

    def _record_answer(self, data: bytes, now: float) -> dpv1.Dpv1Response:
        try:
            pdu = dpv1.decode_request(data)
        except ProfibusDecodeError:
            return dpv1.Dpv1ErrorResponse(dpv1.Dpv1Function.READ, error_code_1=0xA9)
        try:
            if isinstance(pdu, dpv1.ReadRequest):
                values = self.device.read_record(pdu.slot, pdu.index, pdu.length, now)
                return dpv1.ReadResponse(pdu.slot, pdu.index, bytes(values[: pdu.length]))
            if isinstance(pdu, dpv1.WriteRequest):
                self.device.write_record(pdu.slot, pdu.index, pdu.data, now)
                length = self.device.write_answer_length(len(pdu.data))
                return dpv1.WriteResponse(pdu.slot, pdu.index, length)
        except RecordAccessError as exc:
            function = (
                dpv1.Dpv1Function.READ
                if isinstance(pdu, dpv1.ReadRequest)
                else dpv1.Dpv1Function.WRITE
            )
            return dpv1.Dpv1ErrorResponse(function, exc.error_decode, exc.code_1, exc.code_2)
        # 1.10 class A code 9: feature not supported (alarm acknowledge on SAP 51)
        return dpv1.Dpv1ErrorResponse(dpv1.Dpv1Function.READ, error_code_1=0xA9)

    def _alarm_ack(self, request: DataTelegram, now: float) -> Reply:
        if not self.dpv1_active:
            return request.reply(status=ResponseStatus.RS)
        return SHORT_ACK


def _lengths(cfg: bytes) -> tuple[int, int]:
    """(input bytes, output bytes) of a configuration (1.7)."""
    try:
        conf = Configuration.decode(cfg, allow_skip_check=True)
    except ProfibusDecodeError:
        return (0, 0)
    return conf.input_bytes, conf.output_bytes


_HANDLERS: Final[dict[int | None, Callable[[DpSlave, DataTelegram, float], Reply | None]]] = {
    None: DpSlave._data_exchange,
    SlaveSap.SLAVE_DIAG: DpSlave._diagnosis,
    SlaveSap.SET_PRM: DpSlave._set_prm,
    SlaveSap.CHK_CFG: DpSlave._chk_cfg,
    SlaveSap.GET_CFG: DpSlave._get_cfg,
    SlaveSap.RD_INP: DpSlave._read_inputs,
    SlaveSap.RD_OUTP: DpSlave._read_outputs,
    SlaveSap.MSAC_C1: DpSlave._msac_c1,
    SlaveSap.ALARM_ACK: DpSlave._alarm_ack,
}
