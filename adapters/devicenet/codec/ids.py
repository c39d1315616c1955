"""DeviceNet CAN identifiers: message groups 1-4 and the Predefined Master/Slave Connection Set.

Fact sheet 2.1 (identifier formulas per group, 0x7F0-0x7FF invalid) and 2.2 (the
predefined set, which MAC each identifier carries; group 3 and 4 messages [WSD]).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum, IntEnum, auto

from adapters.devicenet.errors import InvalidCanId
from gateway.errors import FrameEncodeError

MAX_MAC = 63  # 6-bit MAC ID (fact sheet 2.1; CFW-08 P701 0-63, seed 4.1.5)
ADR_MAC = 63  # seed 6.1 and P701 note: new devices come up at MAC 63


class MessageGroup(IntEnum):
    """The four message groups of fact sheet 2.1."""

    GROUP_1 = 1
    GROUP_2 = 2
    GROUP_3 = 3
    GROUP_4 = 4


@dataclass(frozen=True, slots=True)
class _GroupLayout:
    first_id: int
    last_id: int
    max_message_id: int
    has_mac: bool
    encode: Callable[[int, int], int]  # (message id, mac) -> identifier
    decode: Callable[[int], tuple[int, int | None]]  # identifier -> (message id, mac)


# Fact sheet 2.1: identifier formulas per group.
_LAYOUTS: dict[MessageGroup, _GroupLayout] = {
    MessageGroup.GROUP_1: _GroupLayout(
        0x000, 0x3FF, 15, True, lambda m, mac: (m << 6) | mac, lambda i: (i >> 6, i & 0x3F)
    ),
    MessageGroup.GROUP_2: _GroupLayout(
        0x400,
        0x5FF,
        7,
        True,
        lambda m, mac: 0x400 | (mac << 3) | m,
        lambda i: (i & 0x07, (i >> 3) & 0x3F),
    ),
    MessageGroup.GROUP_3: _GroupLayout(
        0x600,
        0x7BF,
        6,
        True,
        lambda m, mac: 0x600 | (m << 6) | mac,
        lambda i: ((i >> 6) & 0x07, i & 0x3F),
    ),
    MessageGroup.GROUP_4: _GroupLayout(
        0x7C0, 0x7EF, 0x2F, False, lambda m, _mac: 0x7C0 | m, lambda i: (i - 0x7C0, None)
    ),
}


@dataclass(frozen=True, slots=True)
class CanId:
    """A decoded identifier; ``mac`` is None in group 4 (which carries none)."""

    group: MessageGroup
    message_id: int
    mac: int | None = None

    def __post_init__(self) -> None:
        layout = _LAYOUTS[MessageGroup(self.group)]
        if not 0 <= self.message_id <= layout.max_message_id:
            raise FrameEncodeError(
                f"group {int(self.group)} message id {self.message_id:#x} "
                f"out of 0..{layout.max_message_id:#x}"
            )
        if layout.has_mac:
            if self.mac is None or not 0 <= self.mac <= MAX_MAC:
                raise FrameEncodeError(f"MAC ID {self.mac!r} out of 0..63")
        elif self.mac is not None:
            raise FrameEncodeError("group 4 identifiers carry no MAC ID")

    @property
    def arbitration_id(self) -> int:
        """The 11-bit identifier."""
        return _LAYOUTS[self.group].encode(self.message_id, self.mac or 0)


def encode_can_id(group: MessageGroup, message_id: int, mac: int | None = None) -> int:
    """The 11-bit identifier of a group message; FrameEncodeError when out of range."""
    return CanId(group, message_id, mac).arbitration_id


def decode_can_id(arbitration_id: int) -> CanId:
    """Group, message id and MAC of an identifier; :class:`InvalidCanId` otherwise."""
    if isinstance(arbitration_id, bool) or not isinstance(arbitration_id, int):
        raise InvalidCanId(f"identifier {arbitration_id!r} is not an int")
    for group, layout in _LAYOUTS.items():
        if layout.first_id <= arbitration_id <= layout.last_id:
            message_id, mac = layout.decode(arbitration_id)
            return CanId(group, message_id, mac)
    if 0 <= arbitration_id <= 0x7FF:
        reason = "reserved identifier 0x7F0-0x7FF"  # fact sheet 2.1: invalid
    else:
        reason = "not an 11-bit identifier"
    raise InvalidCanId(reason, arbitration_id=arbitration_id if arbitration_id >= 0 else None)


class Group3Message(IntEnum):
    """Group 3 messages named by [WSD] (fact sheet 2.2, "Other groups")."""

    UNCONNECTED_RESPONSE = 5
    UNCONNECTED_REQUEST = 6


class Group4Message(IntEnum):
    """Group 4 messages 0x2C-0x2F (fact sheet 2.2, "Other groups"; names from [WSD])."""

    COMM_FAULTED_RESPONSE = 0x2C
    COMM_FAULTED_REQUEST = 0x2D
    OFFLINE_OWNERSHIP_RESPONSE = 0x2E
    OFFLINE_OWNERSHIP_REQUEST = 0x2F


class MacRole(Enum):
    """Whose MAC ID a predefined-set identifier carries (fact sheet 2.2, last column)."""

    SLAVE = "slave"
    MASTER = "master"
    CLAIMED = "claimed"  # the MAC being claimed by a Duplicate MAC ID check
    UNSPECIFIED = "unspecified"  # fact sheet 2.2 marks G2 message 1 as unclear


class PredefinedMessage(Enum):
    """The Predefined Master/Slave Connection Set (fact sheet 2.2).

    :attr:`group` and :attr:`message_id` place it in the identifier space;
    :attr:`mac_role` says whose MAC the identifier carries.
    """

    SLAVE_MULTICAST_POLL_RESPONSE = auto()
    SLAVE_COS_CYCLIC = auto()
    SLAVE_BIT_STROBE_RESPONSE = auto()
    SLAVE_POLL_RESPONSE = auto()  # also the slave's COS/cyclic ACK
    MASTER_BIT_STROBE_COMMAND = auto()
    MASTER_MULTICAST_POLL = auto()
    MASTER_COS_CYCLIC_ACK = auto()
    SLAVE_EXPLICIT_RESPONSE = auto()  # also the unconnected response
    MASTER_EXPLICIT_REQUEST = auto()
    MASTER_POLL_COMMAND = auto()  # also the master's COS/cyclic command
    UNCONNECTED_EXPLICIT_REQUEST = auto()  # the Group 2 Only unconnected port
    DUPLICATE_MAC_CHECK = auto()

    @property
    def group(self) -> MessageGroup:
        return _PREDEFINED[self][0]

    @property
    def message_id(self) -> int:
        return _PREDEFINED[self][1]

    @property
    def mac_role(self) -> MacRole:
        return _PREDEFINED[self][2]


_G1, _G2 = MessageGroup.GROUP_1, MessageGroup.GROUP_2

# Fact sheet 2.2: group, message id and "MAC in the ID" of each message.
_PREDEFINED: dict[PredefinedMessage, tuple[MessageGroup, int, MacRole]] = {
    PredefinedMessage.SLAVE_MULTICAST_POLL_RESPONSE: (_G1, 0xC, MacRole.SLAVE),
    PredefinedMessage.SLAVE_COS_CYCLIC: (_G1, 0xD, MacRole.SLAVE),
    PredefinedMessage.SLAVE_BIT_STROBE_RESPONSE: (_G1, 0xE, MacRole.SLAVE),
    PredefinedMessage.SLAVE_POLL_RESPONSE: (_G1, 0xF, MacRole.SLAVE),
    PredefinedMessage.MASTER_BIT_STROBE_COMMAND: (_G2, 0, MacRole.MASTER),
    PredefinedMessage.MASTER_MULTICAST_POLL: (_G2, 1, MacRole.UNSPECIFIED),
    PredefinedMessage.MASTER_COS_CYCLIC_ACK: (_G2, 2, MacRole.SLAVE),
    PredefinedMessage.SLAVE_EXPLICIT_RESPONSE: (_G2, 3, MacRole.SLAVE),
    PredefinedMessage.MASTER_EXPLICIT_REQUEST: (_G2, 4, MacRole.SLAVE),
    PredefinedMessage.MASTER_POLL_COMMAND: (_G2, 5, MacRole.SLAVE),
    PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST: (_G2, 6, MacRole.SLAVE),
    PredefinedMessage.DUPLICATE_MAC_CHECK: (_G2, 7, MacRole.CLAIMED),
}

_BY_GROUP_AND_ID: dict[tuple[MessageGroup, int], PredefinedMessage] = {
    (group, message_id): message for message, (group, message_id, _) in _PREDEFINED.items()
}


@dataclass(frozen=True, slots=True)
class PredefinedId:
    """An identifier of the predefined set: which message, and the MAC it carries."""

    message: PredefinedMessage
    mac: int

    @property
    def arbitration_id(self) -> int:
        return predefined_can_id(self.message, self.mac)


def predefined_can_id(message: PredefinedMessage, mac: int) -> int:
    """The identifier of a predefined-set message for ``mac`` (whose MAC: ``mac_role``)."""
    return encode_can_id(message.group, message.message_id, mac)


def match_predefined(arbitration_id: int) -> PredefinedId | None:
    """The predefined-set message an identifier belongs to, or None for other valid ids.

    Raises :class:`InvalidCanId` for identifiers in no group.
    """
    can_id = decode_can_id(arbitration_id)
    message = _BY_GROUP_AND_ID.get((can_id.group, can_id.message_id))
    if message is None or can_id.mac is None:
        return None
    return PredefinedId(message, can_id.mac)
