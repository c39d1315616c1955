"""The CFW-08's DeviceNet objects and DeviceNet parameters as data (seed sections 4 and 5).

Each attribute carries its access rights ("Método" column), type and range as the
seed's tables give them; the simulator serves them and the scanner reads them. Types
the seed does not state come from the ODVA object definitions the fact sheet cites
(2.5, 2.9, 2.12), or are marked as a decision.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum, Flag

from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.datatypes import (
    AttributeValue,
    CipType,
    decode_short_string,
    decode_value,
    encode_short_string,
    encode_value,
)
from adapters.devicenet.errors import DataTypeDecodeError
from gateway.errors import FrameEncodeError


class Access(Flag):
    """The "Método" column: Get, Set, Get/Set."""

    GET = 1
    SET = 2
    GET_SET = 3


class Kind(Enum):
    """How an attribute value is carried."""

    BOOL = "BOOL"  # one byte, 0 or 1
    USINT = "USINT"
    UINT = "UINT"
    INT = "INT"
    UDINT = "UDINT"
    WORD = "WORD"
    BYTE = "BYTE"
    REVISION = "REVISION"  # USINT major, USINT minor (fact sheet 2.12)
    SHORT_STRING = "SHORT_STRING"
    BYTES = "BYTES"  # opaque (assembly data, allocation info, connection paths)


_INT_KINDS: Mapping[Kind, CipType] = {
    Kind.BOOL: CipType.USINT,
    Kind.USINT: CipType.USINT,
    Kind.UINT: CipType.UINT,
    Kind.INT: CipType.INT,
    Kind.UDINT: CipType.UDINT,
    Kind.WORD: CipType.WORD,
    Kind.BYTE: CipType.BYTE,
}

Value = AttributeValue


def encode_attribute(kind: Kind, value: Value) -> bytes:
    """An attribute value on the wire; FrameEncodeError when it does not fit."""
    if kind in _INT_KINDS:
        if not isinstance(value, int):
            raise FrameEncodeError(f"{kind.value} needs an int, not {value!r}")
        return encode_value(_INT_KINDS[kind], value)
    if kind is Kind.REVISION:
        if not isinstance(value, tuple):
            raise FrameEncodeError(f"REVISION needs (major, minor), not {value!r}")
        return encode_value(CipType.USINT, value[0]) + encode_value(CipType.USINT, value[1])
    if kind is Kind.SHORT_STRING:
        if not isinstance(value, str):
            raise FrameEncodeError(f"SHORT_STRING needs a str, not {value!r}")
        return encode_short_string(value)
    if not isinstance(value, bytes):
        raise FrameEncodeError(f"BYTES needs bytes, not {value!r}")
    return value


def decode_attribute(kind: Kind, data: bytes) -> Value:
    """An attribute value from the wire; DataTypeDecodeError on a wrong length."""
    raw = bytes(data)
    if kind in _INT_KINDS:
        return decode_value(_INT_KINDS[kind], raw)
    if kind is Kind.REVISION:
        if len(raw) != 2:
            raise DataTypeDecodeError(f"REVISION of {len(raw)} bytes (2 expected)", raw)
        return (raw[0], raw[1])
    if kind is Kind.SHORT_STRING:
        return decode_short_string(raw)
    return raw


def wire_size(kind: Kind) -> int | None:
    """Fixed size in bytes, or None for variable-length kinds."""
    if kind in _INT_KINDS:
        return _INT_KINDS[kind].size
    return 2 if kind is Kind.REVISION else None


@dataclass(frozen=True, slots=True)
class AttributeSpec:
    attribute: int
    name: str
    access: Access
    kind: Kind
    minimum: int | None = None
    maximum: int | None = None
    default: Value | None = None

    @property
    def gettable(self) -> bool:
        return Access.GET in self.access

    @property
    def settable(self) -> bool:
        return Access.SET in self.access

    def in_range(self, value: int) -> bool:
        if self.kind is Kind.BOOL and value not in (0, 1):
            return False
        if self.minimum is not None and value < self.minimum:
            return False
        return self.maximum is None or value <= self.maximum


@dataclass(frozen=True, slots=True)
class ObjectSpec:
    class_id: int
    name: str
    source: str  # where the seed defines it
    instances: tuple[int, ...]
    attributes: Mapping[int, AttributeSpec]


def _table(*specs: AttributeSpec) -> Mapping[int, AttributeSpec]:
    return {s.attribute: s for s in specs}


G, S, GS = Access.GET, Access.SET, Access.GET_SET

IDENTITY = ObjectSpec(
    CipClass.IDENTITY,
    "Identity",
    "seed 5.1, table 8",
    (1,),
    _table(
        AttributeSpec(1, "Vendor ID", G, Kind.UINT, default=0x355),
        AttributeSpec(2, "Product Type", G, Kind.UINT, default=0x2),
        AttributeSpec(3, "Product Code", G, Kind.UINT),
        AttributeSpec(4, "Vendor Revision", G, Kind.REVISION),
        AttributeSpec(5, "Status", G, Kind.WORD),
        AttributeSpec(6, "Serial Number", G, Kind.UDINT),
        AttributeSpec(7, "Product Name", G, Kind.SHORT_STRING, default="CFW-08"),
    ),
)

MESSAGE_ROUTER = ObjectSpec(
    CipClass.MESSAGE_ROUTER, "Message Router", "seed 5.2 (no attribute)", (1,), _table()
)

DEVICENET = ObjectSpec(
    CipClass.DEVICENET,
    "DeviceNet",
    "seed 5.3, table 9",
    (1,),
    _table(
        AttributeSpec(1, "Mac ID", GS, Kind.USINT, 0, 63, 63),
        AttributeSpec(2, "Baud rate", GS, Kind.USINT, 0, 2, 0),
        AttributeSpec(4, "Bus-Off Counter", GS, Kind.USINT, 0, 255),
        AttributeSpec(5, "Allocation Information", G, Kind.BYTES),
    ),
)

ASSEMBLY_OUTPUTS = (20, 21, 100)  # seed table 11
ASSEMBLY_INPUTS = (70, 71, 150)
ASSEMBLY = ObjectSpec(
    CipClass.ASSEMBLY,
    "Assembly",
    "seed 5.4, tables 10 and 11",
    ASSEMBLY_OUTPUTS + ASSEMBLY_INPUTS,
    _table(AttributeSpec(3, "Data", GS, Kind.BYTES)),
)

CONNECTION = ObjectSpec(
    CipClass.CONNECTION,
    "Connection",
    "seed 5.5, tables 12-14",
    (1, 2, 4),  # explicit, polled, change of state/cyclic
    _table(
        AttributeSpec(1, "State", G, Kind.USINT),
        AttributeSpec(2, "Instance Type", G, Kind.USINT),
        AttributeSpec(3, "Transport Class Trigger", G, Kind.BYTE),
        AttributeSpec(4, "Produced Connection ID", G, Kind.UINT),
        AttributeSpec(5, "Consumed Connection ID", G, Kind.UINT),
        AttributeSpec(6, "Initial Comm. Charac.", G, Kind.BYTE),
        AttributeSpec(7, "Produced Connection Size", G, Kind.UINT),
        AttributeSpec(8, "Consumed Connection Size", G, Kind.UINT),
        AttributeSpec(9, "Expected Packet Rate", GS, Kind.UINT),
        AttributeSpec(12, "Watchdog Timeout Action", G, Kind.USINT),
        AttributeSpec(13, "Produced Connection Path Length", G, Kind.UINT),
        AttributeSpec(14, "Produced Connection Path", G, Kind.BYTES),
        AttributeSpec(15, "Consumed Connection Path Length", G, Kind.UINT),
        AttributeSpec(16, "Consumed Connection Path", G, Kind.BYTES),
        AttributeSpec(17, "Production Inhibit Time", GS, Kind.UINT),
    ),
)

MOTOR_DATA = ObjectSpec(
    CipClass.MOTOR_DATA,
    "Motor Data",
    "seed 5.6, table 15",
    (1,),
    _table(
        AttributeSpec(3, "Motor Type", GS, Kind.USINT, 0, 10, 7),
        AttributeSpec(6, "Rated Current", GS, Kind.UINT, 0, 9999),  # 100 mA units: 0-999.9 A
        AttributeSpec(7, "Rated Voltage", GS, Kind.UINT, 0, 600, 220),
    ),
)

# Seed table 16. "Set" alone is taken literally: the attribute is write-only (decision).
CONTROL_SUPERVISOR = ObjectSpec(
    CipClass.CONTROL_SUPERVISOR,
    "Control Supervisor",
    "seed 5.7, table 16",
    (1,),
    _table(
        AttributeSpec(3, "Run1", S, Kind.BOOL, 0, 1),
        AttributeSpec(4, "Run2", S, Kind.BOOL, 0, 1),
        AttributeSpec(5, "NetCtrl", S, Kind.BOOL, 0, 1, 0),
        AttributeSpec(6, "State", G, Kind.USINT, 0, 7),
        AttributeSpec(7, "Running1", G, Kind.BOOL, 0, 1, 0),
        AttributeSpec(8, "Running2", G, Kind.BOOL, 0, 1, 0),
        AttributeSpec(9, "Ready", G, Kind.BOOL, 0, 1, 0),
        AttributeSpec(10, "Faulted", G, Kind.BOOL, 0, 1, 0),
        AttributeSpec(11, "Warning", G, Kind.BOOL, 0, 0, 0),
        AttributeSpec(12, "Fault Reset", S, Kind.BOOL, 0, 1, 0),
        AttributeSpec(15, "Ctrl from Net", G, Kind.BOOL, 0, 1, 0),
    ),
)

AC_DC_DRIVE = ObjectSpec(
    CipClass.AC_DC_DRIVE,
    "AC/DC Drive",
    "seed 5.8, table 17",
    (1,),
    _table(
        AttributeSpec(4, "NetRef", GS, Kind.BOOL, 0, 1, 0),
        AttributeSpec(6, "DriveMode", GS, Kind.USINT, 1, 2, 2),
        AttributeSpec(7, "Speed Actual", G, Kind.INT, 0, 9999),
        AttributeSpec(8, "Speed Ref", GS, Kind.INT, 0, 9999, 0),
    ),
)

ACKNOWLEDGE_HANDLER = ObjectSpec(
    CipClass.ACKNOWLEDGE_HANDLER,
    "Acknowledge Handler",
    "seed 5.9, table 18",
    (1,),
    _table(
        AttributeSpec(1, "Acknowledge Timer", GS, Kind.UINT, 1, 65535, 16),
        AttributeSpec(2, "Retry Limit", G, Kind.USINT, 0, 255, 1),
        AttributeSpec(3, "COS Production Connection Instance", G, Kind.UINT, default=4),
    ),
)

STANDARD_OBJECTS: Mapping[int, ObjectSpec] = {
    spec.class_id: spec
    for spec in (
        IDENTITY,
        MESSAGE_ROUTER,
        DEVICENET,
        ASSEMBLY,
        CONNECTION,
        MOTOR_DATA,
        CONTROL_SUPERVISOR,
        AC_DC_DRIVE,
        ACKNOWLEDGE_HANDLER,
    )
}


# ---------------------------------------------------------------- parameters (seed 4)


@dataclass(frozen=True, slots=True)
class ParamSpec:
    number: int
    name: str
    minimum: int
    maximum: int
    default: int | None
    writable: bool
    source: str
    needs_reset: bool = False  # takes effect after a drive reset (seed 4.1.4-4.1.8 notes)


SEED_PARAMETERS: Mapping[int, ParamSpec] = {
    p.number: p
    for p in (
        ParamSpec(70, "CAN controller state", 0, 6, None, False, "seed 4.1.1"),
        ParamSpec(81, "network master state", 0, 1, None, False, "seed 4.1.2"),
        ParamSpec(220, "local/remote source", 0, 6, 2, True, "seed 4.2.1"),
        ParamSpec(221, "speed reference, local", 0, 8, 0, True, "seed 4.2.2"),
        ParamSpec(222, "speed reference, remote", 0, 8, 1, True, "seed 4.2.3"),
        ParamSpec(229, "commands, local", 0, 2, 0, True, "seed 4.2.4"),
        ParamSpec(230, "commands, remote", 0, 2, 1, True, "seed 4.2.5"),
        ParamSpec(231, "direction, local and remote", 0, 2, 2, True, "seed 4.2.6"),
        ParamSpec(313, "action on a communication error", 0, 3, 2, True, "seed 4.1.3"),
        ParamSpec(700, "CAN protocol", 0, 2, 0, True, "seed 4.1.4", needs_reset=True),
        ParamSpec(701, "CAN address (MAC ID)", 0, 63, 63, True, "seed 4.1.5", needs_reset=True),
        ParamSpec(702, "baud rate", 0, 8, 0, True, "seed 4.1.6", needs_reset=True),
        ParamSpec(703, "bus-off reset", 0, 1, 0, True, "seed 4.1.7"),
        ParamSpec(710, "I/O instances", 0, 2, 0, True, "seed 4.1.8", needs_reset=True),
    )
}

P070, P081, P313, P700, P701, P702, P703, P710 = 70, 81, 313, 700, 701, 702, 703, 710

P702_BAUD: Mapping[int, int | None] = {
    # seed 4.1.6: 2 = 500k, 3 = 250k, 4 = 125k, anything else auto-baud (None)
    2: 500_000,
    3: 250_000,
    4: 125_000,
}


def baud_to_p702(bitrate: int) -> int | None:
    for code, rate in P702_BAUD.items():
        if rate == bitrate:
            return code
    return None


DEVICENET_BAUD_ATTRIBUTE: Mapping[int, int] = {0: 125_000, 1: 250_000, 2: 500_000}  # 2.5
