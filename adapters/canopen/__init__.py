"""CANopen master for CiA 402 drives, on the shared CAN link and driver.

Codec layer (sans-IO): ``frames`` (COB-IDs, NMT, SDO, heartbeat, EMCY, SYNC, PDO
mapping entries), ``cia402`` (the CiA 402 / IEC 61800-7-201 state machine and
option codes), ``codes`` (SDO abort codes, EMCY error codes, error register bits),
``errors`` (typed decode errors under the project's root).
"""
