"""The simulated WEG CFW-08 on DeviceNet (built from codecs, the profile and gateway.sim).

``node`` is the sans-IO Group 2 Only server, ``drive`` the drive behind it, ``objects``
its explicit-message server, ``connection`` its Connection objects, ``params`` its
parameter table, ``runner`` the async runner on a python-can bus. Never the scanner.
"""

from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig, SimPhase
from adapters.devicenet.sim.runner import SimRunner

__all__ = ["Cfw08Node", "SimNodeConfig", "SimPhase", "SimRunner"]
