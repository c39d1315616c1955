"""DeviceNet scanner for a Group 2 Only slave (WEG CFW-08).

Codec layer (sans-IO, fact sheet Part 2): ``frame`` (the CAN frame), ``ids``
(identifiers, predefined connection set), ``explicit`` (explicit message bodies),
``fragment`` (fragmentation protocol), ``dupmac`` (Duplicate MAC ID check),
``cip`` (general status, services, classes), ``objects`` (class 1/3/5 numbers),
``datatypes`` (CIP elementary types), ``errors`` (typed decode errors).
"""
