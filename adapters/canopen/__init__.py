"""CANopen master for CiA 402 drives, on the shared CAN link and driver, in layers:

``codec/`` (sans-IO: frames, CiA 402 state machine, codes, the object dictionary read
from an EDS), ``master/`` (the engine), ``drive`` (the CiA 402 device profile: the drive
model to and from the drive's words), ``sim/`` (the simulated drive), then ``options``,
``plan`` (the bring-up of each drive), ``link``, ``adapter`` and ``cli``.
"""
