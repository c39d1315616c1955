"""Simulated WEG CFW-11, CFW700 and CFW320 behind the generic DP slave simulator.

Sans-IO, clock injected: every call takes ``now``. Built on the shared motor physics
(:class:`gateway.sim.Motor`) and fault slot (:class:`gateway.sim.FaultInjector`), and on the
same codecs and word layouts as the profiles. What each model does is its manual's:

* cyclic words of the manufacturer profile (P0680/P0681 in, P0684/P0685 out, the four
  direction cases of P0685) and of the PROFIdrive profile (P0967/P0968 state machine,
  4000h = P0134), words 3..N mapped to parameters (P0742.., P0750.. / P746..);
* the parameter table (:mod:`.simparams`) through records 47 and 48 with the manuals'
  errors (read-only, out of range, CFG while running, unknown parameter or subindex);
* ramps P0100/P0101 (P0102/P0103 with the second ramp), local/remote and the command
  sources P0220-P0228, faults until reset, and the reaction to lost communication per
  P0313 with A138/A139 or F238/F239.

The host calls :meth:`WegSim.comm_lost` on watchdog expiry and :meth:`WegSim.clear_mode`
on Global_Control Clear / Operate (A138 needs to tell them apart).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from enum import Enum
from typing import TYPE_CHECKING, ClassVar, Final

from adapters.profibus import profidrive as pd
from adapters.profibus import wegrecord
from adapters.profibus.chkcfg import CompactId, IoDirection
from adapters.profibus.dpv1 import WEG_ERROR_CODE_1_TEXTS
from adapters.profibus.errors import ProfibusDecodeError
from adapters.profibus.profile import RecordAccessError, SimDeviceBase
from adapters.profibus.weg import simparams as sp
from adapters.profibus.weg import spec as specs
from adapters.profibus.weg import words as w
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.spec import DataProfile, ModelSpec
from gateway.model import Device
from gateway.sim import FaultInjector, Motor, MotorParams

if TYPE_CHECKING:
    from gateway.config import DriveConfig

log = logging.getLogger(__name__)

# DP-V1 Error_Code_1 (CFW-11 4.2.3, CFW700 5.2.3, CFW320 5.2.3).
E_SLOT: Final = 0xB0
E_INDEX: Final = 0xB2
E_NOT_ALLOWED: Final = 0xB5
E_READ_ONLY: Final = 0xB6
E_VALUES: Final = 0xB7
E_PARAMETER: Final = 0xB8
E_NOT_AVAILABLE: Final = 0xC3

# Record 47 error numbers (Table 4.2 / 5.2).
PD_NO_PARAMETER: Final = 0x0000
PD_READ_ONLY: Final = 0x0001
PD_LIMITS: Final = 0x0002
PD_SUBINDEX: Final = 0x0003
PD_NO_ARRAY: Final = 0x0004
PD_FORMAT: Final = 0x0005
PD_NO_DESCRIPTION: Final = 0x0009
PD_NO_TEXT: Final = 0x000F
PD_ACCESS: Final = 0x0016
PD_VALUE_COUNT: Final = 0x0018


class Refusal(Enum):
    """Why the drive refuses a parameter change."""

    NO_PARAMETER = "no parameter"
    READ_ONLY = "read-only"
    LIMITS = "out of limits"
    RUNNING = "CFG parameter while running"


REFUSAL_47: Final[Mapping[Refusal, int]] = {
    Refusal.NO_PARAMETER: PD_NO_PARAMETER,
    Refusal.READ_ONLY: PD_READ_ONLY,
    Refusal.LIMITS: PD_LIMITS,
    Refusal.RUNNING: PD_ACCESS,  # Table 4.2 has no "state" error: "incorrect access"
}
REFUSAL_48: Final[Mapping[Refusal, int]] = {
    Refusal.NO_PARAMETER: E_PARAMETER,
    Refusal.READ_ONLY: E_READ_ONLY,
    Refusal.LIMITS: E_VALUES,
    Refusal.RUNNING: E_NOT_ALLOWED,  # "modification not allowed for the parameter"
}


def access_error(code_1: int) -> RecordAccessError:
    return RecordAccessError(WEG_ERROR_CODE_1_TEXTS.get(code_1, f"{code_1:02X}h"), code_1)


class PdState(Enum):
    """The simulator's PROFIdrive switching-on state (fact sheet 1.11: S1-S4)."""

    S1 = "switching on inhibited"
    S2 = "ready to switch on"
    S3 = "switched on"
    S4 = "operation"


class PdStop(Enum):
    OFF1 = "ramp stop, then ready to switch on"
    OFF3 = "quick stop, then switching on inhibited"


@dataclass(frozen=True)
class NetCommand:
    """The network's command as the drive holds it (P0684 bits and P0685, 13 bits)."""

    run: bool = False
    general_enable: bool = False
    forward: bool = True
    jog: bool = False
    remote: bool = True
    second_ramp: bool = False
    quick_stop: bool = False
    reference: int = 0  # P0685, signed 13-bit word


@dataclass(frozen=True)
class Panel:
    """The local (HMI) commands: stopped unless P0313 = 4 copied the network's."""

    run: bool = False
    reference_rpm: float = 0.0  # signed


