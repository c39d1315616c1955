"""Soft starter physics for the simulator, on the shared motor model (gateway.sim).

A soft starter has no speed reference: it ramps the motor voltage so the motor accelerates
to line speed with a limited current, closes its bypass and runs at line speed, and on a
soft stop ramps the voltage down. Deterministic, stepped with :meth:`SoftStarter.advance`.

Model (ours; the installation guide describes only the bus side):

* start: the current rises from the initial current to the current limit over the start
  ramp time (current ramp start, %FLC of the programmed FLC); the motor reaches line speed
  at the end of the ramp if the current limit is at least ``required_start_pct`` (a property
  of motor and load). Below it the motor stalls part way and the starter trips on excess
  start time (trip 1) once that time is exceeded.
* running: the motor's own current (magnetising plus load) from :class:`gateway.sim.Motor`.
* soft stop: the motor decelerates over the stop time; a stop time of 0 or a quick stop
  coasts it (the output is off at once, the motor runs down on its own).
* motor thermal model (%): first order towards 100 x (I/FLC)^2 with a time constant of
  36 x the locked rotor time (600 % current reaches 100 % in one locked rotor time);
  at 105 % the starter trips on motor overload (trip 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from adapters.mcd600.monitoring import StarterState
from adapters.mcd600.trips import EXCESS_START_TIME, MOTOR_OVERLOAD
from gateway.sim import Motor, MotorParams

THERMAL_TRIP_PCT: Final = 105.0
MAX_STEP: Final = 0.05  # s: advance in steps no longer than this

ACTIVE_STATES: Final = frozenset(
    {StarterState.STARTING, StarterState.RUNNING, StarterState.STOPPING}
)
POWER_FACTORS: Final[dict[StarterState, float]] = {
    StarterState.STARTING: 0.35,
    StarterState.RUNNING: 0.85,
    StarterState.STOPPING: 0.6,
}


@dataclass(frozen=True, slots=True)
class StarterSettings:
    """The starter parameters the physics uses (from the simulator's parameter table)."""

    flc_a: float = 100.0
    start_ramp_time: float = 10.0
    initial_current_pct: float = 200.0
    current_limit_pct: float = 350.0
    excess_start_time: float = 20.0  # 0 = no check
    soft_stop: bool = True
    stop_time: float = 5.0
    locked_rotor_time: float = 10.0


class SoftStarter:
    """The power section of the starter and its motor."""

    def __init__(
        self,
        motor: MotorParams | None = None,
        *,
        line_voltage: float = 400.0,
        required_start_pct: float = 250.0,
    ) -> None:
        self.motor = Motor(motor or MotorParams(rated_rpm=1480.0, rated_current=100.0))
        self.line_voltage = line_voltage
        self.required_start_pct = required_start_pct
        self.state = StarterState.READY
        self.trip_code = 0
        self.thermal_pct = 0.0
        self.current_a = 0.0
        self.elapsed = 0.0  # s in the present start or stop
        self.available = True  # False: reset input open (guide 3.3), the starter will not run
        self.pending_trip = 0  # a soft trip: trip with this code once stopped
        self.warning = False

    # ------------------------------------------------------------------ commands

    @property
    def active(self) -> bool:
        return self.state in ACTIVE_STATES

    @property
    def tripped(self) -> bool:
        return self.state is StarterState.TRIPPED

    def start(self, s: StarterSettings) -> bool:
        if self.state is not StarterState.READY:
            return False
        self.state = StarterState.STARTING
        self.elapsed = 0.0
        self.current_a = s.initial_current_pct * s.flc_a / 100.0
        reach = min(1.0, s.current_limit_pct / self.required_start_pct)
        self.motor.accel_time = s.start_ramp_time
        self.motor.command(True, self.motor.params.rated_rpm * reach)
        return True

    def stop(self, s: StarterSettings) -> None:
        """A stop command: soft stop if set and timed, else coast."""
        if not self.active or self.state is StarterState.STOPPING:
            return
        if not s.soft_stop or s.stop_time <= 0:
            self.coast()
            return
        self.state = StarterState.STOPPING
        self.elapsed = 0.0
        self.motor.decel_time = s.stop_time
        self.motor.command(True, 0.0)

    def coast(self) -> None:
        """Quick stop: output off, the motor coasts (guide 4.2, byte 0 bit 4)."""
        self.motor.coast()
        self.current_a = 0.0
        if self.active:
            self.state = StarterState.READY if self.available else StarterState.NOT_READY

    def trip(self, code: int) -> None:
        self.coast()
        self.pending_trip = 0
        self.state = StarterState.TRIPPED
        self.trip_code = code

    def soft_trip(self, code: int, s: StarterSettings) -> None:
        """Soft stop, then trip (parameter 6-13 "Soft Trip and Log")."""
        if self.active:
            self.pending_trip = code
            self.stop(s)
            if self.active:
                return
        self.trip(code)

    def reset(self) -> bool:
        """Clear a trip if its condition is gone (guide 5.1.1)."""
        if not self.tripped:
            return False
        if self.trip_code == MOTOR_OVERLOAD and self.thermal_pct >= 100.0:
            return False  # the motor is still too hot
        self.trip_code = 0
        self.state = StarterState.READY if self.available else StarterState.NOT_READY
        return True

    def power_off(self) -> None:
        self.coast()
        self.pending_trip = 0
        self.trip_code = 0
        self.state = StarterState.READY if self.available else StarterState.NOT_READY

    # ------------------------------------------------------------------ physics

    def advance(self, dt: float, s: StarterSettings) -> None:
        while dt > 1e-12:
            step = min(dt, MAX_STEP)
            self._step(step, s)
            dt -= step

    def _step(self, dt: float, s: StarterSettings) -> None:
        self.apply_availability()
        self.motor.advance(dt)
        self.elapsed += dt
        handler = _STEPS.get(self.state)
        if handler is not None:
            handler(self, s)
        else:
            self.current_a = 0.0
        self._thermal(dt, s)

    def apply_availability(self) -> None:
        """The reset input (guide 3.3 note: "se a entrada de reset estiver ativa, o soft
        starter não opera"): open, a ready starter is not ready and an active one stops
        (output off, the motor coasts); closed again, a not ready starter is ready. A trip
        stays a trip either way."""
        if self.available and self.state is StarterState.NOT_READY:
            self.state = StarterState.READY
        elif not self.available and self.state is StarterState.READY:
            self.state = StarterState.NOT_READY
        elif not self.available and self.active:
            self.coast()

    def _starting(self, s: StarterSettings) -> None:
        ramp = max(s.start_ramp_time, 1e-6)
        span = s.current_limit_pct - s.initial_current_pct
        pct = min(s.current_limit_pct, s.initial_current_pct + span * min(1.0, self.elapsed / ramp))
        self.current_a = pct * s.flc_a / 100.0
        if self.motor.speed >= self.motor.params.rated_rpm:
            self.state = StarterState.RUNNING  # up to speed: bypass closed
            self.current_a = self.motor.current()
        elif s.excess_start_time > 0 and self.elapsed > s.excess_start_time:
            self.trip(EXCESS_START_TIME)

    def _running(self, _s: StarterSettings) -> None:
        self.current_a = self.motor.current()

    def _stopping(self, _s: StarterSettings) -> None:
        self.current_a = self.motor.current()
        if self.motor.stopped:
            self.motor.coast()
            self.current_a = 0.0
            self.state = StarterState.READY if self.available else StarterState.NOT_READY
            if self.pending_trip:
                self.trip(self.pending_trip)

    def _thermal(self, dt: float, s: StarterSettings) -> None:
        ratio = self.current_a / s.flc_a if s.flc_a > 0 else 0.0
        tau = 36.0 * max(s.locked_rotor_time, 0.1)
        target = 100.0 * ratio * ratio
        self.thermal_pct += (target - self.thermal_pct) * (1.0 - math.exp(-dt / tau))
        if self.thermal_pct >= THERMAL_TRIP_PCT and not self.tripped:
            self.trip(MOTOR_OVERLOAD)

    # ------------------------------------------------------------------ readings

    def current_pct(self, s: StarterSettings) -> float:
        return 100.0 * self.current_a / s.flc_a if s.flc_a > 0 else 0.0

    @property
    def power_factor(self) -> float:
        return POWER_FACTORS.get(self.state, 0.0) if self.current_a > 0 else 0.0

    @property
    def power_w(self) -> float:
        return math.sqrt(3.0) * self.line_voltage * self.current_a * self.power_factor

    @property
    def apparent_power_va(self) -> float:
        return math.sqrt(3.0) * self.line_voltage * self.current_a


_STEPS = {
    StarterState.STARTING: SoftStarter._starting,
    StarterState.RUNNING: SoftStarter._running,
    StarterState.STOPPING: SoftStarter._stopping,
}
