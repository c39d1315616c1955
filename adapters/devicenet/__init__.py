"""DeviceNet scanner for Group 2 Only slaves (the WEG CFW-08), in layers:

``codec/`` (sans-IO, fact sheet Part 2: frames, identifiers, explicit messages,
fragmentation, Duplicate MAC ID check, CIP, objects, data types, EDS), ``scanner/`` (the
engine), ``contract`` (what a device profile gives the adapter), ``cfw08/`` (the device),
``sim/`` (its simulator), then ``options``, ``link``, ``adapter`` and ``cli``.
"""
