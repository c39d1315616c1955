"""Issue 32 items 5 and 12 on the CANopen adapter, stepped with an injected clock: the
drive's own reaction to a lost master (``failsafe``), doubtful readings from conflicting
frames (set, reported rate-limited, cleared after DOUBT_HOLD), another master heard."""

from __future__ import annotations

from typing import Any

import pytest

from adapters.canopen.adapter import (
    CONFLICT_EVENT_EVERY,
    DOUBT_HOLD,
    CanOpenAdapter,
    failsafe_of,
)
from adapters.canopen.master import Configured, Conflict, Master, MasterHeard
from gateway.adapter import EventKind
from gateway.config import parse
from gateway.errors import LineHeld
from gateway.hub import Hub
from gateway.runtime.daemon import build_hub


def _adapter(bus_keys: dict[str, Any] | None = None, **drive: Any) -> tuple[CanOpenAdapter, Hub]:
    bus = {
        **(bus_keys or {}),
        "adapter": "canopen",
        "interface": "virtual",
        "channel": "issue32",
        "drives": [
            {"id": "d1", "device": "CiA 402", "address": 1, "eds": "eds/cia402-drive.eds"} | drive
        ],
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}}, "t"
    )
    adapter = CanOpenAdapter(config.buses[0])
    hub = build_hub(config)
    adapter._hub, adapter.engine = hub, Master(adapter.master_config(), adapter.node_configs)
    return adapter, hub


@pytest.mark.parametrize(
    ("option", "consumer", "failsafe"),
    [
        (1, "c", True),
        (2, "c", True),
        (3, "c", True),
        (0, "c", False),
        (None, "c", None),
        (-1, "c", None),
        (3, None, False),
    ],
)
def test_failsafe_from_0x6007_and_the_consumer(
    option: int | None, consumer: str | None, failsafe: bool | None
) -> None:
    value, text = failsafe_of(option, consumer)
    assert value is failsafe
    assert text


def test_the_configured_drive_publishes_its_failsafe_reaction() -> None:
    adapter, hub = _adapter(comm_loss_option=0)
    adapter._handle(0.0, Configured(1, {(0x6007, 0): (0).to_bytes(2, "little")}))
    state = hub.state("d1")
    assert state.failsafe is False
    assert state.failsafe_text is not None and "0x6007 = 0 (no action)" in state.failsafe_text
    adapter._handle(0.0, Configured(1, {(0x6007, 0): (3).to_bytes(2, "little")}))
    assert hub.state("d1").failsafe is True
    assert "0x1016:1 watches node 127" in (hub.state("d1").failsafe_text or "")


def test_without_the_gateways_heartbeat_no_drive_is_failsafe() -> None:
    bus_adapter, hub = _adapter({"heartbeat": 0}, comm_loss_option=3)
    bus_adapter._handle(0.0, Configured(1, {(0x6007, 0): (3).to_bytes(2, "little")}))
    assert hub.state("d1").failsafe is False


def test_a_conflict_makes_the_drive_doubtful_until_a_quiet_hold() -> None:
    adapter, hub = _adapter()
    with hub.subscribe_events() as events:
        adapter._handle(1.0, Conflict(1, "a second TPDO1 in one SYNC cycle"))
        adapter._handle(2.0, Conflict(1, "a second TPDO1 in one SYNC cycle"))
        assert hub.state("d1").doubtful
        adapter._refresh(1.0 + DOUBT_HOLD)
        assert hub.state("d1").doubtful  # the second conflict holds it on
        adapter._handle(1.0 + CONFLICT_EVENT_EVERY, Conflict(1, "x"))
        adapter._refresh(1.0 + CONFLICT_EVENT_EVERY + DOUBT_HOLD + 0.01)
        assert not hub.state("d1").doubtful
        seen = events.drain()
    bus = [e for e in seen if e.kind is EventKind.BUS]
    assert [e.data.get("conflicts") for e in bus[:2]] == [1, 2]  # rate-limited, counted
    assert bus[0].data["node"] == 1 and "node 1: a second TPDO1" in bus[0].text
    assert "readings trusted again" in bus[-1].text


def test_another_master_while_listening_is_a_line_held() -> None:
    adapter, _hub = _adapter()
    with pytest.raises(LineHeld, match="another master is on this line"):
        adapter._handle(0.1, MasterHeard("a SYNC from another producer", claimed=False))
    assert not adapter.claimed.is_set()


def test_another_master_later_makes_every_drive_doubtful() -> None:
    adapter, hub = _adapter()
    adapter._handle(5.0, MasterHeard("a SYNC from another producer", claimed=True))
    assert hub.state("d1").doubtful
