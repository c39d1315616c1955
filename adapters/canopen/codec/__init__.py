"""The CANopen codec layer (sans-IO): ``frames`` (COB-IDs, NMT, SDO, heartbeat, EMCY,
SYNC, PDO mapping entries), ``cia402`` (the CiA 402 / IEC 61800-7-201 state machine and
option codes), ``codes`` (SDO abort codes, EMCY error codes, error register bits), ``od``
(a node's object dictionary, read from its EDS or DCF with the canopen library). Typed
decode errors are the package's ``errors``."""
