"""Shared pieces of every device simulator: motor physics and fault injection."""

from gateway.sim.faults import FaultInjector
from gateway.sim.motor import Motor, MotorParams

__all__ = ["FaultInjector", "Motor", "MotorParams"]
