"""A simulated MCD 600 with its PROFIBUS card, for the generic DP slave simulator.

:class:`Mcd600Sim` implements :class:`adapters.profibus.contract.SimDevice` (sans-IO, clock
injected) on the soft starter physics of :mod:`adapters.mcd600.starter`, following the
card's installation guide:

* network commands are obeyed only when parameter 1-1 Command Source is Network and the
  reset input is closed (3.3); a start needs control word byte 0 bit 4 = 0 (4.2);
* start is a level (4.2 byte 1 bit 0 "0 = Parada, 1 = Partida"): a start the master still
  sends starts the starter whenever it becomes ready again (after the reset input closes
  again, after a trip is reset at the keypad or by auto-reset, after 1-1 is set back to
  Network). The guide warns of exactly this (1.3: "a máquina pode entrar em funcionamento
  sem aviso"); the gateway's profile must not rely on the starter to refuse it;
* the reset input (3.3 note, :meth:`set_reset_input`): while it is open ("ativa") the
  starter does not operate: status not ready, a running motor coasts; opening it also
  resets a trip whose condition is gone (it is the starter's reset switch; our reading,
  the guide names it only);
* the communication timeout from Set_Prm (3.3, 0-100 s, 0 = keep the state) forces the
  reaction of parameter 6-13 once the master has been gone that long;
* Global_Control (6): Clear makes the starter quick stop; Sync holds the outputs until the
  next Sync; Freeze holds the inputs until the next Freeze (:meth:`Mcd600Sim.global_control`);
* data requests (4.3) with their scales (:mod:`.monitor`), parameter reads and writes
  (4.4) with the invalid number / invalid value answers, and the diagnosis telegram (5.1).

Fault injection: :meth:`trip` (any code, until reset), :meth:`keypad_reset` (the LCP's
reset, behind the network's back), the auto-reset parameters (a trip resets itself after a
delay on the injected clock), :meth:`keypad_change`, ``reset_input_closed``,
``input_a``/``input_b``, ``warning``, :attr:`faults` (the shared
:class:`gateway.sim.FaultInjector`, whose line-level knobs the host applies).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Final, Protocol, Self

from adapters.mcd600.diag import ExtDiag
from adapters.mcd600.layout import LAYOUTS, InputTelegram, Mode, OutputTelegram
from adapters.mcd600.monitoring import StarterState
from adapters.mcd600.options import DEFAULT_IDENT_NUMBER, Mcd600Options, parse_user_prm
from adapters.mcd600.paramtable import (
    AUTO_RESET_ACTION,
    AUTO_RESET_DELAY,
    AUTO_RESET_MAX,
    COMMAND_SOURCE,
    CURRENT_LIMIT,
    EXCESS_START_TIME,
    INITIAL_CURRENT,
    LOCKED_ROTOR_TIME,
    MOTOR_FLC,
    NETWORK_COMMS,
    PROFIBUS_ADDRESS,
    START_RAMP_TIME,
    STOP_MODE,
    STOP_TIME,
    AutoResetAction,
    CommandSource,
    NetworkCommsAction,
    ParamStore,
    StopMode,
)
from adapters.mcd600.programming import ParamReply, ParamRequest
from adapters.mcd600.sim.monitor import monitor_reply
from adapters.mcd600.starter import SoftStarter, StarterSettings
from adapters.mcd600.trips import NETWORK_FORCED_TRIP
from adapters.mcd600.words import ControlWord, MotorSet, StatusWord, current_to_raw
from adapters.profibus.contract import RecordAccessError, SimDeviceBase
from gateway.sim import FaultInjector, MotorParams

if TYPE_CHECKING:
    from gateway.config import DriveConfig

log = logging.getLogger(__name__)

DEFAULT_COMM_TIMEOUT: Final = 10  # s, guide 3.3
WARNING_THERMAL_PCT: Final = 90.0  # our choice: warn before the overload trip
NO_DPV1: Final = 0xA9  # DP-V1 error class 0xA (application), code 9: not supported


class GlobalControlLike(Protocol):
    """What :meth:`Mcd600Sim.global_control` reads (a ``codec.dp.GlobalControl``)."""

    @property
    def clear_data(self) -> bool: ...

    @property
    def unfreeze(self) -> bool: ...

    @property
    def freeze(self) -> bool: ...

    @property
    def unsync(self) -> bool: ...

    @property
    def sync(self) -> bool: ...


class Mcd600Sim(SimDeviceBase):
    """One simulated MCD 600 with a PROFIBUS card (a ``SimDevice``)."""

    dpv1 = False  # Set_Prm has no DP-V1 status bytes: user data from byte 7
    reads_user_prm = True  # its comm timeout byte (3.3), behind a GSD file too

    def __init__(
        self,
        mode: Mode = Mode.BASIC,
        *,
        flc_a: int = 100,
        params: dict[int, int] | None = None,
        ident_number: int = DEFAULT_IDENT_NUMBER,
        current_x10: bool = False,
        line_voltage: float = 400.0,
        load: float = 0.6,
        required_start_pct: float = 250.0,
        version: tuple[int, int] = (1, 4),
        seed: int = 0,
        time_scale: float = 1.0,
    ) -> None:
        if not time_scale > 0:
            raise ValueError(f"time scale must be positive, got {time_scale!r}")
        self.mode = mode
        self.time_scale = time_scale  # the power section runs this many times faster
        self.layout = LAYOUTS[mode]
        self.ident_number = ident_number
        self.current_x10 = current_x10
        self.version = version
        self.params = ParamStore({MOTOR_FLC: flc_a, **(params or {})})
        motor = MotorParams(
            rated_rpm=1480.0,
            rated_current=float(flc_a),
            magnetising_current=0.3 * flc_a,
            load=load,
        )
        self.starter = SoftStarter(
            motor, line_voltage=line_voltage, required_start_pct=required_start_pct
        )
        self.faults: FaultInjector = FaultInjector(seed=seed)
        # digital inputs (request 16); the reset input must be closed to run (3.3)
        self.reset_input_closed = True
        self.start_input = False
        self.input_a = False
        self.input_b = False
        self.warning = False  # injected warning (status word byte 1 bit 3)
        # bus side
        self.comm_timeout = DEFAULT_COMM_TIMEOUT
        self.prm_ok = False
        self.exchanging = False
        self._lost_at: float | None = None
        self._comm_acted = False
        self._comm_warning = False
        self._last_tick: float | None = None
        self._tripped_at: float | None = None  # when the present trip began (auto-reset)
        self.auto_resets = 0  # auto-resets since the last manual reset or power-up
        self._control = ControlWord()
        self._applied = OutputTelegram()
        self._param_reply = ParamReply()
        self._changed_param = 0
        self._sync = False
        self._held: OutputTelegram | None = None
        self._frozen: bytes | None = None
        # what tests look at
        self.reset_edges = 0
        self.starts = 0
        self.motor_set_used: MotorSet | None = None

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> Self:
        """The simulated starter a configured drive describes (``simulate = true``): its
        mode, Ident_Number, FLC, small-model current scale, PROFIBUS address (parameter
        12-7), ``sim_params`` and ``sim_time_scale``; a factory default one for ``None``."""
        if drive is None:
            return cls()
        o = drive.options if isinstance(drive.options, Mcd600Options) else Mcd600Options()
        params = {PROFIBUS_ADDRESS: drive.address} if 1 <= drive.address <= 125 else {}
        params.update(o.sim_params)
        flc = 100 if o.flc_a is None else min(2000, max(1, round(o.flc_a)))  # param 2 range
        return cls(
            o.mode,
            flc_a=params.pop(MOTOR_FLC, flc),  # the motor model follows parameter 2
            params=params,
            ident_number=o.ident_number,
            current_x10=o.current_x10,
            time_scale=o.sim_time_scale,
        )

    # ------------------------------------------------------------------ SimDevice

    def expected_cfg(self) -> bytes:
        return self.layout.cfg

    def set_prm(self, user_prm: bytes) -> bool:
        timeout = parse_user_prm(user_prm)  # guide 3.3: 0-100 s
        if timeout is None:
            return False
        self.comm_timeout = timeout
        self.prm_ok = True
        return True

    def exchange(self, outputs: bytes, now: float) -> bytes:
        self.tick(now)
        telegram = OutputTelegram.decode(self.layout, outputs)
        self.exchanging = True
        self._lost_at = None
        self._comm_acted = False
        self._comm_warning = False
        if self._sync:
            self._held = telegram  # 6.2: not processed until the next Sync
        else:
            self._apply(telegram)
        if self._frozen is not None:
            return self._frozen  # 6.1: inputs only change on the next Freeze
        return self._inputs()

    def comm_lost(self, now: float) -> None:
        """The DP watchdog expired: keep the state, start the comm timeout (3.3)."""
        self.tick(now)
        if self.exchanging:
            self.exchanging = False
            self._lost_at = now
            self._comm_acted = False

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        raise RecordAccessError("the MCD 600 PROFIBUS card has no DP-V1", NO_DPV1)

    def write_record(self, slot: int, index: int, data: bytes, now: float) -> None:
        raise RecordAccessError("the MCD 600 PROFIBUS card has no DP-V1", NO_DPV1)

    def ext_diag(self) -> bytes:
        """The diagnosis telegram of 5.1 (3 bytes, length byte included), empty when clear."""
        diag = ExtDiag(self.trip_code, self._changed_param)
        return b"" if diag.empty else diag.encode()

    @property
    def diag_alert(self) -> bool:
        """A trip raises the diagnosis alarm (5.1.1); a changed parameter does not (5.1.2)."""
        return self.trip_code != 0

    def alerts(self, ext: bytes) -> bool:
        return self.diag_alert

    def tick(self, now: float) -> None:
        """Advance to ``now``; the timers due on the way (communication timeout, auto-reset)
        act at their own time."""
        last = now if self._last_tick is None else self._last_tick
        self._last_tick = max(now, last)
        while (event := self._next_timer()) is not None and event[0] <= now:
            at, action = event
            self._advance_to(last, at)
            last = max(at, last)
            action(self, last)
            self._advance_to(last, last)  # a trip the action made begins now
        self._advance_to(last, now)

    def _advance_to(self, last: float, when: float) -> None:
        self._advance(max(0.0, when - last))
        if not self.starter.tripped:
            self._tripped_at = None
        elif self._tripped_at is None:
            self._tripped_at = max(when, last)

    def _next_timer(self) -> tuple[float, Callable[[Mcd600Sim, float], None]] | None:
        timers = [
            (at, action)
            for at, action in (
                (self._comm_deadline(), Mcd600Sim._comm_timeout_expired),
                (self.auto_reset_due(), Mcd600Sim._auto_reset),
            )
            if at is not None
        ]
        return min(timers, key=lambda t: t[0]) if timers else None

    def power_cycle(self, now: float) -> None:
        """Control power off and on: parameters and thermal model kept, the rest lost."""
        self.tick(now)
        self.starter.power_off()
        self.faults.clear()
        self._tripped_at = None
        self.auto_resets = 0
        self.comm_timeout = DEFAULT_COMM_TIMEOUT
        self.prm_ok = False
        self.exchanging = False
        self._lost_at = None
        self._comm_warning = False
        self._control = ControlWord()
        self._applied = OutputTelegram()
        self._param_reply = ParamReply()
        self._changed_param = 0
        self._sync = False
        self._held = None
        self._frozen = None

    # ------------------------------------------------------------------ Global_Control (6)

    def global_control(self, control: GlobalControlLike, now: float) -> None:
        self.tick(now)
        if control.clear_data and self.starter.active:
            self.starter.coast()  # 6.3: Clear -> quick stop
        if control.unsync:
            self._sync = False
            self._release_held()
        elif control.sync:
            self._release_held()  # 6.2: the outputs received so far take effect
            self._sync = True
        if control.unfreeze:
            self._frozen = None
        elif control.freeze:
            self._frozen = self._inputs()  # 6.1: inputs sampled now

    def _release_held(self) -> None:
        held, self._held = self._held, None
        if held is not None:
            self._apply(held)

    # ------------------------------------------------------------------ fault injection

    def trip(self, code: int, now: float | None = None) -> None:
        """Trip on ``code`` (any 1-255); the starter stops and reports it until reset. The
        trip begins at ``now`` (default: the last tick) for the auto-reset delay."""
        if not 1 <= code <= 255:
            raise ValueError(f"trip code {code} is not 1..255")
        if now is not None:
            self.tick(now)
        self.faults.trip(code)
        if not self.starter.tripped:
            self._tripped_at = self._last_tick
        self.starter.trip(code)

    def keypad_reset(self, now: float) -> bool:
        """The Reset key on the starter's LCP: the trip clears behind the network's back (if
        its condition is gone). Start is a level (guide 4.2, byte 1 bit 0): a start the
        master still sends starts the motor again at the next exchange."""
        self.tick(now)
        done = self._reset()
        if done:
            log.info("MCD 600 sim: trip reset at the keypad")
        return done

    def auto_reset_due(self) -> float | None:
        """When the present trip resets by itself: the auto-reset delay after it began, while
        the auto-reset action is on and fewer than its maximum resets were made."""
        p = self.params
        if (
            p[AUTO_RESET_ACTION] == AutoResetAction.OFF
            or self._tripped_at is None
            or self.auto_resets >= p[AUTO_RESET_MAX]
        ):
            return None
        return self._tripped_at + p[AUTO_RESET_DELAY]

    def _auto_reset(self, at: float) -> None:
        self.auto_resets += 1
        code = self.trip_code
        if self.starter.reset():
            self.faults.clear()
            self._tripped_at = None
            log.info("MCD 600 sim: auto-reset of trip %d (%d made)", code, self.auto_resets)
        else:
            self._tripped_at = at  # the condition is still there: try again after the delay

    def set_reset_input(self, closed: bool, now: float) -> None:
        """The starter's RESET input (guide 3.3 note). Opening it ("entrada de reset
        ativa") resets a trip whose condition is gone, as the keypad's Reset does, and the
        starter does not operate while it is open (not ready; an active starter stops, the
        motor coasts). Closing it makes the starter ready again: a start still sent by the
        master then starts it (start is a level, 4.2)."""
        self.tick(now)
        opened = self.reset_input_closed and not closed
        self.reset_input_closed = closed
        if opened and self._reset():
            log.info("MCD 600 sim: trip reset by the reset input")
        self._advance(0.0)

    def keypad_change(self, number: int, value: int) -> None:
        """Someone changes a parameter on the starter's keypad (5.1.2)."""
        self.params.set(number, value)  # ValueError for an unknown number or bad value
        self._changed_param = number

    # ------------------------------------------------------------------ internals

    @property
    def trip_code(self) -> int:
        return self.starter.trip_code if self.starter.tripped else 0

    @property
    def network_control(self) -> bool:
        return self.params[COMMAND_SOURCE] == CommandSource.NETWORK

    def settings(self) -> StarterSettings:
        p = self.params
        return StarterSettings(
            flc_a=float(p[MOTOR_FLC]),
            start_ramp_time=float(p[START_RAMP_TIME]),
            initial_current_pct=float(p[INITIAL_CURRENT]),
            current_limit_pct=float(p[CURRENT_LIMIT]),
            excess_start_time=float(p[EXCESS_START_TIME]),
            soft_stop=p[STOP_MODE] == StopMode.SOFT_STOP,
            stop_time=float(p[STOP_TIME]),
            locked_rotor_time=float(p[LOCKED_ROTOR_TIME]),
        )

    def _advance(self, dt: float) -> None:
        code = self.faults.fault_code
        if code is not None and not self.starter.tripped:
            self.starter.trip(code)  # an injected condition trips again until reset
        self.starter.available = self.reset_input_closed
        self.starter.apply_availability()  # at once, also when no time passes
        self.starter.advance(dt * self.time_scale, self.settings())

    def _comm_deadline(self) -> float | None:
        if self._lost_at is None or self._comm_acted or self.comm_timeout == 0:
            return None  # 3.3: timeout 0 leaves the starter as it is
        return self._lost_at + self.comm_timeout

    def _comm_timeout_expired(self, _at: float = 0.0) -> None:
        self._comm_acted = True
        action = NetworkCommsAction(self.params[NETWORK_COMMS])
        log.info("MCD 600 sim: communication timeout, %s", action.name)
        if action is NetworkCommsAction.TRIP_STARTER:
            self.starter.trip(NETWORK_FORCED_TRIP)
        elif action is NetworkCommsAction.SOFT_TRIP_AND_LOG:
            self.starter.soft_trip(NETWORK_FORCED_TRIP, self.settings())
        elif action is NetworkCommsAction.WARN_AND_LOG:
            self._comm_warning = True

    def _apply(self, telegram: OutputTelegram) -> None:
        self._applied = telegram
        self._apply_control(telegram.control)
        if self.layout.programming:
            self._param_reply = self._program(telegram.param)

    def _apply_control(self, cw: ControlWord) -> None:
        previous, self._control = self._control, cw
        if not self.network_control:
            return  # 3.3: commands from the card only with 1-1 = Network
        if cw.reset and not previous.reset:
            self.reset_edges += 1
            self._reset()
        if cw.quick_stop:
            self.starter.coast()  # 4.2 byte 0 bit 4: stop action is a quick stop
        elif not cw.start:
            self.starter.stop(self.settings())
        elif self.starter.state is StarterState.READY and cw.motor_set is not MotorSet.RESERVED:
            self._start(cw.motor_set)

    def _start(self, motor_set: MotorSet) -> None:
        """Start with the motor set of control word bits 2-3 (the sim's remote input for
        the motor set is input A: closed = secondary)."""
        if motor_set is MotorSet.REMOTE_INPUT:
            motor_set = MotorSet.SECONDARY if self.input_a else MotorSet.PRIMARY
        if self.starter.start(self.settings()):
            self.starts += 1
            self.motor_set_used = motor_set

    def _reset(self) -> bool:
        """A manual reset (the network's edge, the keypad)."""
        if self.starter.tripped and self.starter.reset():
            self.faults.clear()  # the injected condition is gone (5.1.1)
            self._tripped_at = None
            self.auto_resets = 0
            return True
        return False

    def _program(self, request: ParamRequest) -> ParamReply:
        """4.4: answer a read or write; a write wins when both bits are set."""
        number = request.number
        if request.idle:
            return ParamReply(echo=number)
        if not self.params.known(number):
            return ParamReply(echo=number, invalid_number=True)
        if request.write:
            if not self.params.valid_value(number, request.value):
                return ParamReply(echo=number, invalid_value=True, value=self.params[number])
            self.params.set(number, request.value)
        if number == self._changed_param:
            self._changed_param = 0  # 5.1.2: the master read or wrote it
        return ParamReply(echo=number, value=self.params[number])

    # ------------------------------------------------------------------ inputs

    def _inputs(self) -> bytes:
        monitor = monitor_reply(self, self._applied.request) if self.layout.monitoring else None
        param = self._param_reply if self.layout.programming else None
        return InputTelegram(self._status_word(), monitor, param).encode(self.layout)

    def _status_word(self) -> StatusWord:
        s = self.starter
        return StatusWord(
            current_raw=current_to_raw(s.current_pct(self.settings())),
            network_control=self.network_control,
            ramping=s.state in _RAMPING,
            ready=s.state is _READY,
            active=s.active,
            tripped=s.tripped,
            warning=self._warning(),
        )

    def _warning(self) -> bool:
        return (
            self.warning or self._comm_warning or (self.starter.thermal_pct >= WARNING_THERMAL_PCT)
        )


_RAMPING: Final = frozenset({StarterState.STARTING, StarterState.STOPPING})
_READY: Final = StarterState.READY
