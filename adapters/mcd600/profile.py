"""The Danfoss VLT MCD 600 soft starter on the Profibus DP master (PROFIBUS card).

Source: the card's installation guide (seeds/danfoss-mcd600-profibus.pt.txt); sections and
tables are cited next to each use. One :class:`Mcd600Profile` per configured starter; it
keeps no state shared with other instances.

What the common model gets from a soft starter: status (ready, starting, running, stopping,
tripped, not ready), running, remote (network is the command source) and local_control
(it is not: the starter ignores the card's commands, guide 3.3), alarm (warning),
current in %FLC every cycle and in A when ``flc_a`` is configured, the trip code and text;
in extended and parameter modes also motor temperature, power, voltage and the other
monitoring values (``values``). Speed fields stay None: a soft starter has no speed.
At connect: ``failsafe``/``failsafe_text``, the starter's reaction to a lost master from
its config (:mod:`adapters.mcd600.failsafe`; the card cannot be asked).

No start by itself (docs/safety.md, issue 32 item 3): start is a level on the wire (4.2
byte 1 bit 0) and the starter acts on it whenever it can (1.3: "a máquina pode entrar em
funcionamento sem aviso"). The profile sends start only on a run it saw go from off to on
after the last of: (re)connection, a trip, a quick/coast stop, a status of not ready (reset
input open, 3.3 note; restart delay), the starter out of network control (3.3). The latch
(``_run_armed``) clears on each of these and re-arms only when ``desired.run`` is seen off.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar, Final

from adapters.mcd600.diag import ExtDiag
from adapters.mcd600.failsafe import failsafe_of
from adapters.mcd600.layout import LAYOUTS, InputTelegram, Mode, OutputTelegram
from adapters.mcd600.options import (
    Mcd600Options,
    parse_options,
    safety_warning,
    user_prm_data,
)
from adapters.mcd600.params import ParamChannel
from adapters.mcd600.poller import DataPoller
from adapters.mcd600.programming import IDLE, PARAM_NUMBER_MAX, PARAM_VALUE_MAX, ParamRequest
from adapters.mcd600.trips import trip_text
from adapters.mcd600.words import CURRENT_RAW_MAX, ControlWord, StatusWord
from adapters.profibus.contract import (
    AddressRange,
    DiagEvent,
    DiagKind,
    DpProfileBase,
    EventSink,
    RecordChannel,
    SlaveSetup,
)
from gateway.adapter import Capabilities, ParamValue
from gateway.errors import DriveOffline, GatewayError, ParameterError
from gateway.model import DesiredCommand, Device, DriveStatus, Readings

if TYPE_CHECKING:
    from gateway.config import DriveConfig
    from gateway.schema import Table

log = logging.getLogger(__name__)

UNSUPPORTED: Final[Mapping[str, str]] = MappingProxyType(
    {
        "direction": "the MCD 600 is a soft starter: it has no direction command",
        "jog": "the MCD 600 PROFIBUS control word has no jog command",
        "remote": (
            "the MCD 600 takes network commands only when its parameter 1-1 Command Source "
            "is Network; the control word cannot take or leave remote"
        ),
    }
)
"""Commands the starter cannot do (speed is refused by the missing speed scale)."""

STOP_SUBSTITUTES: Final[Mapping[str, str]] = MappingProxyType({"quick_stop": "coast_stop"})
"""The card's only fast stop is byte 0 bit 4, "parada rápida (parada por inércia)": a coast
(guide 4.2 table 2). A quick stop is that coast stop (the hub says so once, issue 32 item 4);
the soft starter has no faster controlled ramp than its soft stop."""

NEEDS_PARAMETER_MODE = (
    'MCD 600 parameter access needs mode = "parameter" (the PROFIBUS card reads and writes '
    "parameters only through the programming structure of the cyclic data, guide 4.4; "
    "it has no DP-V1)"
)


class Mcd600Profile(DpProfileBase):
    """:class:`adapters.profibus.contract.DpProfile` for the MCD 600 PROFIBUS card."""

    device: ClassVar[Device] = Device.MCD600
    addresses: ClassVar[AddressRange] = AddressRange(
        1, 125, "MCD 600 PROFIBUS manual 7.2 Configurações: Faixa de endereços 1-125"
    )
    failsafe_needs_watchdog: ClassVar[bool] = True
    """Guide 3.3 l.171: the comm timeout starts when the card leaves data exchange, which
    only the DP watchdog makes it do (the adapter publishes failsafe false with it off)."""
    sees_every_diag: ClassVar[bool] = True
    """Every diagnosis read comes here, even bytes equal to the last ones: after a reset the
    card clears its telegram (5.1.1) without raising the alert, so the same trip again is
    the same three bytes, and only this profile knows it is a new trip."""

    @classmethod
    def telegram_keys(cls, input_bytes: int, output_bytes: int) -> tuple[str, ...]:
        """``mode``: the one whose layout has these sizes (guide 4.1)."""
        for layout in LAYOUTS.values():
            if (layout.input_len, layout.output_len) == (input_bytes, output_bytes):
                return (f'mode = "{layout.mode.value}"',)
        return ()

    @classmethod
    def telegram_text(cls, options: Any) -> str:
        """The ``mode`` (guide 4.1)."""
        if not isinstance(options, Mcd600Options):
            return super().telegram_text(options)
        return f"MCD 600 mode = {options.mode.value!r}"

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> Mcd600Options:
        return parse_options(table, drive)

    @classmethod
    def safety_warnings(cls, drive: DriveConfig, watchdog: float) -> list[str]:
        """``check-config``: the starter's reaction to a lost master from the config alone
        (comm_timeout, network_comms and the DP watchdog: :func:`.options.safety_warning`)."""
        text = safety_warning(_options_of(drive), watchdog)
        return [] if text is None else [text]

    def __init__(self, drive: DriveConfig, options: Mcd600Options | None = None) -> None:
        self.drive_id = drive.id
        self.options = options if options is not None else _options_of(drive)
        self.layout = LAYOUTS[self.options.mode]
        self._poller = DataPoller(self.options.request_period, self.options.current_scale)
        self._params = ParamChannel(self.options.param_timeout, f"MCD 600 {drive.id}")
        self._reset_connection_state()

    def _reset_connection_state(self) -> None:
        """Forget everything learnt from the starter (communication lost)."""
        self._tripped_seen = False
        self._trip_code: int | None = None
        self._diag = ExtDiag()  # the last external diagnosis seen
        self._reset_command_state()

    def _reset_command_state(self) -> None:
        """Forget edges and progress; keep what the start-up diagnosis said (trip code)."""
        self._run_armed = False  # start only after run was seen off (no restart, rule 1)
        self._start_sent = False
        self._reset_seen: int | None = None  # fault_reset_seq last acted on
        self._reset_until: float | None = None  # the pulse in progress ends then
        self._reset_pending = False  # a pulse to start
        self._reset_high = False  # the reset bit of the last output telegram
        self._status: DriveStatus | None = None
        self._poller.reset()

    # ------------------------------------------------------------------ setup

    def setup(self) -> SlaveSetup:
        return SlaveSetup(
            ident_number=self.options.ident_number,
            cfg=self.layout.cfg,
            user_prm=user_prm_data(self.options),  # guide 3.3: communication timeout
            input_len=self.layout.input_len,
            output_len=self.layout.output_len,
            dpv1=False,  # the card has no DP-V1 (guide 4.1: parameters via mode 3 only)
            group=self.options.group_mask,  # Sync/Freeze (guide 6.1, 6.2)
        )

    def capabilities(self) -> Capabilities:
        return Capabilities(
            speed_scale=None,
            unsupported=dict(UNSUPPORTED),
            stop_substitutes=dict(STOP_SUBSTITUTES),
            run_needs_ready=True,  # a not-ready starter keeps no start for later (item 3)
        )

    async def on_connect(self, channel: RecordChannel, event: EventSink) -> Readings:
        """Nothing to read at start-up (no DP-V1, no speed scale): start from a clean slate,
        keeping a trip code the start-up diagnosis may already have given. The reaction to
        a lost master comes from the config (comm_timeout, network_comms; guide 3.3)."""
        self._reset_command_state()
        failsafe, text = failsafe_of(self.options.comm_timeout, self.options.network_comms)
        return {"failsafe": failsafe, "failsafe_text": text}

    def unconfigured_outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The telegram before the starter is configured (first output after any
        (re)connection): built fresh, a stop (start 0, soft stop as set on the starter,
        no reset, 4.2), no data request, programming idle. Nothing of the command state is
        touched, so it arms nothing."""
        control = ControlWord(motor_set=self.options.motor_set)
        return OutputTelegram(control, 0, IDLE).encode(self.layout)

    def on_comm_lost(self) -> None:
        self._params.fail(DriveOffline(f"MCD 600 {self.drive_id}: communication lost"))
        self._reset_connection_state()

    # ------------------------------------------------------------------ outputs

    @property
    def steady(self) -> bool:
        """Without monitoring and programming words (their polls run in every telegram)
        and with no reset pulse under way, the telegrams depend on the inputs and the
        desired command only."""
        return (
            not self.layout.monitoring
            and not self.layout.programming
            and self._reset_until is None
            and not self._reset_pending
            and not self._reset_high
        )

    def outputs(self, desired: DesiredCommand, now: float) -> bytes:
        control = self._control_word(desired, now)
        request = self._poller.next_request(now) if self.layout.monitoring else 0
        param = self._params.output() if self.layout.programming else IDLE
        return OutputTelegram(control, request, param).encode(self.layout)

    def _control_word(self, desired: DesiredCommand, now: float) -> ControlWord:
        reset = self._reset_bit(desired.fault_reset_seq, now)
        coast = desired.coast_stop or desired.quick_stop  # 4.2 t2 byte 0 bit 4: quick stop
        if not desired.run:
            self._run_armed = True
        elif coast:
            self._run_armed = False  # rule 1: a run asked before the stop never restarts
        # 4.2 note: byte 0 bit 4 must be 0 for a start; never start and reset together.
        start = desired.run and self._run_armed and not coast and not reset
        self._start_sent = start
        return ControlWord(
            start=start, quick_stop=coast, reset=reset, motor_set=self.options.motor_set
        )

    def _reset_bit(self, seq: int, now: float) -> bool:
        """One reset pulse (byte 1 bit 3) per growth of ``fault_reset_seq``, never repeated;
        a reset asked while the bit is still set gets one low telegram first, so the starter
        sees a new edge."""
        self._reset_high = self._next_reset_bit(seq, now)
        return self._reset_high

    def _next_reset_bit(self, seq: int, now: float) -> bool:
        if self._reset_seen is None or seq < self._reset_seen:
            self._reset_seen = seq  # first sight or a counter restart: no pulse
        elif seq > self._reset_seen:
            self._reset_seen = seq
            self._reset_until = None
            self._reset_pending = True
            if self._reset_high:
                return False  # the gap before the new edge; the pulse starts next cycle
        if self._reset_pending:  # the pulse starts: held for reset_pulse, at least one cycle
            self._reset_pending = False
            self._reset_until = now + self.options.reset_pulse
            return True
        if self._reset_until is None or now >= self._reset_until:
            self._reset_until = None
            return False
        return True

    # ------------------------------------------------------------------ inputs

    def inputs(self, data: bytes, now: float) -> Readings:
        telegram = InputTelegram.decode(self.layout, data)
        if telegram.monitor is not None:
            new = self._poller.take(telegram.monitor)
            if new and new.get("trip_code") and telegram.status.tripped:  # request 2 b8-15
                self._trip_code = int(new["trip_code"])
        if telegram.param is not None:
            self._params.take(telegram.param)
        changes = self._status_changes(telegram.status)
        if self.layout.monitoring:
            changes.update(self._poller.model_fields())
            changes["values"] = self._poller.values()
            measured = self._poller.readings.get("current_avg_a")  # request 3, in A
            saturated = telegram.status.current_raw >= CURRENT_RAW_MAX  # 63 = 200 % or more
            if measured is not None and (changes["current_a"] is None or saturated):
                changes["current_a"] = float(measured)
        return changes

    def _status_changes(self, st: StatusWord) -> Readings:
        status = self._map_status(st)
        self._status = status
        if status is DriveStatus.NOT_READY or not st.network_control:
            # 3.3: not ready (reset input open, restart delay) or out of network control,
            # the starter would act on a start held from before when it can again (start is
            # a level, 4.2): like a trip, it needs a run seen off and on afterwards.
            self._run_armed = False
        pct = round(st.current_pct_flc, 2)
        flc = self.options.flc_a
        return {
            "status": status,
            "running": st.active,
            "at_reference": status is DriveStatus.RUNNING,  # up to line speed (bypass)
            "remote": st.network_control,
            "local_control": not st.network_control,  # 3.3: 1-1 Command Source not Network
            "alarm": st.warning,
            "current_pct_flc": pct,
            "current_a": None if flc is None else round(pct * flc / 100.0, 2),
            **self._fault_fields(st.tripped),
        }

    def _map_status(self, st: StatusWord) -> DriveStatus:
        """Status word (4.2 table 3) -> DriveStatus."""
        if st.tripped:
            return DriveStatus.TRIPPED
        if st.active:
            if not st.ramping:
                return DriveStatus.RUNNING
            return DriveStatus.STARTING if self._ramp_is_start(st) else DriveStatus.STOPPING
        return DriveStatus.READY if st.ready else DriveStatus.NOT_READY

    def _ramp_is_start(self, st: StatusWord) -> bool:
        """Bit 7 says "starting or stopping": under network control our start bit tells
        which; under local control, a ramp after running is a stop."""
        if st.network_control:
            return self._start_sent
        return self._status not in (DriveStatus.RUNNING, DriveStatus.STOPPING)

    def _fault_fields(self, tripped: bool) -> Readings:
        if not tripped:
            if self._tripped_seen:  # the trip was reset: its code is history
                self._tripped_seen = False
                self._trip_code = None
                # 5.1.1: the reset sets the telegram's trip code to 0 in the card too
                self._diag = ExtDiag(0, self._diag.changed_param)
            return {"fault_code": None, "fault_text": None}
        self._tripped_seen = True
        self._run_armed = False  # a trip needs a new run command afterwards
        code = self._trip_code or None
        return {"fault_code": code, "fault_text": None if code is None else trip_text(code)}

    # ------------------------------------------------------------------ diagnosis

    def on_ext_diag(self, data: bytes) -> list[DiagEvent]:
        """Events from the card's diagnosis telegram (guide 5.1); no bytes: nothing to report."""
        diag = ExtDiag.decode(data) if data else ExtDiag()
        old, self._diag = self._diag, diag
        events: list[DiagEvent] = []
        if diag.trip_code != old.trip_code:
            if diag.trip_code:  # 5.1.1
                self._trip_code = diag.trip_code
                text = trip_text(diag.trip_code)
                events.append(
                    DiagEvent(
                        f"trip {diag.trip_code}: {text}", DiagKind.TRIP, {"code": diag.trip_code}
                    )
                )
            else:
                events.append(DiagEvent("trip code cleared", DiagKind.INFO, {"code": 0}))
        if diag.changed_param and diag.changed_param != old.changed_param:  # 5.1.2
            events.append(
                DiagEvent(
                    f"parameter {diag.changed_param} changed on the starter",
                    DiagKind.PARAMETER,
                    {"number": diag.changed_param},
                )
            )
        return events

    def _param_touched(self, number: int) -> None:
        """5.1.2: reading or writing the changed parameter resets byte 2 in the card."""
        if number == self._diag.changed_param:
            self._diag = ExtDiag(self._diag.trip_code, 0)

    # ------------------------------------------------------------------ parameters

    async def read_param(self, channel: RecordChannel, number: int, subindex: int) -> ParamValue:
        self._check_param_access(number, subindex)
        value = await self._params.transact(ParamRequest(number, read=True))
        self._param_touched(number)
        return value

    async def write_param(
        self, channel: RecordChannel, number: int, subindex: int, value: ParamValue
    ) -> None:
        self._check_param_access(number, subindex)
        raw = _param_value(value)
        await self._params.transact(ParamRequest(number, write=True, value=raw))
        self._param_touched(number)

    def _check_param_access(self, number: int, subindex: int) -> None:
        if not self.layout.programming:
            raise ParameterError(NEEDS_PARAMETER_MODE)
        if subindex != 0:
            raise ParameterError("MCD 600 parameters have no subindex (use 0)")
        if not 1 <= number <= PARAM_NUMBER_MAX:
            raise ParameterError(
                f"MCD 600 parameter numbers are 1..{PARAM_NUMBER_MAX} (one byte, guide 4.4.1)"
            )


def _param_value(value: ParamValue) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value != int(value)
    ):
        raise ParameterError(f"MCD 600 parameter values are integers, not {value!r}")
    raw = int(value)
    if not 0 <= raw <= PARAM_VALUE_MAX:
        raise ParameterError(f"MCD 600 parameter values are 0..{PARAM_VALUE_MAX}, not {raw}")
    return raw


def _options_of(drive: DriveConfig) -> Mcd600Options:
    if isinstance(drive.options, Mcd600Options):
        return drive.options
    nested = getattr(drive.options, "profile", None)
    if isinstance(nested, Mcd600Options):
        return nested
    if drive.options is None:
        return Mcd600Options()
    raise GatewayError(
        f"drive {drive.id}: MCD 600 profile options missing (got {type(drive.options).__name__})"
    )


__all__ = ["Mcd600Options", "Mcd600Profile", "Mode"]