class WegSim(SimDeviceBase):
    """A simulated WEG drive (one model per subclass); implements the SimDevice protocol."""

    handles_clear = True  # Clear is A138/F238 per P0313, not a lost communication

    spec: ClassVar[ModelSpec]

    def __init__(
        self,
        *,
        address: int = 1,
        words: int = 2,
        data_profile: DataProfile = DataProfile.MANUFACTURER,
        frame: int = 1,
        words_in: tuple[int, ...] = (),
        words_out: tuple[int, ...] = (),
        params: Mapping[int, int] | None = None,
        motor: MotorParams | None = None,
        ident_number: int | None = None,
        busy_reads: int = 0,
        now: float = 0.0,
    ) -> None:
        """Program the drive: address, telegram size, data profile (frame 20 on the CFW-11),
        word mapping and any other parameter values (``params``, raw words), as if set at the
        HMI before power-up. ``busy_reads``: DS_Reads answered C3h before each answer."""
        self.table = sp.PARAMETERS[self.spec.device]
        self.values: dict[int, int] = {
            n: p.default for n, p in self.table.items() if not p.live or p.network_only
        }
        self.values[313] = self.spec.comm_action_default
        self._program(
            address=address,
            n_words=words,
            profile=data_profile,
            frame=frame,
            words_in=words_in,
            words_out=words_out,
        )
        for number, value in (params or {}).items():
            self._store(number, value)
        self.ident_number = self.spec.default_ident if ident_number is None else ident_number
        self.faults: FaultInjector = FaultInjector()
        self.busy_reads = busy_reads
        self.motor = Motor(motor or self._motor_params())
        self.pinned: dict[int, int] = {}
        self.undervoltage = False
        self.config_mode = False
        # P0680 bits the simulator does not compute: set by a test or the fault-injection API
        self.fire_mode = False  # CFW320 Table 4.2 bit 2
        self.pid_automatic = False  # CFW-11 Table 3.2 bit 14
        self.record_read_lengths: list[tuple[int, int]] = []  # (index, length) of each DS_Read
        self.saved: dict[int, int] = {}  # CFW320: values before cyclic writes (not saved)
        self._power_up(now)

    # ------------------------------------------------------------------ programming

    def _program(
        self,
        *,
        address: int,
        n_words: int,
        profile: DataProfile,
        frame: int,
        words_in: tuple[int, ...],
        words_out: tuple[int, ...],
    ) -> None:
        spec = self.spec
        if profile not in spec.profiles or (frame == 20 and not spec.frame20):
            raise ValueError(f"the {spec.device.value} has no {profile.value} frame {frame}")
        if frame == 20:
            n_words, words_in, words_out = (
                specs.FRAME20_WORDS,
                specs.FRAME20_INPUTS,
                specs.FRAME20_OUTPUTS,
            )
        if not 2 <= n_words <= spec.max_words:
            raise ValueError(f"the {spec.device.value} takes 2..{spec.max_words} words")
        self._store(spec.address_param, address)
        self._store(spec.telegram_param, spec.telegram_code(n_words))
        if len(spec.profiles) > 1:
            self._store(741, profile.p0741)
        for i, param in enumerate(words_in):
            self._store(spec.read_map_param(i + 3), param)
        for i, param in enumerate(words_out):
            self._store(spec.write_map_param(i + 3), param)

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> WegSim:
        """The drive a configured drive describes (``simulate = true``): programmed as its
        profile options expect, at its address; a factory default one for ``None``."""
        if drive is None:
            return cls()
        if isinstance(drive.options, WegOptions):
            return cls.matching(drive.options, address=drive.address)
        return cls(address=drive.address)

    @classmethod
    def matching(
        cls,
        options: WegOptions,
        *,
        address: int = 1,
        params: Mapping[int, int] | None = None,
        motor: MotorParams | None = None,
        busy_reads: int = 0,
        now: float = 0.0,
    ) -> WegSim:
        """A drive programmed as a profile's options expect (telegram, profile, mapping)."""
        return cls(
            address=address,
            words=options.words,
            data_profile=options.data_profile,
            frame=options.frame,
            words_in=options.words_in,
            words_out=options.words_out,
            params=params,
            motor=motor,
            ident_number=options.ident_number,
            busy_reads=busy_reads,
            now=now,
        )

    def _store(self, number: int, value: int) -> None:
        """Set a parameter at the HMI (no checks but existence)."""
        if number not in self.table:
            raise KeyError(f"the {self.spec.device.value} has no {self.spec.pname(number)}")
        self.values[number] = value

    def _motor_params(self) -> MotorParams:
        v = self.values
        return MotorParams(
            rated_rpm=max(float(v[134]), 1.0),
            accel_time=v[100] / 10.0,
            decel_time=v[101] / 10.0,
            rated_current=max(v[401] / 10.0, 0.1),
            magnetising_current=max(v[401] / 10.0, 0.1) * 0.3,
        )

    def _power_up(self, now: float) -> None:
        self._time = now
        self.address = self.values[self.spec.address_param]
        self.n_words = self.spec.words_of(self.values[self.spec.telegram_param])
        profiles = self.spec.profiles
        pidrive = len(profiles) > 1 and self.values[741] == 0
        self.data_profile = DataProfile.PROFIDRIVE if pidrive else DataProfile.MANUFACTURER
        self.comm = specs.COMM_OFFLINE  # "initialized in the offline state" (A139 note)
        self.clear = False
        self.fault = 0
        self._fault_at = now
        self.alarm = 0
        self.net = NetCommand(remote=self.values[220] != sp.SRC_LOCREM_NET_LOC)
        self.panel = Panel()
        self.pd_state = PdState.S1
        self.pd_stop: PdStop | None = None
        self.stw1 = w.ProfidriveControl()
        self._reset_level = False
        self._online_since: float | None = None
        self._pending_47: bytes | None = None
        self._busy_left = 0
        self._selected_48: int | None = None
        self.motor.speed = 0.0
        self.motor.coast()
        self.faults.clear()

    # ------------------------------------------------------------------ SimDevice

    def expected_cfg(self) -> bytes:
        """One consistent word identifier for the telegram size (see docs/devices.md)."""
        return CompactId(
            IoDirection.INPUT_OUTPUT, self.n_words, words=True, consistent=True
        ).encode()

    def check_cfg(self, cfg: bytes) -> bool:
        """Chk_Cfg: False (P0740 = 3, configuration data error) unless it is ours."""
        if bytes(cfg) != self.expected_cfg():
            self.comm = specs.COMM_CFG_ERROR
            return False
        return True

    def set_prm(self, user_prm: bytes) -> bool:
        """Set_Prm: no user parameter data is defined (P0740 = 4 otherwise).

        The drive takes P0741/P0922 (P751) and, on the CFW700/CFW320, its address "only when
        there is no cyclic communication": here.
        """
        if user_prm:
            self.comm = specs.COMM_PRM_ERROR
            return False
        if self.comm in (specs.COMM_ONLINE, specs.COMM_CLEAR):
            log.info("%s: Set_Prm while exchanging: leaving data exchange", self.spec.device)
        self.comm = specs.COMM_OFFLINE
        self._take_offline_params()
        return True

    def _take_offline_params(self) -> None:
        """P0741, P0922 (P751) and, on the CFW700/CFW320, the address: taken "only when there
        is no cyclic communication with the master" (CFW-11 l.959-961, CFW700 l.922-924,
        l.1029, l.1172; CFW320 l.547, l.581): at Set_Prm and when cyclic data stops."""
        self.n_words = self.spec.words_of(self.values[self.spec.telegram_param])
        if len(self.spec.profiles) > 1:
            pidrive = self.values[741] == 0
            self.data_profile = DataProfile.PROFIDRIVE if pidrive else DataProfile.MANUFACTURER
        if not self.spec.address_needs_power_cycle:
            self.address = self.values[self.spec.address_param]

    def exchange(self, outputs: bytes, now: float) -> bytes:
        self.tick(now)
        self._go_online(now)
        if len(outputs) != 2 * self.n_words:
            log.warning(
                "%s: %d output bytes, expected %d", self.spec.device, len(outputs), 2 * self.n_words
            )
        elif not self.clear:
            self._take_outputs(struct.unpack(f">{self.n_words}H", outputs), now)
        self._drive_motor()
        return self._inputs()

    def comm_lost(self, now: float) -> None:
        """DP watchdog expired: offline, A139 or F239 per P0313 (section 5 / 6 / 7)."""
        self.tick(now)
        if self.comm not in (specs.COMM_ONLINE, specs.COMM_CLEAR):
            return  # "only if the transition from online to offline occurs"
        self.comm = specs.COMM_OFFLINE
        self.clear = False
        self._online_since = None
        self._comm_error(139)
        self._take_offline_params()

    def clear_mode(self, now: float, active: bool = True) -> None:
        """Global_Control Clear (A138/F238 per P0313) or Operate (the A138 alarm goes)."""
        self.tick(now)
        if active and self.comm == specs.COMM_ONLINE:
            self.comm = specs.COMM_CLEAR
            self.clear = True
            self._comm_error(138)
        elif not active and self.comm == specs.COMM_CLEAR:
            self.comm = specs.COMM_ONLINE
            self.clear = False
            if self.alarm == 138:
                self.alarm = 0

    def ext_diag(self) -> bytes:
        return b""  # the manuals define no device-related diagnosis

    def tick(self, now: float) -> None:
        """Advance the motor to ``now`` under the commands in force (an auto-reset due on
        the way happens at its own time)."""
        if now <= self._time:
            return
        if self.faults.fault_code is not None and not self.fault:
            self._trip(self.faults.fault_code)
        due = self.auto_reset_due()
        if due is not None and due <= now:
            self._advance_to(due)
            log.info("%s: auto-reset of F%03d (P0206)", self.spec.device, self.fault)
            self._reset_fault()
        self._advance_to(now)

    def _advance_to(self, when: float) -> None:
        dt = when - self._time
        if dt <= 0:
            return
        self._time = when
        self._drive_motor()
        self.motor.advance(dt)
        self._after_motion()

    def power_cycle(self, now: float) -> None:
        """Parameters kept (but the CFW320's cyclic writes, not saved: P746 note)."""
        for number, value in self.saved.items():
            self.values[number] = value
        self.saved.clear()
        self.pinned.clear()
        self._power_up(now)

    # ------------------------------------------------------------------ faults, alarms

    def inject_fault(self, code: int, now: float) -> None:
        """Trip with any fault code; the drive stops (coasts) and reports it until reset."""
        self.tick(now)
        self.faults.trip(code)
        self._trip(code)

    def keypad_reset(self, now: float) -> None:
        """The HMI's reset key: the fault clears behind the network's back. The run command
        in force (P0684 bit 0 is a level) applies again at once, as after any reset."""
        self.tick(now)
        if self.fault:
            log.info("%s: F%03d reset at the HMI", self.spec.device, self.fault)
        self._reset_fault()

    def auto_reset_due(self) -> float | None:
        """When the present fault resets by itself: P0206 seconds after the trip (0 = off;
        the programming manuals' auto-reset, docs/devices.md)."""
        seconds = self.values.get(206, 0)
        if not self.fault or seconds <= 0:
            return None
        return self._fault_at + seconds

    def inject_alarm(self, code: int) -> None:
        self.alarm = code

    def clear_alarm(self) -> None:
        self.alarm = 0

    def interface_error(self, now: float) -> None:
        """The control board cannot read the Profibus module: A140/F240 per P0313
        (CFW-11 / CFW700 section 5 / 6), F032 on the CFW320 (section 7)."""
        self.tick(now)
        code = self.spec.interface_fault
        if code is None:
            return
        if code < 100 or self.values[313] == specs.CommAction.FAULT.value:
            self._trip(code)
        else:
            self.alarm = code - 100

    def _trip(self, code: int) -> None:
        if self.fault:
            return  # one fault at a time (P0944: at most 1)
        self.fault = code
        self._fault_at = self._time
        self.motor.coast()
        self.pd_stop = None

    def _reset_fault(self) -> None:
        """Fault reset (P0684 bit 7 / P0967 bit 7 rising edge): clears the fault."""
        if not self.fault:
            return
        self.fault = 0
        self.faults.clear()
        self.pd_state = PdState.S1
        if self.data_profile is DataProfile.PROFIDRIVE:
            # switching on inhibited: no operation until ON = 0 then ON = 1 (fact sheet
            # 1.11); the manufacturer profile's P0684 bit 0 is a level and applies again
            self.net = replace(self.net, run=False, jog=False, general_enable=False)

    def _comm_error(self, alarm: int) -> None:
        """P0313 reaction to a communication error (Table 3.3.1 / 4.1 / 4.1).

        The actions write the control-word bits (P0684) the network holds, so they act only
        where the network is a command source. 5 trips F2xx instead of the A1xx alarm.
        """
        action = specs.CommAction(self.values[313])
        if action is specs.CommAction.FAULT:
            self._trip(alarm + 100)
            return
        self.alarm = alarm
        handler = _COMM_ACTIONS.get(action)
        if handler is not None:
            handler(self)
        self.values[684] = self._net_word()

    def _act_ramp_stop(self) -> None:
        self.net = replace(self.net, run=False)
        if self.pd_state is PdState.S4:
            self.pd_stop = PdStop.OFF1

    def _act_disable(self) -> None:
        self.net = replace(self.net, general_enable=False, run=False)
        self.pd_state = PdState.S1
        self.pd_stop = None

    def _act_local(self) -> None:
        self.net = replace(self.net, remote=False)

    def _act_local_keep(self) -> None:
        remote = self._remote()
        self.panel = Panel(run=self._run_command(remote), reference_rpm=self._reference_rpm(remote))
        self.net = replace(self.net, remote=False)

    # ------------------------------------------------------------------ cyclic data

    def _go_online(self, now: float) -> None:
        if self.comm == specs.COMM_OFFLINE:
            self.comm = specs.COMM_ONLINE
            self._online_since = now
            if self.alarm == 139:
                self.alarm = 0  # "disappears when the cyclic communication is reestablished"

    def _take_outputs(self, words: tuple[int, ...], now: float) -> None:
        if self.data_profile is DataProfile.PROFIDRIVE:
            self._take_profidrive(words[0], w.signed(words[1]))
        else:
            self._take_manufacturer(words[0], w.signed(words[1]))
        delay = self.values.get(799, 0) / 10.0  # P0799 (CFW-11): I/O update delay
        if self._online_since is not None and now - self._online_since < delay:
            return
        for i, word in enumerate(words[2:]):
            param = self.values[self.spec.write_map_param(i + 3)]
            if param:
                self._cyclic_write(param, word)

    def _take_manufacturer(self, word: int, reference: int) -> None:
        """P0684 (Table 3.3 / 4.3) and P0685."""
        c = w.ManufacturerControl.decode(word, self.spec.control_bits)
        if c.fault_reset and not self._reset_level:
            self._reset_fault()
        self._reset_level = c.fault_reset
        self.net = NetCommand(
            run=c.run,
            general_enable=c.general_enable,
            forward=c.forward,
            jog=c.jog,
            remote=c.remote,
            second_ramp=c.second_ramp,
            quick_stop=c.quick_stop,
            reference=reference,
        )
        self.values[684] = word
        self.values[685] = w.to_word(reference)

    def _take_profidrive(self, word: int, nsoll: int) -> None:
        """P0967 STW1 (Table 3.8 / 4.7) through the switching-on states; NSOLL -> P0685."""
        c = w.ProfidriveControl.decode(word, w.STW1_BITS)
        self.stw1 = c
        self.values[967] = word
        if c.fault_ack and not self._reset_level:
            self._reset_fault()
        self._reset_level = c.fault_ack
        if not self.fault:
            self._step_state(c)
        rpm = nsoll * self.values[134] / w.PROFIDRIVE_SPEED_BASE
        reference = w.speed_to_raw(rpm, self._sync_rpm(), w.SPEED_13BIT_BASE)
        operation = self.pd_state is PdState.S4 and not self.fault
        self.net = NetCommand(
            run=operation and c.on and c.enable_ramp and self.pd_stop is None,
            general_enable=operation and c.no_coast_stop,
            forward=True,  # reversal by a negative reference (P0967 note)
            jog=operation and c.jog,
            remote=c.control_by_plc,
            quick_stop=self.pd_stop is PdStop.OFF3,
            reference=reference if c.enable_setpoint else 0,  # bit 6: 0 zeroes the reference
        )
        self.values[685] = w.to_word(self.net.reference)
        self.values[684] = self._net_word()

    def _step_state(self, c: w.ProfidriveControl) -> None:
        """One step of the PROFIdrive switching-on state machine (fact sheet 1.11)."""
        state = self.pd_state
        if self.undervoltage or self.config_mode or not c.no_coast_stop:
            self.pd_state, self.pd_stop = PdState.S1, None  # OFF2: coast, inhibited
        elif state is PdState.S1:
            if not c.on and c.no_quick_stop:
                self.pd_state = PdState.S2
        elif state is PdState.S2:
            if not c.no_quick_stop:
                self.pd_state = PdState.S1
            elif c.on:
                self.pd_state = PdState.S4 if c.enable_operation else PdState.S3
        elif not c.no_quick_stop:
            self._stop_or_go(PdStop.OFF3, PdState.S1)
        elif not c.on:
            self._stop_or_go(PdStop.OFF1, PdState.S2)
        else:
            self.pd_stop = None
            self.pd_state = PdState.S4 if c.enable_operation else PdState.S3

    def _stop_or_go(self, stop: PdStop, then: PdState) -> None:
        if self.pd_state is PdState.S4 and self.motor.speed != 0.0:
            self.pd_stop = stop
        else:
            self.pd_state, self.pd_stop = then, None

    def _cyclic_write(self, number: int, word: int) -> None:
        """A word mapped by P0750../P746..: written like any write (refusals ignored)."""
        before = self.values.get(number)
        refusal = self.write_param(number, word)
        if refusal is not None:
            log.debug("%s: cyclic write of %s refused: %s", self.spec.device, number, refusal)
        elif self.spec.device is Device.CFW320 and before is not None:
            self.saved.setdefault(number, before)  # P746 note: not saved in memory

    def _net_word(self) -> int:
        n = self.net
        control = w.ManufacturerControl(
            run=n.run,
            general_enable=n.general_enable,
            forward=n.forward,
            jog=n.jog,
            remote=n.remote,
            second_ramp=n.second_ramp,
            quick_stop=n.quick_stop,
        )
        return control.encode(self.spec.control_bits)

    # ------------------------------------------------------------------ the drive

    def _remote(self) -> bool:
        """LOC/REM per P0220 (always local/remote, or the network's bit 4 / STW1 bit 10)."""
        source = self.values[220]
        if source == sp.SRC_LOCREM_ALWAYS_LOCAL:
            return False
        if source == sp.SRC_LOCREM_ALWAYS_REMOTE:
            return True
        if source in (sp.SRC_LOCREM_NET_LOC, sp.SRC_LOCREM_NET_REM):
            return self.net.remote
        return False  # HMI key or digital input: local in the simulator

    def _sources(self, remote: bool) -> tuple[int, int, int, int]:
        """(run/stop, reference, direction, JOG) sources: P0227/222/226/228 or 224/221/223/225."""
        v = self.values
        return (v[227], v[222], v[226], v[228]) if remote else (v[224], v[221], v[223], v[225])

    def _run_command(self, remote: bool) -> bool:
        run_src = self._sources(remote)[0]
        return self.net.run if run_src == sp.SRC_RUN_NET else self.panel.run

    def _sync_rpm(self) -> float:
        try:
            return w.synchronous_rpm(float(self.values[403]), float(self.values[402]))
        except ValueError:
            return 1800.0

    def _reference_rpm(self, remote: bool) -> float:
        """Signed reference in rpm, clamped to P0134."""
        _, ref_src, dir_src, _ = self._sources(remote)
        if ref_src != sp.SRC_REF_NET:
            return self.panel.reference_rpm
        if dir_src in sp.SRC_DIR_NET:
            raw = w.effective_reference(self.net.forward, self.net.reference)
        else:
            raw = abs(self.net.reference) * (-1 if dir_src == sp.SRC_DIR_REVERSE else 1)
        rpm = w.raw_to_speed(raw, self._sync_rpm(), w.SPEED_13BIT_BASE)
        limit = float(self.values[134])
        return max(-limit, min(limit, rpm))

    def _general_enabled(self, remote: bool) -> bool:
        """General enable in force and nothing keeping the drive off (P0680 bit 9: "active
        and the inverter is ready to run the motor"): P0684 bit 1 where the network gives
        the run/stop commands (the HMI's enable otherwise), no fault, undervoltage or
        configuration mode."""
        network = self._sources(remote)[0] == sp.SRC_RUN_NET
        enable = self.net.general_enable if network else True
        return enable and not (self.fault or self.undervoltage or self.config_mode)

    def _drive_motor(self) -> None:
        """Commands in force -> motor: fault, disable, quick stop, JOG, run, stop."""
        m = self.motor
        m.params = replace(m.params, rated_rpm=max(float(self.values[134]), 1.0))
        second = self._second_ramp()
        m.accel_time = self.values[102 if second else 100] / 10.0
        m.decel_time = self.values[103 if second else 101] / 10.0
        remote = self._remote()
        run_src, _, _, jog_src = self._sources(remote)
        network = run_src == sp.SRC_RUN_NET
        quick = network and self.net.quick_stop and self._executes_quick_stop()
        jog = jog_src == sp.SRC_JOG_NET and self.net.jog
        if not self._general_enabled(remote):
            m.coast()
        elif quick:
            if m.speed != 0.0:
                m.quick_stop()
            else:
                m.command(False, 0.0)
        elif jog:
            m.command(True, sp.JOG_RPM if self.net.forward else -sp.JOG_RPM)
        elif self._run_command(remote):
            m.command(True, self._reference_rpm(remote))
        elif m.speed != 0.0 and m.enabled:
            m.command(True, 0.0)  # ramp down, then the output goes off
        else:
            m.command(False, 0.0)

    def _executes_quick_stop(self) -> bool:
        """P0684 bit 6 acts: the model has it and, on the CFW700, P0202 is a vector type.

        CFW700 P0684 bit 6: "This function is not allowed with control types (P0202) V/f
        or VVW": the simulated CFW700 ignores the bit there (the motor keeps the run/stop
        bit's command). The CFW-11 manual only advises against it: it executes it. The
        PROFIdrive OFF3 (P0967 bit 2, "not recommended" on both) is always executed.
        """
        if not self.spec.quick_stop:
            return False
        if self.data_profile is DataProfile.PROFIDRIVE:
            return True
        ramp_only = self.spec.quick_stop_as_ramp(self.values.get(202, 0))
        return not (self.spec.quick_stop_ignored_ramp_only and ramp_only)

    def _second_ramp(self) -> bool:
        source = self.values[105]
        if source == sp.SRC_RAMP_SECOND:
            return True
        return source == sp.SRC_RAMP_NET and self.net.second_ramp

    def _after_motion(self) -> None:
        m = self.motor
        if (
            m.speed == 0.0
            and m.enabled
            and m.reference == 0.0
            and not self._run_command(self._remote())
        ):
            m.command(False, 0.0)
        if self.pd_stop is not None and m.speed == 0.0:
            self.pd_state = PdState.S2 if self.pd_stop is PdStop.OFF1 else PdState.S1
            self.pd_stop = None

    # ------------------------------------------------------------------ status

    @property
    def running(self) -> bool:
        """P0680 bit 8: turning at the reference or on a ramp (the ramp is enabled)."""
        m = self.motor
        return (
            m.enabled
            and not self.fault
            and (self._run_command(self._remote()) or m.speed != 0.0 or self.net.jog)
        )

    @property
    def forward(self) -> bool:
        """P0680 bit 10: the direction turning, or the one commanded at standstill."""
        m = self.motor
        if m.speed != 0.0:
            return m.speed > 0
        if m.reference != 0.0:
            return m.reference > 0
        return self._reference_rpm(self._remote()) >= 0 if self._remote() else True

    def _torque_fraction(self) -> float:
        m = self.motor
        if not m.enabled:
            return 0.0
        frac = abs(m.speed) / max(self._sync_rpm(), 1.0)
        accelerating = m.speed != m.reference and abs(m.reference) > abs(m.speed)
        return m.params.load * frac + (0.3 if accelerating else 0.0)

    def status_word(self) -> int:
        """P0680 (Table 3.2 / 4.2 / 4.2): the model's own bits only."""
        run_cmd = self._run_command(self._remote())
        status = w.ManufacturerStatus(
            run_command=run_cmd and not self.fault,
            fire_mode=self.fire_mode,
            automatic=self.pid_automatic,
            quick_stop_active=self.motor.quick_stopping,
            second_ramp=self._second_ramp(),
            config_mode=self.config_mode,
            alarm=self.alarm != 0,
            running=self.running,
            general_enable=self._general_enabled(self._remote()),
            forward=self.forward,
            jog=self.net.jog and self.motor.enabled,
            remote=self._remote(),
            undervoltage=self.undervoltage,
            fault=self.fault != 0,
        )
        return status.encode(self.spec.status_bits)

    def zsw1(self) -> int:
        """P0968 (Table 3.9 / 4.8)."""
        fault = self.fault != 0
        state = self.pd_state
        inhibited = state is PdState.S1 or self.undervoltage or self.config_mode
        m = self.motor
        reached = state is PdState.S4 and self.net.run and m.speed == m.reference and m.speed != 0.0
        status = w.ProfidriveStatus(
            ready_to_switch_on=not fault and not inhibited,
            ready_to_operate=not fault and state in (PdState.S3, PdState.S4),
            operation_enabled=not fault and state is PdState.S4,
            fault=fault,
            coast_stop_not_active=self.stw1.no_coast_stop,
            quick_stop_not_active=self.stw1.no_quick_stop and self.pd_stop is not PdStop.OFF3,
            switching_on_inhibited=not fault and inhibited,
            warning=self.alarm != 0,
            control_requested=self._remote(),
            frequency_reached=not fault and reached,
        )
        return status.encode(self.spec.zsw1_bits)

    def _inputs(self) -> bytes:
        if self.data_profile is DataProfile.PROFIDRIVE:
            speed = w.speed_to_raw(
                self.motor.speed, float(self.values[134] or 1), w.PROFIDRIVE_SPEED_BASE
            )
            first = [self.zsw1(), w.to_word(speed)]
        else:
            first = [self.status_word(), self.param(681)]
        mapped = [
            self.param(p) if (p := self.values[self.spec.read_map_param(i + 3)]) else 0
            for i in range(self.n_words - 2)
        ]
        return struct.pack(f">{self.n_words}H", *first, *mapped)

    # ------------------------------------------------------------------ parameters

    def param(self, number: int, subindex: int = 0) -> int:
        """A parameter's raw word (live ones computed now); KeyError if the model has none."""
        if number not in self.table:
            raise KeyError(number)
        if number in self.pinned:
            return self.pinned[number]
        getter = _LIVE.get(number)
        if getter is not None and self.table[number].live and not self.table[number].network_only:
            return getter(self, subindex) & 0xFFFF
        return self.values[number] & 0xFFFF

    def pin(self, number: int, raw: int) -> None:
        """Hold a parameter's reading at ``raw`` (tests reproducing the manuals' examples)."""
        self.pinned[number] = raw

    def write_param(self, number: int, raw: int) -> Refusal | None:
        """Change a parameter as a network write does; the refusal, or None when done."""
        p = self.table.get(number)
        if p is None:
            return Refusal.NO_PARAMETER
        if p.read_only or p.network_only:
            return Refusal.READ_ONLY
        value = w.signed(raw) if p.signed else raw & 0xFFFF
        if not p.low <= value <= p.high:
            return Refusal.LIMITS
        if p.cfg and self.running:
            return Refusal.RUNNING
        self.values[number] = value
        return None

    # ------------------------------------------------------------------ DP-V1 records

    def write_record(self, slot: int, index: int, data: bytes, now: float) -> None:
        self.tick(now)
        if slot != 0:
            raise access_error(E_SLOT)
        if index == pd.PARAMETER_INDEX:
            self._request_47(bytes(data))
        elif index == wegrecord.WEG_RECORD_INDEX:
            self._request_48(bytes(data))
        else:
            raise access_error(E_INDEX)

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        self.tick(now)
        self.record_read_lengths = [*self.record_read_lengths[-15:], (index, length)]
        if slot != 0:
            raise access_error(E_SLOT)
        if index == pd.PARAMETER_INDEX:
            if self._pending_47 is None or self._busy_left > 0:
                self._busy_left = max(0, self._busy_left - 1)
                raise access_error(E_NOT_AVAILABLE)
            data, self._pending_47 = self._pending_47, None
            return data[:length]
        if index == wegrecord.WEG_RECORD_INDEX:
            if self._selected_48 is None:
                raise access_error(E_NOT_AVAILABLE)
            return wegrecord.WegValue(self.param(self._selected_48)).encode()[:length]
        raise access_error(E_INDEX)

    def _request_48(self, data: bytes) -> None:
        """WEG record 48 (4.2.6 / 5.2.5 / 5.2.4): 2 bytes select, 4 bytes change."""
        try:
            request = wegrecord.decode_write_data(data)
        except ProfibusDecodeError:
            raise access_error(E_VALUES) from None
        if isinstance(request, wegrecord.WegSelect):
            if request.number not in self.table:
                raise access_error(E_PARAMETER)
            self._selected_48 = request.number
            return
        refusal = self.write_param(request.number, request.value)
        if refusal is not None:
            raise access_error(REFUSAL_48[refusal])

    def _request_47(self, data: bytes) -> None:
        """PROFIdrive record 47 (4.2.4 / 5.2.4): checked, then answered at the next read."""
        try:
            request = pd.ParameterRequest.decode(data)
        except ProfibusDecodeError:
            raise access_error(E_VALUES) from None
        if request.request_id is pd.RequestId.READ:
            response = self._read_47(request)
        else:
            response = self._change_47(request)
        self._pending_47 = response.encode()
        self._busy_left = self.busy_reads

    def _read_47(self, request: pd.ParameterRequest) -> pd.ParameterResponse:
        blocks = [self._read_block(a) for a in request.parameters]
        failed = any(b.is_error for b in blocks)
        rid = pd.ResponseId.READ_ERROR if failed else pd.ResponseId.READ_OK
        return pd.ParameterResponse(
            request.reference, rid, len(blocks), tuple(blocks), request.axis
        )

    def _read_block(self, a: pd.ParameterAddress) -> pd.ValueBlock:
        if a.attribute is pd.Attribute.DESCRIPTION:
            return pd.ValueBlock.error(PD_NO_DESCRIPTION)
        if a.attribute is pd.Attribute.TEXT:
            return pd.ValueBlock.error(PD_NO_TEXT)
        p = self.table.get(a.number)
        if p is None:
            return pd.ValueBlock.error(PD_NO_PARAMETER)
        count = max(1, a.elements)
        if p.array:
            if a.subindex + count > p.array:
                return pd.ValueBlock.error(PD_SUBINDEX)
            return pd.ValueBlock.word(*(self.param(a.number, a.subindex + i) for i in range(count)))
        if a.subindex:
            return pd.ValueBlock.error(PD_SUBINDEX)
        if count > 1:
            return pd.ValueBlock.error(PD_NO_ARRAY)
        return pd.ValueBlock.word(self.param(a.number))

    def _change_47(self, request: pd.ParameterRequest) -> pd.ParameterResponse:
        codes = [
            self._change_one(a, v) for a, v in zip(request.parameters, request.values, strict=True)
        ]
        n = len(codes)
        if all(c is None for c in codes):
            return pd.ParameterResponse.change_ok(request.reference, n, request.axis)
        blocks = tuple(
            pd.ValueBlock(pd.DataFormat.ZERO) if c is None else pd.ValueBlock.error(c)
            for c in codes
        )
        # The manuals' negative change answer (CFW-11 4.2.5, CFW320 5.2.5) declares 2
        # parameters for a one-parameter change: the simulator answers exactly that.
        count = 2 if n == 1 else n
        return pd.ParameterResponse(
            request.reference, pd.ResponseId.CHANGE_ERROR, count, blocks, request.axis
        )

    def _change_one(self, a: pd.ParameterAddress, v: pd.ValueBlock) -> int | None:
        if a.attribute is not pd.Attribute.VALUE:
            return PD_ACCESS
        p = self.table.get(a.number)
        if p is None:
            return PD_NO_PARAMETER
        if p.array:
            return PD_READ_ONLY if a.subindex < p.array else PD_SUBINDEX
        if a.subindex:
            return PD_SUBINDEX
        if a.elements > 1:
            return PD_NO_ARRAY
        if v.format is not pd.DataFormat.WORD:
            return PD_FORMAT  # "the value 42h (16 bit word) must be used"
        if len(v.values) != 1:
            return PD_VALUE_COUNT
        refusal = self.write_param(a.number, int(v.values[0]))
        return None if refusal is None else REFUSAL_47[refusal]


