"""Motor physics shared by the simulators: ramps, direction through zero, current, coast-down.

Deterministic: the caller advances it with :meth:`Motor.advance` and its own clock.
Speeds are signed rpm (negative = reverse).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class MotorParams:
    rated_rpm: float = 1800.0  # speed the ramp times refer to (0 -> rated_rpm)
    accel_time: float = 5.0  # s from 0 to rated_rpm (WEG P0100)
    decel_time: float = 5.0  # s from rated_rpm to 0 (WEG P0101)
    quick_stop_time: float = 0.5  # s from rated_rpm to 0 on a quick stop
    coast_time: float = 8.0  # s from rated_rpm to 0 when coasting (friction only)
    rated_current: float = 10.0  # A at rated speed and full load
    magnetising_current: float = 3.0  # A with the motor magnetised at no load
    load: float = 0.6  # fraction of rated torque at rated speed (load ~ speed)


class Motor:
    """One motor on one drive output."""

    def __init__(self, params: MotorParams | None = None) -> None:
        self.params = params or MotorParams()
        self.speed = 0.0  # signed rpm
        self.reference = 0.0  # signed rpm the drive ramps toward
        self.enabled = False  # the drive output is on (False = coasting)
        self.quick_stopping = False
        self.accel_time = self.params.accel_time
        self.decel_time = self.params.decel_time

    @property
    def running(self) -> bool:
        return self.enabled and (self.reference != 0.0 or self.speed != 0.0)

    @property
    def stopped(self) -> bool:
        return self.speed == 0.0

    def command(self, enabled: bool, reference: float) -> None:
        self.enabled = enabled
        self.reference = reference if enabled else 0.0
        if not enabled or reference != 0.0:
            self.quick_stopping = False

    def quick_stop(self) -> None:
        self.quick_stopping = True
        self.reference = 0.0

    def coast(self) -> None:
        self.enabled = False
        self.reference = 0.0
        self.quick_stopping = False

    def _rate(self, towards_zero: bool) -> float:
        """rpm per second for the current situation."""
        p = self.params
        if not self.enabled:
            return p.rated_rpm / max(p.coast_time, 1e-6)
        if self.quick_stopping:
            return p.rated_rpm / max(p.quick_stop_time, 1e-6)
        ramp = self.decel_time if towards_zero else self.accel_time
        return math.inf if ramp <= 0 else p.rated_rpm / ramp

    def advance(self, dt: float) -> None:
        """Move the speed toward the reference for ``dt`` seconds (through zero on reversal)."""
        while dt > 1e-12:
            target = self.reference if self.enabled else 0.0
            if self.speed == target:
                return
            crossing = self.speed != 0.0 and (target == 0.0 or (target > 0) != (self.speed > 0))
            goal = 0.0 if crossing else target
            towards_zero = abs(goal) < abs(self.speed)
            rate = self._rate(towards_zero)
            distance = abs(goal - self.speed)
            needed = distance / rate if rate != math.inf else 0.0
            if needed <= dt or distance < 1e-6:
                self.speed = goal  # snap: no float residue left at the end of a ramp
                dt -= needed
            else:
                step = rate * dt
                self.speed += step if goal > self.speed else -step
                dt = 0.0

    def current(self) -> float:
        """Motor current in A: magnetising plus load proportional to speed, plus ramping."""
        p = self.params
        if not self.enabled and self.speed == 0.0:
            return 0.0
        if not self.enabled:
            return 0.0
        frac = abs(self.speed) / p.rated_rpm if p.rated_rpm else 0.0
        ramping = self.speed != self.reference
        torque = p.load * frac + (0.3 if ramping and abs(self.reference) > abs(self.speed) else 0.0)
        active = torque * math.sqrt(max(p.rated_current**2 - p.magnetising_current**2, 0.0))
        return math.hypot(p.magnetising_current, active)
