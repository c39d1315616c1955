"""CIP tables and DeviceNet object numbers (fact sheet 2.5, 2.6, 2.7, 2.9, 2.12)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.cip import (
    ALLOCATION_REJECTIONS,
    GENERAL_STATUS_TEXT,
    AllocationRejection,
    CipClass,
    DeviceNetAdditionalCode,
    GeneralStatus,
    Service,
    allocation_rejection,
    general_status_text,
)
from adapters.devicenet.codec.objects import (
    AllocationChoice,
    AllocationInfo,
    ConnectionAttribute,
    ConnectionState,
    WatchdogAction,
)
from adapters.devicenet.errors import DataTypeDecodeError, DeviceNetDecodeError
from gateway.errors import FrameEncodeError

# Fact sheet 2.6, verbatim.
FACT_SHEET_2_6 = {
    0x00: "Success",
    0x01: "Connection failure",
    0x02: "Resource unavailable",
    0x03: "Invalid parameter value",
    0x04: "Path segment error",
    0x05: "Path destination unknown",
    0x06: "Partial transfer",
    0x07: "Connection lost",
    0x08: "Service not supported",
    0x09: "Invalid attribute value",
    0x0A: "Attribute list error",
    0x0B: "Already in requested state",
    0x0C: "Object state conflict",
    0x0D: "Object already exists",
    0x0E: "Attribute not settable",
    0x0F: "Privilege violation",
    0x10: "Device state conflict",
    0x11: "Reply too large",
    0x13: "Not enough data",
    0x14: "Attribute not supported",
    0x15: "Too much data",
    0x16: "Object does not exist",
    0x17: "Fragmentation out of sequence",
    0x20: "Invalid parameter",
    0x2A: "Group 2 Only server failure",
}


def test_general_status_table_is_the_fact_sheet():
    assert dict(GENERAL_STATUS_TEXT) == FACT_SHEET_2_6
    assert {int(s) for s in GeneralStatus} == set(FACT_SHEET_2_6)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 0xFF))
def test_every_status_byte_has_a_text(code):
    text = general_status_text(code)
    assert text == FACT_SHEET_2_6.get(code, f"Unknown general status 0x{code:02X}")


@pytest.mark.parametrize(
    ("general", "additional", "rejection"),
    [
        (0x0C, 0x01, AllocationRejection.OWNED_BY_ANOTHER_MASTER),
        (0x09, 0x02, AllocationRejection.INVALID_CHOICE),
        (0x02, 0x02, AllocationRejection.UNSUPPORTED_CHOICE),
        (0x0B, 0x02, AllocationRejection.ALREADY_ALLOCATED),
        (0x08, 0x03, AllocationRejection.INVALID_GROUP_2_ONLY_REQUEST),
        (0x02, 0x03, AllocationRejection.INVALID_GROUP_2_ONLY_REQUEST),
        (0x0C, 0x02, None),
        (0x14, 0xFF, None),
    ],
)
def test_allocation_rejections_of_fact_sheet_2_5(general, additional, rejection):
    assert allocation_rejection(general, additional) is rejection


def test_every_rejection_has_a_pair_it_is_read_back_from():
    for rejection, pairs in ALLOCATION_REJECTIONS.items():
        for pair in pairs:
            assert allocation_rejection(pair.general_status, pair.additional_code) is rejection


def test_devicenet_additional_codes():
    # Fact sheet 2.5 [GCF][JB].
    assert [int(c) for c in DeviceNetAdditionalCode] == [0x01, 0x02, 0x03, 0x04, 0xFF]


def test_service_and_class_codes():
    # Fact sheet 2.7 and seed section 5.
    codes = {s.name: int(s) for s in Service}
    assert codes["GET_ATTRIBUTE_SINGLE"] == 0x0E
    assert codes["SET_ATTRIBUTE_SINGLE"] == 0x10
    assert codes["ALLOCATE_MASTER_SLAVE_CONNECTION_SET"] == 0x4B
    assert codes["RELEASE_MASTER_SLAVE_CONNECTION_SET"] == 0x4C
    assert codes["RESET"] == 0x05
    assert {c.name: int(c) for c in CipClass}["AC_DC_DRIVE"] == 0x2A


def test_connection_object_numbers():
    # Fact sheet 2.9.
    assert {a.name: int(a) for a in ConnectionAttribute}["EXPECTED_PACKET_RATE"] == 9
    assert {a.name: int(a) for a in ConnectionAttribute}["WATCHDOG_TIMEOUT_ACTION"] == 12
    assert [int(s) for s in ConnectionState] == list(range(7))
    assert [int(a) for a in WatchdogAction] == list(range(4))


def test_allocation_info_golden():
    # Fact sheet 2.5: class 3 attribute 5 = choice byte + master MAC (0xFF = none).
    info = AllocationInfo(AllocationChoice.EXPLICIT | AllocationChoice.POLL, 0)
    assert info.encode() == b"\x03\x00"
    assert AllocationInfo.decode(b"\x00\xff") == AllocationInfo(AllocationChoice(0))


@pytest.mark.parametrize("data", [b"", b"\x03", b"\x03\x00\x00", b"\x03\x40"])
def test_allocation_info_bad_data(data):
    with pytest.raises(DataTypeDecodeError):
        AllocationInfo.decode(data)


def test_allocation_info_encode_range():
    with pytest.raises(FrameEncodeError):
        AllocationInfo(AllocationChoice.EXPLICIT, 64).encode()


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=4))
def test_allocation_info_fuzz(data):
    try:
        info = AllocationInfo.decode(data)
    except DeviceNetDecodeError:
        return
    assert info.encode() == data
