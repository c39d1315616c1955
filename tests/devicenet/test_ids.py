"""CAN identifiers and the predefined connection set (fact sheet 2.1, 2.2)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.ids import (
    CanId,
    Group3Message,
    Group4Message,
    MacRole,
    MessageGroup,
    PredefinedId,
    PredefinedMessage,
    decode_can_id,
    encode_can_id,
    match_predefined,
    predefined_can_id,
)
from adapters.devicenet.errors import InvalidCanId
from gateway.errors import FrameDecodeError, FrameEncodeError
from tests.devicenet.strategies import macs

G1, G2, G3, G4 = (
    MessageGroup.GROUP_1,
    MessageGroup.GROUP_2,
    MessageGroup.GROUP_3,
    MessageGroup.GROUP_4,
)
MASTER, SLAVE = 0, 10  # fact sheet 2.2 "Example IDs"

# Fact sheet 2.2, "Example IDs (master MAC 0, slave MAC 10)", verbatim.
EXAMPLE_IDS = [
    (PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST, SLAVE, 0x456),  # Allocate
    (PredefinedMessage.SLAVE_EXPLICIT_RESPONSE, SLAVE, 0x453),
    (PredefinedMessage.MASTER_EXPLICIT_REQUEST, SLAVE, 0x454),
    (PredefinedMessage.MASTER_POLL_COMMAND, SLAVE, 0x455),
    (PredefinedMessage.SLAVE_POLL_RESPONSE, SLAVE, 0x3CA),
    (PredefinedMessage.DUPLICATE_MAC_CHECK, MASTER, 0x407),
]


@pytest.mark.parametrize(("message", "mac", "arbitration_id"), EXAMPLE_IDS)
def test_fact_sheet_example_ids_both_ways(message, mac, arbitration_id):
    assert predefined_can_id(message, mac) == arbitration_id
    assert match_predefined(arbitration_id) == PredefinedId(message, mac)
    assert PredefinedId(message, mac).arbitration_id == arbitration_id


@pytest.mark.parametrize(
    ("arbitration_id", "expected"),
    [
        (0x000, CanId(G1, 0, 0)),
        (0x3FF, CanId(G1, 15, 63)),
        (0x400, CanId(G2, 0, 0)),
        (0x5FF, CanId(G2, 7, 63)),
        (0x600, CanId(G3, 0, 0)),
        (0x7BF, CanId(G3, 6, 63)),
        (0x74A, CanId(G3, Group3Message.UNCONNECTED_RESPONSE, 10)),
        (0x78A, CanId(G3, Group3Message.UNCONNECTED_REQUEST, 10)),
        (0x7C0, CanId(G4, 0)),
        (0x7EC, CanId(G4, Group4Message.COMM_FAULTED_RESPONSE)),
        (0x7EF, CanId(G4, Group4Message.OFFLINE_OWNERSHIP_REQUEST)),
    ],
)
def test_group_boundaries(arbitration_id, expected):
    assert decode_can_id(arbitration_id) == expected
    assert expected.arbitration_id == arbitration_id


@pytest.mark.parametrize("arbitration_id", [*range(0x7F0, 0x800), -1, 0x800, 0xFFFF])
def test_invalid_ids_raise_typed_error(arbitration_id):
    with pytest.raises(InvalidCanId) as info:
        decode_can_id(arbitration_id)
    assert isinstance(info.value, FrameDecodeError)
    with pytest.raises(InvalidCanId):
        match_predefined(arbitration_id)


def test_invalid_id_error_names_the_identifier():
    with pytest.raises(InvalidCanId, match="0x7F5"):
        decode_can_id(0x7F5)


def test_every_valid_identifier_round_trips():
    for arbitration_id in range(0x7F0):
        can_id = decode_can_id(arbitration_id)
        assert encode_can_id(can_id.group, can_id.message_id, can_id.mac) == arbitration_id


@pytest.mark.parametrize(
    ("group", "message_id", "mac"),
    [
        (G1, 16, 0),
        (G1, -1, 0),
        (G2, 8, 0),
        (G3, 7, 0),
        (G4, 0x30, None),
        (G1, 0, 64),
        (G2, 0, -1),
        (G2, 0, None),
        (G4, 0, 5),
    ],
)
def test_encode_out_of_range_is_an_encode_error(group, message_id, mac):
    with pytest.raises(FrameEncodeError):
        encode_can_id(group, message_id, mac)


def test_predefined_set_table():
    # Fact sheet 2.2: group, message id and whose MAC.
    table = {m: (m.group, m.message_id, m.mac_role) for m in PredefinedMessage}
    assert table == {
        PredefinedMessage.SLAVE_MULTICAST_POLL_RESPONSE: (G1, 0xC, MacRole.SLAVE),
        PredefinedMessage.SLAVE_COS_CYCLIC: (G1, 0xD, MacRole.SLAVE),
        PredefinedMessage.SLAVE_BIT_STROBE_RESPONSE: (G1, 0xE, MacRole.SLAVE),
        PredefinedMessage.SLAVE_POLL_RESPONSE: (G1, 0xF, MacRole.SLAVE),
        PredefinedMessage.MASTER_BIT_STROBE_COMMAND: (G2, 0, MacRole.MASTER),
        PredefinedMessage.MASTER_MULTICAST_POLL: (G2, 1, MacRole.UNSPECIFIED),
        PredefinedMessage.MASTER_COS_CYCLIC_ACK: (G2, 2, MacRole.SLAVE),
        PredefinedMessage.SLAVE_EXPLICIT_RESPONSE: (G2, 3, MacRole.SLAVE),
        PredefinedMessage.MASTER_EXPLICIT_REQUEST: (G2, 4, MacRole.SLAVE),
        PredefinedMessage.MASTER_POLL_COMMAND: (G2, 5, MacRole.SLAVE),
        PredefinedMessage.UNCONNECTED_EXPLICIT_REQUEST: (G2, 6, MacRole.SLAVE),
        PredefinedMessage.DUPLICATE_MAC_CHECK: (G2, 7, MacRole.CLAIMED),
    }


@pytest.mark.parametrize("arbitration_id", [0x000, 0x2CA, 0x600, 0x7C0, 0x7EF])
def test_ids_outside_the_predefined_set_match_nothing(arbitration_id):
    assert match_predefined(arbitration_id) is None


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(PredefinedMessage), macs)
def test_predefined_round_trip(message, mac):
    arbitration_id = predefined_can_id(message, mac)
    assert match_predefined(arbitration_id) == PredefinedId(message, mac)


@settings(max_examples=200, deadline=None)
@given(st.integers(-(1 << 16), 1 << 16))
def test_decode_raises_only_typed_errors(arbitration_id):
    try:
        can_id = decode_can_id(arbitration_id)
    except InvalidCanId:
        assert not 0 <= arbitration_id < 0x7F0
        return
    assert can_id.arbitration_id == arbitration_id