# ---------------------------------------------------------------------- live parameters


def _speed_rpm(sim: WegSim, _: int) -> int:
    return round(abs(sim.motor.speed))  # P0002 motor speed, rpm


def _current(sim: WegSim, _: int) -> int:
    return round(sim.motor.current() * 10)  # P0003, one decimal


def _power(sim: WegSim, _: int) -> int:
    rated = sim.values.get(404, 55) / 10.0
    frac = abs(sim.motor.speed) / max(sim._sync_rpm(), 1.0)
    return round(rated * sim._torque_fraction() * frac * 10)  # P0010 kW, one decimal


def _speed_13(sim: WegSim, _: int) -> int:
    return w.to_word(w.speed_to_raw(sim.motor.speed, sim._sync_rpm(), w.SPEED_13BIT_BASE))


def _pd_fraction(value: float) -> int:
    """P0760-P0762: 0 to 16384 (0x4000 = 100 %), the manual's range."""
    return max(0, min(w.PROFIDRIVE_PERCENT_BASE, round(value * w.PROFIDRIVE_PERCENT_BASE)))


def _pd_current(sim: WegSim, _: int) -> int:
    return _pd_fraction(sim.motor.current() / max(sim.values[401] / 10.0, 0.1))


def _pd_power(sim: WegSim, sub: int) -> int:
    return _pd_fraction(_power(sim, sub) / max(sim.values[404], 1))  # (P0010 / P0404) x 4000h


