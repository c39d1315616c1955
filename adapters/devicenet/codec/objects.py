"""Instance and attribute numbers of the DeviceNet objects a master talks to.

Fact sheet 2.5 (allocation choice bits, DeviceNet object class 3 attributes),
2.9 (Connection object class 5: instances, attributes, states, watchdog actions),
2.12 (Identity object class 1); seed ``weg-cfw08-devicenet.pt.md`` 5.1, 5.3, 5.5.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag

from adapters.devicenet.errors import DataTypeDecodeError
from gateway.errors import FrameEncodeError


class AllocationChoice(IntFlag):
    """Allocation choice bits of Allocate/Release (fact sheet 2.5 [BRB][JB]).

    Bit 0x80 has no name; it is kept as given so a server can reject it.
    """

    EXPLICIT = 0x01
    POLL = 0x02
    BIT_STROBE = 0x04
    MULTICAST_POLL = 0x08
    COS = 0x10
    CYCLIC = 0x20
    ACK_SUPPRESSION = 0x40


NO_MASTER = 0xFF  # fact sheet 2.5: allocation info master MAC 0xFF = none


class DeviceNetAttribute(IntEnum):
    """DeviceNet object (class 3) attributes (fact sheet 2.5; seed table 9)."""

    MAC_ID = 1
    BAUD_RATE = 2
    BUS_OFF_INTERRUPT = 3
    BUS_OFF_COUNTER = 4
    ALLOCATION_INFORMATION = 5


class BaudRate(IntEnum):
    """Class 3 attribute 2 values (fact sheet 2.5)."""

    KBIT_125 = 0
    KBIT_250 = 1
    KBIT_500 = 2


@dataclass(frozen=True, slots=True)
class AllocationInfo:
    """Class 3 attribute 5: choice byte, then the master's MAC (0xFF = none) (fact sheet 2.5)."""

    choice: AllocationChoice
    master_mac: int = NO_MASTER

    def encode(self) -> bytes:
        if not 0 <= int(self.choice) <= 0xFF:
            raise FrameEncodeError(f"allocation choice {int(self.choice):#x} is not a byte")
        if not (0 <= self.master_mac <= 63 or self.master_mac == NO_MASTER):
            raise FrameEncodeError(f"master MAC {self.master_mac} not 0..63 or 0xFF")
        return bytes((int(self.choice), self.master_mac))

    @classmethod
    def decode(cls, data: bytes) -> AllocationInfo:
        raw = bytes(data)
        if len(raw) != 2:
            raise DataTypeDecodeError(f"allocation info of {len(raw)} bytes (2 expected)", raw)
        choice, master = raw
        if not (master <= 63 or master == NO_MASTER):
            raise DataTypeDecodeError(f"allocation info master MAC {master}", raw)
        return cls(AllocationChoice(choice), master)


class IdentityAttribute(IntEnum):
    """Identity object (class 1, instance 1) attributes (fact sheet 2.12; seed table 8)."""

    VENDOR_ID = 1
    DEVICE_TYPE = 2
    PRODUCT_CODE = 3
    REVISION = 4
    STATUS = 5
    SERIAL_NUMBER = 6
    PRODUCT_NAME = 7


class ConnectionInstance(IntEnum):
    """Connection object (class 5) instances of the predefined set (fact sheet 2.9)."""

    EXPLICIT = 1
    POLL = 2
    BIT_STROBE = 3
    COS_CYCLIC = 4
    MULTICAST_POLL = 5


