"""One DP slave as the master sees it: its start-up, data exchange, loss and recovery.

Fact sheet 1.5: Slave_Diag until a valid diagnosis (WAIT_DIAG), Set_Prm, Chk_Cfg, Slave_Diag
until ready (WAIT_READY), then Data_Exchange; a refused configuration is learnt with
Get_Cfg before the fault is reported. A station that stops answering is ABSENT (probed once
per ``absent_retry``), one that refuses is in FAULT (tried again after ``fault_retry``), and
one that leaves data exchange starts up again. Each start-up state has a timeout
(:data:`STATE_TIMEOUTS`). The station decides what its replies and diagnoses mean; when it
is served is the scheduler's business (:mod:`.scheduler`), and its DP-V1 jobs are the job
queue's (:mod:`.acyclic`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Final

from adapters.profibus.codec.diag import SlaveDiag, describe_blocks
from adapters.profibus.codec.dp import (
    DataExchange,
    GetCfgRequest,
    MasterSap,
    SlaveDiagRequest,
    SlaveSap,
    build_request,
)
from adapters.profibus.codec.fdl import DataTelegram, FcbState, RequestFc, ResponseStatus
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.master.common import (
    DATA_OK,
    MAX_TURN,
    REQUEST_NAMES,
    Pending,
    Reply,
    Turn,
    show,
    status_of,
)
from adapters.profibus.master.events import (
    Action,
    DiagnosisRead,
    FaultKind,
    InputsReceived,
    Purpose,
    SlaveDown,
    SlaveFault,
    SlaveParams,
    SlaveState,
    SlaveStateChanged,
    SlaveUp,
    describe_cfg,
)
from adapters.profibus.master.figures import LineFigures, SlaveFigures
from adapters.profibus.master.timing import MAX_TELEGRAM, BusParams
from gateway.errors import FrameEncodeError

MAX_PRM_ATTEMPTS: Final = 3  # Set_Prm repeated on Prm_Req before "keeps asking"
INPUTS_REFRESH: Final = 1.0  # s: a quiet slave's unchanged inputs reported this often (0102)
FRAME_MEMO: Final = 4  # Data_Exchange telegrams kept encoded per slave (2 FCBs x outputs)

# 1.5, pyprofibus state timeouts (s): how long a start-up state may last before restarting.
STATE_TIMEOUTS: Final[Mapping[SlaveState, float]] = {
    SlaveState.WAIT_DIAG: 1.0,
    SlaveState.SET_PRM: 0.5,
    SlaveState.CHK_CFG: 0.5,
    SlaveState.WAIT_READY: 1.0,
    SlaveState.GET_CFG: 0.5,
}
# The states whose timeout the engine watches (WAIT_DIAG ends through the retries instead).
TIMED_STATES: Final = frozenset(STATE_TIMEOUTS) - {SlaveState.WAIT_DIAG}


@dataclass
class StationContext:
    """What every station of one line shares: the line's parameters and what they report to.

    ``timed`` holds the stations in a start-up state with a timeout (so that a line in
    data exchange has nothing to look at per step); ``left_exchange`` is called when a
    station leaves data exchange (its DP-V1 jobs end); ``exchange_changes`` counts the
    stations that entered or left data exchange (the scheduler's budget follows them).
    """

    bus: BusParams
    out: list[Action]
    figures: LineFigures
    left_exchange: Callable[[Station], None]
    timed: dict[int, Station] = field(default_factory=dict)
    exchange_changes: int = 0

    @property
    def master(self) -> int:
        return self.bus.master_address


class Station:
    """The state machine of one DP slave (see the module docstring)."""

    def __init__(self, params: SlaveParams, context: StationContext, now: float) -> None:
        self.params = params
        self.address = params.address
        self.context = context
        self._out = context.out  # what the station reports (the master's actions)
        self.set_prm = params.set_prm(context.bus.min_tsdr).encode()
        self.outputs = bytes(params.output_len)
        self.outputs_pending = False  # set_outputs given, no Data_Exchange built from them yet
        self.state = SlaveState.WAIT_DIAG
        self.since = now
        self.fcb = FcbState()
        self.retry_at = 0.0
        self.diag_pending = False
        self.prm_attempts = 0
        self.fault: str | None = None
        self.last_diag: SlaveDiag | None = None
        self.frames: dict[tuple[bool, bool, bytes], bytes] = {}
        # the steady case (see took_inputs): the inputs last reported and until when
        # unchanged ones need not be; quiet: the caller said unchanged inputs tell it nothing
        self.quiet = False
        self.last_inputs: bytes | None = None
        self.inputs_due = 0.0
        self.steady_reply = b""  # the bytes of the last plain Data_Exchange reply taken whole
        self.turn = Turn()
        self.figures = SlaveFigures()

    # ------------------------------------------------------------------ outputs

    def set_outputs(self, data: bytes) -> None:
        if len(data) != self.params.output_len:
            raise FrameEncodeError(
                f"slave {self.address} takes {self.params.output_len} output bytes, got {len(data)}"
            )
        self.outputs = bytes(data)
        self.outputs_pending = True

    # ------------------------------------------------------------------ telegrams

    def request(self, purpose: Purpose, fc: RequestFc) -> DataTelegram:
        """A start-up telegram: Slave_Diag, Set_Prm, Chk_Cfg or Get_Cfg."""
        return _REQUESTS[purpose](self, fc)

    def _diag_request(self, fc: RequestFc) -> DataTelegram:
        return build_request(SlaveDiagRequest(), da=self.address, sa=self.context.master, fc=fc)

    def _set_prm_request(self, fc: RequestFc) -> DataTelegram:
        return DataTelegram(
            self.address, self.context.master, fc, SlaveSap.SET_PRM, MasterSap.MS0, self.set_prm
        )

    def _chk_cfg_request(self, fc: RequestFc) -> DataTelegram:
        return DataTelegram(
            self.address, self.context.master, fc, SlaveSap.CHK_CFG, MasterSap.MS0, self.params.cfg
        )

    def _get_cfg_request(self, fc: RequestFc) -> DataTelegram:
        return build_request(GetCfgRequest(), da=self.address, sa=self.context.master, fc=fc)

    def data_frame(self, fc: RequestFc, operate: bool) -> bytes:
        """The Data_Exchange telegram (1.5 step 6; zero outputs in Clear), kept encoded:
        the same outputs go out cycle after cycle with one of two FCB values."""
        self.outputs_pending = False  # carried (in Clear: dropped, as Clear requires)
        return self.frame_for(fc, operate)

    def frame_for(self, fc: RequestFc, operate: bool) -> bytes:
        """The Data_Exchange telegram :meth:`data_frame` sends, nothing marked as carried
        (a steady ring's plan: it goes out only if the ring gets that far)."""
        outputs = self.outputs if operate else bytes(len(self.outputs))
        key = (fc.fcb, fc.fcv, outputs)
        frame = self.frames.get(key)
        if frame is None:
            if len(self.frames) >= FRAME_MEMO:
                self.frames.clear()
            request = build_request(
                DataExchange(outputs), da=self.address, sa=self.context.master, fc=fc
            )
            frame = self.frames[key] = request.encode()
        return frame

    # ------------------------------------------------------------------ replies

    def answered(self, pending: Pending, now: float) -> None:
        self.figures.response.add(now - pending.sent_at)
        if pending.fcb_function:
            self.fcb = self.fcb.acknowledged()  # 1.3: toggle after each acknowledged SRD

    def on_reply(self, pending: Pending, t: Reply, now: float) -> None:
        """The answer to a start-up request or a Data_Exchange."""
        _REPLY_HANDLERS[pending.purpose](self, pending, t, now)

    def _reply_diag(self, p: Pending, t: Reply, now: float) -> None:
        if not (isinstance(t, DataTelegram) and t.ssap == SlaveSap.SLAVE_DIAG and len(t.data) >= 6):
            self._invalid(f"Slave_Diag answered with {show(t)}", now)
            return
        try:
            diag = SlaveDiag.decode(t.data, dpv1=self.params.dpv1)
        except ProfibusDecodeError as exc:
            self._invalid(f"undecodable diagnosis: {exc.message}", now)
            return
        self._on_diag(diag, bytes(t.data[6:]), now)

    def _reply_ack(self, p: Pending, t: Reply, now: float) -> None:
        """Set_Prm and Chk_Cfg expect a short acknowledgement (1.5 steps 3 and 4)."""
        status = status_of(t)
        if status not in (ResponseStatus.OK, ResponseStatus.DL) or (
            isinstance(t, DataTelegram) and t.data
        ):
            what = "Set_Prm" if p.purpose is Purpose.SET_PRM else "Chk_Cfg"
            self.fault_with(FaultKind.REFUSED, f"the slave refused {what} ({show(t)})", now)
            return
        if p.purpose is Purpose.SET_PRM:
            self.enter(SlaveState.CHK_CFG, now)
        else:
            self.enter(SlaveState.WAIT_READY, now)

    def _reply_get_cfg(self, p: Pending, t: Reply, now: float) -> None:
        sent = describe_cfg(self.params.cfg)
        slave_cfg: bytes | None = None
        if isinstance(t, DataTelegram) and t.ssap == SlaveSap.GET_CFG:
            slave_cfg = bytes(t.data)
            has = describe_cfg(slave_cfg)
            text = f"Cfg_Fault: the slave refused the configuration {sent}; it has {has}"
        else:
            text = f"Cfg_Fault: the slave refused the configuration {sent} (Get_Cfg: {show(t)})"
        text += _origin(self.params) + _slave_words(self.last_diag)
        self.fault_with(FaultKind.CFG_FAULT, text, now, slave_cfg)

    def _reply_data(self, p: Pending, t: Reply, now: float) -> None:
        """Data_Exchange reply (1.5 step 6): DL with inputs, E5 without, DH: diag waits."""
        status = status_of(t)
        if status is ResponseStatus.RS:
            self.enter(SlaveState.WAIT_DIAG, now, "the slave left data exchange (RS)")
            return
        if status not in DATA_OK or (isinstance(t, DataTelegram) and t.dsap is not None):
            self._restart_bad(f"Data_Exchange answered with {show(t)}", now)
            return
        data = bytes(t.data) if isinstance(t, DataTelegram) else b""
        if len(data) != self.params.input_len:
            self._restart_bad(
                f"{len(data)} input bytes, the configuration has {self.params.input_len}", now
            )
            return
        if status in (ResponseStatus.DH, ResponseStatus.RDH):
            self.diag_pending = True
        self.took_inputs(data, now)

    def took_inputs(self, data: bytes, now: float) -> None:
        """A Data_Exchange's inputs: reported as :class:`InputsReceived` when they changed,
        when the caller has not said it is quiet, and at least every
        :data:`INPUTS_REFRESH` s. A quiet caller (its outputs and readings depend on
        nothing but the inputs and what it is told otherwise: docs/decisions/0096) is not
        called for a reply that says nothing new: the steady exchange costs the line only
        its telegrams (issue 34's fast path)."""
        self.figures.exchanges += 1
        if self.quiet and data == self.last_inputs and now < self.inputs_due:
            return
        if data != self.last_inputs:  # the steady reply says the last inputs, no longer
            self.steady_reply = b""  # these (the engine's short path sets it again)
        self.last_inputs = data
        self.inputs_due = now + INPUTS_REFRESH
        self._out.append(InputsReceived(self.address, data))

    def took_same_inputs(self, now: float) -> None:
        """A steady reply taken by its bytes (a steady ring): its inputs are the last
        reported ones, reported again if their refresh is due (:meth:`took_inputs`)."""
        if self.last_inputs is None:  # (never: a steady slave's inputs were taken)
            self.figures.exchanges += 1
            return
        self.took_inputs(self.last_inputs, now)

    def _invalid(self, text: str, now: float) -> None:
        """A reply that is no answer to the request: counted; the state decides what next."""
        self.figures.invalid_replies += 1
        self.context.figures.invalid_replies += 1
        if self.state is SlaveState.DATA_EXCHANGE:
            self.enter(SlaveState.WAIT_DIAG, now, text)

    def _restart_bad(self, text: str, now: float) -> None:
        self.figures.invalid_replies += 1
        self.context.figures.invalid_replies += 1
        self.enter(SlaveState.WAIT_DIAG, now, text)

    def gave_up(self, pending: Pending, now: float) -> None:
        """No (valid) reply after every try (1.5 step 7)."""
        what = "no valid reply" if pending.garbled else "no reply"
        if self.state in (SlaveState.WAIT_DIAG, SlaveState.ABSENT):
            self.retry_at = now + self.context.bus.absent_retry
            self.enter(SlaveState.ABSENT, now, what)
            return
        wait = (pending.deadline - pending.sent_at) * 1000
        tries = f"{pending.tries} {'try' if pending.tries == 1 else 'tries'}"
        self.enter(
            SlaveState.WAIT_DIAG,
            now,
            f"{what} to {REQUEST_NAMES[pending.purpose]} after {tries} "
            f"(waited {wait:.1f} ms for each)",
        )

    # ------------------------------------------------------------------ diagnosis

    def _on_diag(self, diag: SlaveDiag, ext: bytes, now: float) -> None:
        self.last_diag = diag
        self._out.append(DiagnosisRead(self.address, diag, ext))
        _DIAG_HANDLERS.get(self.state, Station._diag_ignored)(self, diag, now)

    def _diag_ignored(self, diag: SlaveDiag, now: float) -> None:
        return

    def _diag_start(self, diag: SlaveDiag, now: float) -> None:
        """1.5 step 2: a valid diagnosis; go on with Set_Prm unless another master has it."""
        owner = diag.master_address
        if owner not in (0xFF, self.context.master) and not diag.prm_req:
            self.fault_with(FaultKind.LOCKED, f"the slave is parameterised by master {owner}", now)
            return
        self.enter(SlaveState.SET_PRM, now)

    def _diag_ready(self, diag: SlaveDiag, now: float) -> None:
        """1.5 step 5: ready when Not_Ready, Cfg_Fault, Prm_Fault and Prm_Req are all 0."""
        if diag.prm_fault:
            self.fault_with(FaultKind.PRM_FAULT, self._prm_fault_text(diag), now)
        elif diag.cfg_fault:
            self.enter(SlaveState.GET_CFG, now)  # learn the slave's own configuration
        elif diag.not_supported:
            self.fault_with(
                FaultKind.NOT_SUPPORTED,
                "Not_Supported: the slave does not support a requested function"
                + _slave_words(diag),
                now,
            )
        elif diag.prm_req:
            if self.prm_attempts >= MAX_PRM_ATTEMPTS:
                self.fault_with(
                    FaultKind.PRM_REQ_LOOP,
                    f"the slave keeps asking for parameters (Prm_Req after "
                    f"{self.prm_attempts} Set_Prm)",
                    now,
                )
            else:
                self.enter(SlaveState.SET_PRM, now)
        elif diag.ready_for_data_exchange:
            self.diag_pending = diag.stat_diag
            self.enter(SlaveState.DATA_EXCHANGE, now)
        # Not_Ready alone: ask again next turn, until the state times out

    def _diag_exchange(self, diag: SlaveDiag, now: float) -> None:
        """A diagnosis read during data exchange (after DH/RDH, or Stat_Diag)."""
        self.diag_pending = diag.stat_diag  # 1.8 Status_2 b1: keep reading diagnosis
        if diag.prm_req:
            self.enter(SlaveState.SET_PRM, now, "the slave asks for parameters (Prm_Req)")
        elif not diag.ready_for_data_exchange:
            flags = [
                name
                for name, on in (
                    ("Station_Not_Ready", diag.station_not_ready),
                    ("Cfg_Fault", diag.cfg_fault),
                    ("Prm_Fault", diag.prm_fault),
                )
                if on
            ]
            self.enter(SlaveState.WAIT_DIAG, now, f"diagnosis says {', '.join(flags)}")

    def _prm_fault_text(self, diag: SlaveDiag) -> str:
        p = self.params
        text = (
            f"Prm_Fault: the slave refused the parameters (Ident_Number 0x{p.ident_number:04X}, "
            f"{len(p.user_prm)} bytes of user parameters"
            + (f": {p.user_prm.hex(' ').upper()})" if p.user_prm else ")")
        )
        if diag.ident_number != p.ident_number:
            text += f"; the slave reports Ident_Number 0x{diag.ident_number:04X}"
        return text + _origin(p) + _slave_words(diag)

    # ------------------------------------------------------------------ state changes

    def fault_with(
        self, kind: FaultKind, text: str, now: float, slave_cfg: bytes | None = None
    ) -> None:
        changed = self.fault != text
        self.fault = text
        self.retry_at = now + self.context.bus.fault_retry
        self.enter(SlaveState.FAULT, now, text)
        if changed:
            self._out.append(SlaveFault(self.address, kind, text, slave_cfg))

    def enter(self, new: SlaveState, now: float, reason: str = "") -> None:
        old = self.state
        self.since = now
        if new is SlaveState.WAIT_DIAG:
            self.fcb = FcbState.reset()  # 1.3: after a (re)start FCB = 1, FCV = 0
            self.prm_attempts = 0
        if old is new:
            return
        self.state = new
        self.quiet, self.last_inputs = False, None  # a new start: every reply reported
        self.steady_reply = b""
        context = self.context
        if new in TIMED_STATES:
            context.timed[self.address] = self
        else:
            context.timed.pop(self.address, None)
        if old is SlaveState.DATA_EXCHANGE or new is SlaveState.DATA_EXCHANGE:
            context.exchange_changes += 1
        if old is SlaveState.DATA_EXCHANGE:
            self.figures.restarts += 1
            self.diag_pending = False
            self._out.append(SlaveDown(self.address, reason or new.value))
            context.left_exchange(self)
        self._out.append(SlaveStateChanged(self.address, old, new))
        if new is SlaveState.DATA_EXCHANGE:
            self.fault = None
            self.turn.count = MAX_TURN  # first Data_Exchange next turn, with the caller's outputs
            self._out.append(SlaveUp(self.address))

    def check_timeout(self, now: float, busy: list[int]) -> None:
        """A start-up state that lasted too long (1.5): start again, or not ready."""
        limit = STATE_TIMEOUTS.get(self.state)
        if limit is None or self.state not in TIMED_STATES:
            return
        bus = self.context.bus
        limit = max(limit, 4 * bus.cycle_time, 4 * _retry_bound(bus))
        if now - self.since <= limit or self.address in busy:
            return
        if self.state is SlaveState.WAIT_READY:
            self.fault_with(
                FaultKind.NOT_READY,
                f"the slave stays not ready {limit:g} s after Set_Prm and Chk_Cfg"
                + _slave_words(self.last_diag),
                now,
            )
        else:
            self.enter(SlaveState.WAIT_DIAG, now, f"{self.state.value} timed out")


# ---------------------------------------------------------------------------------------
# Tables and helpers

_REQUESTS: Final[dict[Purpose, Callable[[Station, RequestFc], DataTelegram]]] = {
    Purpose.DIAG: Station._diag_request,
    Purpose.SET_PRM: Station._set_prm_request,
    Purpose.CHK_CFG: Station._chk_cfg_request,
    Purpose.GET_CFG: Station._get_cfg_request,
}

_REPLY_HANDLERS: Final[dict[Purpose, Callable[[Station, Pending, Reply, float], None]]] = {
    Purpose.DIAG: Station._reply_diag,
    Purpose.SET_PRM: Station._reply_ack,
    Purpose.CHK_CFG: Station._reply_ack,
    Purpose.GET_CFG: Station._reply_get_cfg,
    Purpose.DATA: Station._reply_data,
}

_DIAG_HANDLERS: Final[dict[SlaveState, Callable[[Station, SlaveDiag, float], None]]] = {
    SlaveState.WAIT_DIAG: Station._diag_start,
    SlaveState.ABSENT: Station._diag_start,
    SlaveState.FAULT: Station._diag_start,
    SlaveState.WAIT_READY: Station._diag_ready,
    SlaveState.DATA_EXCHANGE: Station._diag_exchange,
}


def _retry_bound(bus: BusParams) -> float:
    return (1 + bus.retries) * (bus.reply_wait + bus.tx_time(MAX_TELEGRAM))


def _origin(p: SlaveParams) -> str:
    """Where the bytes sent come from, when not from the profile (a GSD file and module)."""
    return f"; sent as {p.origin} says" if p.origin else ""


def _slave_words(diag: SlaveDiag | None) -> str:
    """The slave's own extended diagnosis (1.8) for a fault text, if it gave one."""
    if diag is None or not diag.blocks:
        return ""
    return f"; the slave's diagnosis: {describe_blocks(diag.blocks)}"