def _pd_torque(sim: WegSim, _: int) -> int:
    return _pd_fraction(sim._torque_fraction())


def _namur(sim: WegSim, _: int) -> int:
    """P0763 (Table 3.7): the bit whose faults include the present one."""
    return sum(1 << bit for bit, _, codes in w.NAMUR_BITS if sim.fault in codes)


def _fw_id(sim: WegSim, sub: int) -> int:
    """P0964 subindices 0-4: 367, 4, P0023, year, ddmm."""
    return (367, 4, sim.values.get(23, 0), 2024, 101)[sub]


def _inverter_state(sim: WegSim, _: int) -> int:
    """CFW320 P006 as the simulator numbers it: 0 ready, 1 run, 2 undervoltage, 3 fault."""
    if sim.fault:
        return 3
    if sim.undervoltage:
        return 2
    return 1 if sim.running else 0


_LIVE: Final[Mapping[int, Callable[[WegSim, int], int]]] = {
    2: _speed_rpm,
    3: _current,
    6: _inverter_state,
    10: _power,
    48: lambda sim, _: sim.alarm,
    49: lambda sim, _: sim.fault,
    680: lambda sim, _: sim.status_word(),
    681: _speed_13,
    692: lambda sim, _: 0,
    740: lambda sim, _: sim.comm,
    760: _pd_current,
    761: _pd_power,
    762: _pd_torque,
    763: _namur,
    944: lambda sim, _: 1 if sim.fault else 0,  # P0944: at most 1, reset with the fault
    947: lambda sim, _: sim.fault,
    964: _fw_id,
    968: lambda sim, _: sim.zsw1(),
}

_COMM_ACTIONS: Final[Mapping[specs.CommAction, Callable[[WegSim], None]]] = {
    specs.CommAction.RAMP_STOP: WegSim._act_ramp_stop,
    specs.CommAction.GENERAL_DISABLE: WegSim._act_disable,
    specs.CommAction.GO_TO_LOCAL: WegSim._act_local,
    specs.CommAction.LOCAL_KEEP: WegSim._act_local_keep,
}


class Cfw11Sim(WegSim):
    """Simulated CFW-11 (manufacturer or PROFIdrive profile, frame 20, 2-10 words)."""

    spec: ClassVar[ModelSpec] = specs.CFW11


class Cfw700Sim(WegSim):
    """Simulated CFW700 (manufacturer or PROFIdrive profile, 2-10 words)."""

    spec: ClassVar[ModelSpec] = specs.CFW700


class Cfw320Sim(WegSim):
    """Simulated CFW320 (manufacturer profile, 2-6 words, address P750, no quick stop)."""

    spec: ClassVar[ModelSpec] = specs.CFW320
