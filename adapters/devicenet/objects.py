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
