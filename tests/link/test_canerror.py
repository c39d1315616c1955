"""SocketCAN error frames (fact sheet Part 3, [LNX] error classes)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.can.health import LineHealth, health_after
from adapters.link.canerror import LineCondition, decode_error_frame

C = LineCondition


def test_error_classes() -> None:
    assert decode_error_frame(0x040, b"") == {C.BUS_OFF}
    assert decode_error_frame(0x020, bytes(8)) == {C.NO_ACK}
    assert decode_error_frame(0x100, bytes(8)) == {C.RESTARTED}
    assert decode_error_frame(0x001 | 0x002 | 0x008, bytes(8)) == {
        C.TX_TIMEOUT,
        C.LOST_ARBITRATION,
        C.PROTOCOL,
    }


def test_controller_details_in_data_1() -> None:
    passive = bytes([0, 0x20, 0, 0, 0, 0, 0, 0])
    assert decode_error_frame(0x004, passive) == {C.CONTROLLER, C.ERROR_PASSIVE}
    warning = bytes([0, 0x08, 0, 0, 0, 0, 0, 0])
    assert decode_error_frame(0x004, warning) == {C.CONTROLLER, C.ERROR_WARNING}
    overflow = bytes([0, 0x01])
    assert decode_error_frame(0x004, overflow) == {C.CONTROLLER, C.RX_OVERFLOW}
    # Controller details only count with the controller class bit.
    assert decode_error_frame(0x020, passive) == {C.NO_ACK}


def test_health() -> None:
    h = health_after(LineHealth.OK, frozenset({C.ERROR_WARNING}))
    assert h is LineHealth.ERROR_WARNING
    h = health_after(h, frozenset({C.ERROR_PASSIVE}))
    assert h is LineHealth.ERROR_PASSIVE
    h = health_after(h, frozenset({C.BUS_OFF}))
    assert h is LineHealth.BUS_OFF
    assert health_after(h, frozenset({C.ERROR_PASSIVE})) is LineHealth.BUS_OFF
    assert health_after(h, frozenset({C.RESTARTED})) is LineHealth.OK
    assert health_after(LineHealth.OK, frozenset({C.NO_ACK})) is LineHealth.OK


def test_back_to_error_active_clears_warning_and_passive() -> None:
    """[LNX] error.h: data[1] 0x40 CAN_ERR_CRTL_ACTIVE, "recovered to error active state"."""
    active = bytes([0, 0x40, 0, 0, 0, 0, 0, 0])
    assert decode_error_frame(0x004, active) == {C.CONTROLLER, C.ERROR_ACTIVE}
    for health in (LineHealth.ERROR_WARNING, LineHealth.ERROR_PASSIVE, LineHealth.BUS_OFF):
        assert health_after(health, decode_error_frame(0x004, active)) is LineHealth.OK


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 0x1FFFFFFF), st.binary(max_size=8))
def test_any_error_frame_decodes(error_class: int, data: bytes) -> None:
    found = decode_error_frame(error_class, data)
    assert all(isinstance(c, LineCondition) for c in found)
