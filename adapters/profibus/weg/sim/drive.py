"""Simulated WEG CFW-11, CFW700 and CFW320 behind the generic DP slave simulator.

Sans-IO, clock injected: every call takes ``now``. Built on the shared motor physics
(:class:`gateway.sim.Motor`) and fault slot (:class:`gateway.sim.FaultInjector`), and on the
same codecs and word layouts as the profiles. What each model does is its manual's:

* cyclic words of the manufacturer profile (P0680/P0681 in, P0684/P0685 out, the four
  direction cases of P0685: :mod:`.manufacturer`) and of the PROFIdrive profile
  (P0967/P0968 state machine, 4000h = P0134: :mod:`.profidrive`), words 3..N mapped to
  parameters (P0742.., P0750.. / P746..);
* the parameter table (:mod:`.params`) through records 47 and 48 with the manuals'
  errors (read-only, out of range, CFG while running, unknown parameter or subindex:
  :mod:`.records`);
* ramps P0100/P0101 (P0102/P0103 with the second ramp), local/remote and the command
  sources P0220-P0228 (:mod:`.commands`), faults until reset, and the reaction to lost
  communication per P0313 with A138/A139 or F238/F239 (:mod:`.commloss`).

The host calls :meth:`WegSim.comm_lost` on watchdog expiry and :meth:`WegSim.clear_mode`
on Global_Control Clear / Operate (A138 needs to tell them apart).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, ClassVar, Final

from adapters.profibus.codec.chkcfg import CompactId, IoDirection
from adapters.profibus.weg import spec as specs
from adapters.profibus.weg import words as w
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.busside import SyncFreeze, WegBusSide
from adapters.profibus.weg.sim.commands import Commands, NetCommand, Panel, sync_rpm
from adapters.profibus.weg.sim.commloss import COMM_ACTIONS
from adapters.profibus.weg.sim.dataprofile import PdState, PdStop, SimDataWords
from adapters.profibus.weg.sim.manufacturer import ManufacturerSimWords
from adapters.profibus.weg.sim.profidrive import ProfidriveSimWords
from adapters.profibus.weg.sim.programming import motor_params, programming
from adapters.profibus.weg.sim.records import Records, Refusal
from adapters.profibus.weg.spec import DataProfile, ModelSpec
from gateway.model import Device
from gateway.sim import FaultInjector, Motor, MotorParams

if TYPE_CHECKING:
    from gateway.config import DriveConfig

log = logging.getLogger(__name__)

SIM_DATA_WORDS: Final[Mapping[DataProfile, SimDataWords]] = {
    DataProfile.MANUFACTURER: ManufacturerSimWords(),
    DataProfile.PROFIDRIVE: ProfidriveSimWords(),
}
"""The words of each data profile (P0741) on the drive's side."""


