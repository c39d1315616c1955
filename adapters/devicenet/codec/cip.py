"""CIP tables used on DeviceNet: general status codes, services, object classes,
DeviceNet-object additional codes and the allocation rejections seen in slaves.

Fact sheet 2.6 (general status codes), 2.7 (common services), 2.5 (allocation
rejections and additional codes), seed ``weg-cfw08-devicenet.pt.md`` section 5
(classes supported by the CFW-08). Codes are data: unknown values stay ints, and
:func:`general_status_text` names any byte.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum


class GeneralStatus(IntEnum):
    """CIP general status codes (fact sheet 2.6)."""

    SUCCESS = 0x00
    CONNECTION_FAILURE = 0x01
    RESOURCE_UNAVAILABLE = 0x02
    INVALID_PARAMETER_VALUE = 0x03
    PATH_SEGMENT_ERROR = 0x04
    PATH_DESTINATION_UNKNOWN = 0x05
    PARTIAL_TRANSFER = 0x06
    CONNECTION_LOST = 0x07
    SERVICE_NOT_SUPPORTED = 0x08
    INVALID_ATTRIBUTE_VALUE = 0x09
    ATTRIBUTE_LIST_ERROR = 0x0A
    ALREADY_IN_REQUESTED_STATE = 0x0B
    OBJECT_STATE_CONFLICT = 0x0C
    OBJECT_ALREADY_EXISTS = 0x0D
    ATTRIBUTE_NOT_SETTABLE = 0x0E
    PRIVILEGE_VIOLATION = 0x0F
    DEVICE_STATE_CONFLICT = 0x10
    REPLY_TOO_LARGE = 0x11
    NOT_ENOUGH_DATA = 0x13
    ATTRIBUTE_NOT_SUPPORTED = 0x14
    TOO_MUCH_DATA = 0x15
    OBJECT_DOES_NOT_EXIST = 0x16
    FRAGMENTATION_OUT_OF_SEQUENCE = 0x17
    INVALID_PARAMETER = 0x20
    GROUP_2_ONLY_SERVER_FAILURE = 0x2A


# Fact sheet 2.6, the "Meaning" column verbatim.
GENERAL_STATUS_TEXT: dict[int, str] = {
    GeneralStatus.SUCCESS: "Success",
    GeneralStatus.CONNECTION_FAILURE: "Connection failure",
    GeneralStatus.RESOURCE_UNAVAILABLE: "Resource unavailable",
    GeneralStatus.INVALID_PARAMETER_VALUE: "Invalid parameter value",
    GeneralStatus.PATH_SEGMENT_ERROR: "Path segment error",
    GeneralStatus.PATH_DESTINATION_UNKNOWN: "Path destination unknown",
    GeneralStatus.PARTIAL_TRANSFER: "Partial transfer",
    GeneralStatus.CONNECTION_LOST: "Connection lost",
    GeneralStatus.SERVICE_NOT_SUPPORTED: "Service not supported",
    GeneralStatus.INVALID_ATTRIBUTE_VALUE: "Invalid attribute value",
    GeneralStatus.ATTRIBUTE_LIST_ERROR: "Attribute list error",
    GeneralStatus.ALREADY_IN_REQUESTED_STATE: "Already in requested state",
    GeneralStatus.OBJECT_STATE_CONFLICT: "Object state conflict",
    GeneralStatus.OBJECT_ALREADY_EXISTS: "Object already exists",
    GeneralStatus.ATTRIBUTE_NOT_SETTABLE: "Attribute not settable",
    GeneralStatus.PRIVILEGE_VIOLATION: "Privilege violation",
    GeneralStatus.DEVICE_STATE_CONFLICT: "Device state conflict",
    GeneralStatus.REPLY_TOO_LARGE: "Reply too large",
    GeneralStatus.NOT_ENOUGH_DATA: "Not enough data",
    GeneralStatus.ATTRIBUTE_NOT_SUPPORTED: "Attribute not supported",
    GeneralStatus.TOO_MUCH_DATA: "Too much data",
    GeneralStatus.OBJECT_DOES_NOT_EXIST: "Object does not exist",
    GeneralStatus.FRAGMENTATION_OUT_OF_SEQUENCE: "Fragmentation out of sequence",
    GeneralStatus.INVALID_PARAMETER: "Invalid parameter",
    GeneralStatus.GROUP_2_ONLY_SERVER_FAILURE: "Group 2 Only server failure",
}


def general_status_text(code: int) -> str:
    """The text of a general status byte; codes outside fact sheet 2.6 are named as such."""
    return GENERAL_STATUS_TEXT.get(code, f"Unknown general status 0x{code:02X}")


NO_ADDITIONAL_CODE = 0xFF  # fact sheet 2.4: error reply additional code 0xFF = none


class DeviceNetAdditionalCode(IntEnum):
    """Additional codes of the DeviceNet object (class 3) [GCF][JB] (fact sheet 2.5)."""

    ALLOCATION_CONFLICT = 0x01
    INVALID_CHOICE = 0x02
    INVALID_GROUP_2_ONLY_REQUEST = 0x03
    PREDEFINED_SET_RESOURCES_UNAVAILABLE = 0x04
    NONE = NO_ADDITIONAL_CODE


DEVICENET_ADDITIONAL_CODE_TEXT: dict[int, str] = {
    DeviceNetAdditionalCode.ALLOCATION_CONFLICT: "Allocation conflict",
    DeviceNetAdditionalCode.INVALID_CHOICE: "Invalid allocation choice",
    DeviceNetAdditionalCode.INVALID_GROUP_2_ONLY_REQUEST: "Invalid Group 2 Only request",
    DeviceNetAdditionalCode.PREDEFINED_SET_RESOURCES_UNAVAILABLE: (
        "Predefined Master/Slave Connection Set resources unavailable"
    ),
    DeviceNetAdditionalCode.NONE: "No additional code",
}


class AllocationRejection(Enum):
    """Why a slave rejects Allocate/Release, as reference slaves answer (fact sheet 2.5)."""

    OWNED_BY_ANOTHER_MASTER = "owned by another master"
    INVALID_CHOICE = "invalid allocation choice"
    UNSUPPORTED_CHOICE = "unsupported allocation choice bits"
    ALREADY_ALLOCATED = "already allocated"
    INVALID_GROUP_2_ONLY_REQUEST = "invalid request on the Group 2 Only port"


@dataclass(frozen=True, slots=True)
class StatusPair:
    """A general status with its additional code, as an error response carries them."""

    general_status: int
    additional_code: int = NO_ADDITIONAL_CODE


# Fact sheet 2.5, "Rejections seen in reference slaves" [JB][SOJO]: what a server
# answers (the first pair is the one a simulated slave sends).
ALLOCATION_REJECTIONS: dict[AllocationRejection, tuple[StatusPair, ...]] = {
    AllocationRejection.OWNED_BY_ANOTHER_MASTER: (StatusPair(0x0C, 0x01),),
    AllocationRejection.INVALID_CHOICE: (StatusPair(0x09, 0x02),),
    AllocationRejection.UNSUPPORTED_CHOICE: (StatusPair(0x02, 0x02),),
    AllocationRejection.ALREADY_ALLOCATED: (StatusPair(0x0B, 0x02),),
    AllocationRejection.INVALID_GROUP_2_ONLY_REQUEST: (
        StatusPair(0x08, 0x03),
        StatusPair(0x02, 0x03),
    ),
}

_REJECTION_BY_PAIR: dict[StatusPair, AllocationRejection] = {
    pair: rejection for rejection, pairs in ALLOCATION_REJECTIONS.items() for pair in pairs
}


def allocation_rejection(general_status: int, additional_code: int) -> AllocationRejection | None:
    """What an Allocate/Release error response means, or None if no known pattern."""
    return _REJECTION_BY_PAIR.get(StatusPair(general_status, additional_code))


class Service(IntEnum):
    """CIP service codes used on DeviceNet (fact sheet 2.7)."""

    GET_ATTRIBUTES_ALL = 0x01
    SET_ATTRIBUTES_ALL = 0x02
    RESET = 0x05
    START = 0x06
    STOP = 0x07
    GET_ATTRIBUTE_SINGLE = 0x0E
    SET_ATTRIBUTE_SINGLE = 0x10
    ERROR_RESPONSE = 0x14
    RESTORE = 0x15
    SAVE = 0x16
    ALLOCATE_MASTER_SLAVE_CONNECTION_SET = 0x4B
    RELEASE_MASTER_SLAVE_CONNECTION_SET = 0x4C


class CipClass(IntEnum):
    """Object classes of a DeviceNet AC/DC drive (seed section 5; fact sheet 2.11, 2.12)."""

    IDENTITY = 0x01
    MESSAGE_ROUTER = 0x02
    DEVICENET = 0x03
    ASSEMBLY = 0x04
    CONNECTION = 0x05
    MOTOR_DATA = 0x28
    CONTROL_SUPERVISOR = 0x29
    AC_DC_DRIVE = 0x2A
    ACKNOWLEDGE_HANDLER = 0x2B
