"""The simulated CiA 402 drive on CANopen (the canopen library's LocalNode around a drive
model over the shared motor physics).

``drive`` is the sans-IO CiA 402 drive (state machine, option codes, vl and pv modes),
``node`` the LocalNode around it (NMT, SDO checks, PDO, heartbeat, EMCY, lost
communication, fault injection), ``runner`` the async runner on a python-can bus.
Never the master.
"""

from adapters.canopen.sim.drive import Cia402Drive, DriveConfig
from adapters.canopen.sim.node import BootState, SimNode, SimNodeConfig
from adapters.canopen.sim.runner import SimRunner

__all__ = ["BootState", "Cia402Drive", "DriveConfig", "SimNode", "SimNodeConfig", "SimRunner"]
