"""The Modbus TCP front end: one unit id per drive, a fixed 0-based register map.

Modules, from the wire inwards:

- :mod:`gateway.modbus.mbap`: sans-IO check of the MBAP header (bad frames close the link).
- :mod:`gateway.modbus.regs`: register types, null sentinels, map fields, exception codes.
- :mod:`gateway.modbus.command`: the command word and the per-client edge rules.
- :mod:`gateway.modbus.map`: a drive unit's register map, its encoders, the write decoder.
- :mod:`gateway.modbus.health`: the gateway unit's register map (health).
- :mod:`gateway.modbus.doc`: ``python -m gateway.modbus.doc > docs/modbus-map.md``.
- :mod:`gateway.modbus.server`: the pymodbus server with allow-list and unit check.
- :mod:`gateway.modbus.frontend`: :class:`ModbusFrontEnd`, what the daemon runs.
"""