class WegSim(WegBusSide):
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
        programmed = programming(
            self.spec,
            address=address,
            n_words=words,
            profile=data_profile,
            frame=frame,
            words_in=words_in,
            words_out=words_out,
        )
        for number, value in [*programmed, *(params or {}).items()]:
            self._store(number, value)
        self.ident_number = self.spec.default_ident if ident_number is None else ident_number
        self.faults: FaultInjector = FaultInjector()
        self.busy_reads = busy_reads
        self.motor = Motor(motor or motor_params(self.values))
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

    def _power_up(self, now: float) -> None:
        self._time = now
        self.address = self.values[self.spec.address_param]
        self.n_words = self.spec.words_of(self.values[self.spec.telegram_param])
        profiles = self.spec.profiles
        pidrive = len(profiles) > 1 and self.values[741] == 0
        self.data_profile = DataProfile.PROFIDRIVE if pidrive else DataProfile.MANUFACTURER
        self.data_words = SIM_DATA_WORDS[self.data_profile]
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
        self._records = Records(self)
        self.sync_freeze = SyncFreeze()
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
            self.data_words = SIM_DATA_WORDS[self.data_profile]
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
            taken = self.sync_freeze.outputs(struct.unpack(f">{self.n_words}H", outputs))
            if taken is not None:
                self._take_outputs(taken, now)
        self._drive_motor()
        return self.sync_freeze.inputs(self._inputs())

    def comm_lost(self, now: float) -> None:
        """DP watchdog expired: offline, A139 or F239 per P0313 (section 5 / 6 / 7)."""
        self.tick(now)
        if self.comm not in (specs.COMM_ONLINE, specs.COMM_CLEAR):
            return  # "only if the transition from online to offline occurs"
        self.comm = specs.COMM_OFFLINE
        self.clear = False
        self.sync_freeze = SyncFreeze()
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
        self.net = self.data_words.after_reset(self.net)

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
        handler = COMM_ACTIONS.get(action)
        if handler is not None:
            handler(self)
        self.values[684] = self.net.control_word(self.spec.control_bits)

    # ------------------------------------------------------------------ cyclic data

    def _go_online(self, now: float) -> None:
        if self.comm == specs.COMM_OFFLINE:
            self.comm = specs.COMM_ONLINE
            self._online_since = now
            if self.alarm == 139:
                self.alarm = 0  # "disappears when the cyclic communication is reestablished"

    def _take_outputs(self, words: tuple[int, ...], now: float) -> None:
        reset = self.data_words.fault_reset(self, words[0])
        if reset and not self._reset_level:
            self._reset_fault()  # a rising edge of P0684 bit 7 / STW1 bit 7
        self._reset_level = reset
        self.data_words.take(self, words[0], w.signed(words[1]))
        delay = self.values.get(799, 0) / 10.0  # P0799 (CFW-11): I/O update delay
        if self._online_since is not None and now - self._online_since < delay:
            return
        for i, word in enumerate(words[2:]):
            param = self.values[self.spec.write_map_param(i + 3)]
            if param:
                self._cyclic_write(param, word)

    def _cyclic_write(self, number: int, word: int) -> None:
        """A word mapped by P0750../P746..: written like any write (refusals ignored)."""
        before = self.values.get(number)
        refusal = self.write_param(number, word)
        if refusal is not None:
            log.debug("%s: cyclic write of %s refused: %s", self.spec.device, number, refusal)
        elif self.spec.device is Device.CFW320 and before is not None:
            self.saved.setdefault(number, before)  # P746 note: not saved in memory

    # ------------------------------------------------------------------ the drive

    @property
    def commands(self) -> Commands:
        """The commands in force: the network's or the HMI's, as P0105, P0220-P0228 say."""
        return Commands(self.values, self.net, self.panel)

    def general_enabled(self, remote: bool) -> bool:
        """General enable in force and nothing keeping the drive off (P0680 bit 9: "active
        and the inverter is ready to run the motor"): P0684 bit 1 where the network gives
        the run/stop commands (the HMI's enable otherwise), no fault, undervoltage or
        configuration mode."""
        network = self.commands.sources(remote)[0] == sp.SRC_RUN_NET
        enable = self.net.general_enable if network else True
        return enable and not (self.fault or self.undervoltage or self.config_mode)

    def _drive_motor(self) -> None:
        """Commands in force -> motor: fault, disable, quick stop, JOG, run, stop."""
        m = self.motor
        m.params = replace(m.params, rated_rpm=max(float(self.values[134]), 1.0))
        commands = self.commands
        second = commands.second_ramp()
        m.accel_time = self.values[102 if second else 100] / 10.0
        m.decel_time = self.values[103 if second else 101] / 10.0
        remote = commands.remote()
        run_src, _, _, jog_src = commands.sources(remote)
        network = run_src == sp.SRC_RUN_NET
        executes = self.spec.quick_stop and self.data_words.executes_quick_stop(self)
        quick = network and self.net.quick_stop and executes
        jog = jog_src == sp.SRC_JOG_NET and self.net.jog
        if not self.general_enabled(remote):
            m.coast()
        elif quick:
            if m.speed != 0.0:
                m.quick_stop()
            else:
                m.command(False, 0.0)
        elif jog:
            m.command(True, sp.JOG_RPM if self.net.forward else -sp.JOG_RPM)
        elif commands.run_command(remote):
            m.command(True, commands.reference_rpm(remote))
        elif m.speed != 0.0 and m.enabled:
            m.command(True, 0.0)  # ramp down, then the output goes off
        else:
            m.command(False, 0.0)

    def _after_motion(self) -> None:
        m = self.motor
        if m.speed == 0.0 and m.enabled and m.reference == 0.0:
            commands = self.commands
            if not commands.run_command(commands.remote()):
                m.command(False, 0.0)
        if self.pd_stop is not None and m.speed == 0.0:
            self.pd_state = PdState.S2 if self.pd_stop is PdStop.OFF1 else PdState.S1
            self.pd_stop = None

    # ------------------------------------------------------------------ status

    @property
    def running(self) -> bool:
        """P0680 bit 8: turning at the reference or on a ramp (the ramp is enabled)."""
        m = self.motor
        if not m.enabled or self.fault:
            return False
        commands = self.commands
        return commands.run_command(commands.remote()) or m.speed != 0.0 or self.net.jog

    def status_word(self) -> int:
        """P0680 (Table 3.2 / 4.2 / 4.2), a live parameter in either data profile."""
        return SIM_DATA_WORDS[DataProfile.MANUFACTURER].status(self)

    def _inputs(self) -> bytes:
        first = [self.data_words.status(self), self.data_words.speed(self)]
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
        self._records.write(slot, index, bytes(data))

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        self.tick(now)
        self.record_read_lengths = [*self.record_read_lengths[-15:], (index, length)]
        return self._records.read(slot, index, length)