class ConnectionAttribute(IntEnum):
    """Connection object attributes (fact sheet 2.9; seed tables 12-14)."""

    STATE = 1
    INSTANCE_TYPE = 2
    TRANSPORT_CLASS_TRIGGER = 3
    PRODUCED_CONNECTION_ID = 4
    CONSUMED_CONNECTION_ID = 5
    INITIAL_COMM_CHARACTERISTICS = 6
    PRODUCED_CONNECTION_SIZE = 7
    CONSUMED_CONNECTION_SIZE = 8
    EXPECTED_PACKET_RATE = 9
    WATCHDOG_TIMEOUT_ACTION = 12
    PRODUCED_PATH_LENGTH = 13
    PRODUCED_PATH = 14
    CONSUMED_PATH_LENGTH = 15
    CONSUMED_PATH = 16
    PRODUCTION_INHIBIT_TIME = 17


class ConnectionType(IntEnum):
    """Connection attribute 2 (fact sheet 2.9)."""

    EXPLICIT = 0
    IO = 1


class ConnectionState(IntEnum):
    """Connection attribute 1 (fact sheet 2.9)."""

    NON_EXISTENT = 0
    CONFIGURING = 1
    WAITING_FOR_ID = 2
    ESTABLISHED = 3
    TIMED_OUT = 4
    DEFERRED_DELETE = 5
    CLOSING = 6


class WatchdogAction(IntEnum):
    """Connection attribute 12 (fact sheet 2.9)."""

    TIME_OUT = 0
    AUTO_DELETE = 1
    AUTO_RESET = 2
    DEFERRED_DELETE = 3


INACTIVITY_EPR_FACTOR = 4  # fact sheet 2.9: inactivity timeout = 4 x EPR


# ---------------------------------------------------------------- connection paths

# Packed EPATH logical segments (fact sheet 2.10 step 4; 2.5: DeviceNet paths are packed):
# segment byte -> (what it names, how many value bytes follow, little-endian).
_LOGICAL_SEGMENTS: dict[int, tuple[str, int]] = {
    0x20: ("class", 1),
    0x21: ("class", 2),
    0x24: ("instance", 1),
    0x25: ("instance", 2),
    0x30: ("attribute", 1),
    0x31: ("attribute", 2),
}
ASSEMBLY_CLASS = 0x04  # fact sheet 2.11; seed 5.4
ASSEMBLY_DATA = 3  # seed table 10: the Data attribute


@dataclass(frozen=True, slots=True)
class LogicalPath:
    """A connection path (Connection attributes 14 and 16) as class, instance, attribute."""

    class_id: int | None = None
    instance_id: int | None = None
    attribute_id: int | None = None

    @property
    def assembly(self) -> int | None:
        """The Assembly instance the path names, or None when it names something else."""
        if self.class_id != ASSEMBLY_CLASS or self.attribute_id not in (None, ASSEMBLY_DATA):
            return None
        return self.instance_id


def assembly_path(instance: int) -> bytes:
    """The path of an Assembly instance's Data: ``20 04 24 <instance> 30 03`` (fact sheet
    2.10 step 4); a 16-bit instance segment above 255."""
    if not 0 <= instance <= 0xFFFF:
        raise FrameEncodeError(f"assembly instance {instance} does not fit a path")
    if instance <= 0xFF:
        middle = bytes((0x24, instance))
    else:
        middle = bytes((0x25,)) + instance.to_bytes(2, "little")
    return bytes((0x20, ASSEMBLY_CLASS)) + middle + bytes((0x30, ASSEMBLY_DATA))


def decode_path(data: bytes) -> LogicalPath:
    """A packed logical path; DataTypeDecodeError on any other segment or a short one."""
    raw = bytes(data)
    found: dict[str, int] = {}
    i = 0
    while i < len(raw):
        segment = _LOGICAL_SEGMENTS.get(raw[i])
        if segment is None:
            raise DataTypeDecodeError(f"path segment {raw[i]:#04x} is not a logical one", raw)
        name, size = segment
        value = raw[i + 1 : i + 1 + size]
        if len(value) != size or name in found:
            raise DataTypeDecodeError(f"bad {name} segment in a connection path", raw)
        found[name] = int.from_bytes(value, "little")
        i += 1 + size
    return LogicalPath(found.get("class"), found.get("instance"), found.get("attribute"))