# ---------------------------------------------------------------------- live parameters


def _speed_rpm(sim: WegSim, _: int) -> int:
    return round(abs(sim.motor.speed))  # P0002 motor speed, rpm


def _current(sim: WegSim, _: int) -> int:
    return round(sim.motor.current() * 10)  # P0003, one decimal


def _torque_fraction(sim: WegSim) -> float:
    m = sim.motor
    if not m.enabled:
        return 0.0
    frac = abs(m.speed) / max(sync_rpm(sim.values), 1.0)
    accelerating = m.speed != m.reference and abs(m.reference) > abs(m.speed)
    return m.params.load * frac + (0.3 if accelerating else 0.0)


def _power(sim: WegSim, _: int) -> int:
    rated = sim.values.get(404, 55) / 10.0
    frac = abs(sim.motor.speed) / max(sync_rpm(sim.values), 1.0)
    return round(rated * _torque_fraction(sim) * frac * 10)  # P0010 kW, one decimal


def _speed_13(sim: WegSim, _: int) -> int:
    return w.to_word(w.speed_to_raw(sim.motor.speed, sync_rpm(sim.values), w.SPEED_13BIT_BASE))


def _pd_fraction(value: float) -> int:
    """P0760-P0762: 0 to 16384 (0x4000 = 100 %), the manual's range."""
    return max(0, min(w.PROFIDRIVE_PERCENT_BASE, round(value * w.PROFIDRIVE_PERCENT_BASE)))


def _pd_current(sim: WegSim, _: int) -> int:
    return _pd_fraction(sim.motor.current() / max(sim.values[401] / 10.0, 0.1))


def _pd_power(sim: WegSim, sub: int) -> int:
    return _pd_fraction(_power(sim, sub) / max(sim.values[404], 1))  # (P0010 / P0404) x 4000h


def _pd_torque(sim: WegSim, _: int) -> int:
    return _pd_fraction(_torque_fraction(sim))


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
    968: lambda sim, _: SIM_DATA_WORDS[DataProfile.PROFIDRIVE].status(sim),
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
