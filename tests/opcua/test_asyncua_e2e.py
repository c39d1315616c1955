"""The OPC UA server through a real daemon, with asyncua's own client over TCP: browse,
read, subscribe, the drives' methods (accepted and refused), alarms with Acknowledge, and
HistoryRead from the gateway's history store (a fake one here)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, Node, ua
from asyncua.common.events import Event, get_filter_from_event_type

from gateway.model import DriveCommand, DriveStatus, Source
from gateway.opcua.frontend import OpcuaFrontEnd
from gateway.opcua.variables import PERCENT, RPM
from tests.opcua.harness import (
    HISTORY_EVENTS,
    HISTORY_ROWS,
    HISTORY_START,
    TIMEOUT,
    Gateway,
    running_gateway,
)
from tests.reliability.demo import until

NS = 2


def node(client: Client, drive: str, name: str) -> Node:
    return client.get_node(ua.NodeId(f"{drive}.{name}", NS))


async def call(client: Client, drive: str, method: str, *args: Any) -> ua.CallMethodResult:
    """The raw CallMethodResult (status and the Result text, whatever the status)."""
    request = ua.CallMethodRequest(
        ObjectId=ua.NodeId(drive, NS),
        MethodId=ua.NodeId(f"{drive}.{method}", NS),
        InputArguments=[ua.Variant(a, ua.VariantType.Double) for a in args],
    )
    (result,) = await client.uaclient.call([request])
    return result


def text(result: ua.CallMethodResult) -> str:
    return str(result.OutputArguments[0].Value)


class Changes:
    """Data changes and events of a subscription, waited for by predicate."""

    def __init__(self) -> None:
        self.values: dict[str, list[Any]] = {}
        self.statuses: dict[str, list[int]] = {}
        self.events: list[Any] = []
        self.changed = asyncio.Event()

    def datachange_notification(self, node: Node, val: Any, data: Any) -> None:
        self.values.setdefault(node.nodeid.Identifier, []).append(val)
        status = data.monitored_item.Value.StatusCode
        self.statuses.setdefault(node.nodeid.Identifier, []).append(status.value)
        self.changed.set()

    def event_notification(self, event: Any) -> None:
        self.events.append(event)
        self.changed.set()

    async def until(self, predicate: Any) -> None:
        async with asyncio.timeout(TIMEOUT):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


@pytest.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    async with running_gateway(tmp_path) as gw:
        yield gw


@pytest.fixture
async def client(gateway: Gateway) -> AsyncIterator[Client]:
    async with Client(gateway.endpoint, timeout=TIMEOUT) as c:
        yield c


async def test_browse_the_drive_model(gateway: Gateway, client: Client) -> None:
    drives = await client.nodes.objects.get_child([f"{NS}:Drives"])
    names = sorted([(await n.read_browse_name()).Name for n in await drives.get_children()])
    assert names == ["m1", "m2", "soft"]
    m1 = await drives.get_child([f"{NS}:m1"])
    children = {(await n.read_browse_name()).Name for n in await m1.get_children()}
    assert {"Device", "Bus", "Address", "Firmware", "SpeedRpm", "CurrentA", "Status"} <= children
    assert {"FaultCode", "FaultText", "ControlClient", "Run", "Stop", "QuickStop"} <= children
    assert {"Reset", "SetSpeed", "FaultAlarm"} <= children
    assert await node(client, "m1", "Device").read_value() == "test"
    assert await node(client, "m1", "Bus").read_value() == "line1"
    assert await node(client, "m1", "Address").read_value() == 1
    speed = node(client, "m1", "SpeedRpm")
    assert (await speed.read_type_definition()) == ua.NodeId(ua.ObjectIds.AnalogItemType)
    units = await node(client, "m1", "SpeedRpm.EngineeringUnits").read_value()
    assert (units.UnitId, units.DisplayName.Text) == (RPM.unit_id, "rpm")
    assert RPM.unit_id == 0x52504D  # "RPM": the UNECE code's characters (Part 8, 5.6.3)
    pct = await node(client, "m1", "SpeedPercent.EngineeringUnits").read_value()
    assert pct.UnitId == PERCENT.unit_id == 0x5031
    # the range follows the drive's scale once its adapter gave it: 100 % of 1800 rpm
    changes = Changes()
    sub = await client.create_subscription(100, changes)
    await sub.subscribe_data_change(node(client, "m1", "SpeedRpm.EURange"))
    await changes.until(
        lambda: any(
            (r.Low, r.High) == (-1800.0, 1800.0)
            for r in changes.values.get("m1.SpeedRpm.EURange", [])
        )
    )
    assert await node(client, "m1", "Comm").read_value() == "online"
    # a reading the drive does not give (a soft starter's speed): no value, never 0; its
    # status says why: no communication while the drive was offline, no data once online
    await sub.subscribe_data_change(node(client, "soft", "SpeedRpm"))
    await changes.until(
        lambda: ua.StatusCodes.BadNoData in changes.statuses.get("soft.SpeedRpm", [])
    )
    assert changes.values["soft.SpeedRpm"][-1] is None
    front_end = gateway.daemon.front_ends["opcua"]
    assert isinstance(front_end, OpcuaFrontEnd)
    for _ in range(2):  # a whole pass of the once-a-second work since the line runs
        front_end.slow_pass.clear()
        await asyncio.wait_for(front_end.slow_pass.wait(), TIMEOUT)
    cycles = await client.nodes.objects.get_child([f"{NS}:Buses", f"{NS}:line1", f"{NS}:cycles"])
    assert await cycles.read_value() > 0


async def test_subscribe_run_and_stop_through_the_hub(gateway: Gateway, client: Client) -> None:
    changes = Changes()
    sub = await client.create_subscription(100, changes)
    await sub.subscribe_data_change(
        [node(client, "m1", n) for n in ("Running", "SpeedRpm", "ControlSource")]
    )
    assert (await call(client, "m1", "SetSpeed", 900.0)).StatusCode.is_good()
    result = await call(client, "m1", "Run")
    assert result.StatusCode.is_good() and text(result) == "accepted"
    state = await gateway.wait_for("m1", lambda s: s.running)
    assert state.control_source is Source.OPCUA
    assert (state.control_client or "").startswith("session ")
    await changes.until(lambda: True in changes.values.get("m1.Running", []))
    await changes.until(lambda: any((v or 0) > 0 for v in changes.values.get("m1.SpeedRpm", [])))
    assert "opcua" in changes.values["m1.ControlSource"]
    result = await call(client, "m1", "Stop")
    assert result.StatusCode.is_good()
    await changes.until(lambda: changes.values["m1.Running"][-1] is False)
    assert await node(client, "m1", "LastCommandResult").read_value() == "accepted"


async def test_a_refusal_is_a_bad_status_with_the_reason(gateway: Gateway, client: Client) -> None:
    result = await call(client, "m2", "Run")  # m2 takes commands from modbus only
    assert result.StatusCode.value == ua.StatusCodes.BadInvalidState
    assert text(result) == "drive m2 takes commands from modbus only"
    assert await node(client, "m2", "LastCommandResult").read_value() == text(result)
    assert not gateway.daemon.hub.desired("m2").run
    result = await call(client, "soft", "SetSpeed", 100.0)  # a soft starter has no speed
    assert result.StatusCode.value == ua.StatusCodes.BadInvalidState
    assert "no speed reference" in text(result)
    request = ua.CallMethodRequest(
        ObjectId=ua.NodeId("m1", NS),
        MethodId=ua.NodeId("m1.SetSpeed", NS),
        InputArguments=[ua.Variant("fast", ua.VariantType.String)],
    )
    (result,) = await client.uaclient.call([request])
    assert result.StatusCode.value == ua.StatusCodes.BadInvalidArgument
    assert gateway.daemon.hub.desired("m1").speed_rpm is None
    # a stop is never refused, even from a source the drive's control leaves out
    assert (await call(client, "m2", "Stop")).StatusCode.is_good()


async def test_a_faulted_drive_refuses_run_raises_an_alarm_and_takes_acknowledge(
    gateway: Gateway, client: Client
) -> None:
    changes = Changes()
    sub = await client.create_subscription(100, changes)
    alarm_type = client.get_node(ua.ObjectIds.AlarmConditionType)
    await sub.subscribe_events(client.nodes.server, alarm_type)
    line = gateway.daemon.runtime.adapters["line1"]
    adapter: Any = line.adapter
    await line.call(lambda: adapter.inject_fault("m1", 7))
    await gateway.wait_for("m1", lambda s: s.status is DriveStatus.FAULTED)
    result = await call(client, "m1", "Run")
    assert result.StatusCode.value == ua.StatusCodes.BadInvalidState
    assert text(result) == (
        "drive m1 is faulted 7 (test fault 7): reset the fault, then send a new run command"
    )
    await changes.until(lambda: any(e.Retain for e in changes.events))
    raised = next(e for e in changes.events if e.Retain)
    assert raised.Message.Text == "m1: fault 7: test fault 7"
    assert raised.SourceName == "m1" and raised.Severity == 800
    condition = ua.NodeId("m1.FaultAlarm", NS)
    ack = client.get_node(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)
    stale = ua.CallMethodRequest(
        ObjectId=condition,
        MethodId=ack.nodeid,
        InputArguments=[
            ua.Variant(b"not-an-event", ua.VariantType.ByteString),
            ua.Variant(ua.LocalizedText("seen"), ua.VariantType.LocalizedText),
        ],
    )
    (result,) = await client.uaclient.call([stale])
    assert result.StatusCode.value == ua.StatusCodes.BadEventIdUnknown
    good = ua.CallMethodRequest(
        ObjectId=condition,
        MethodId=ack.nodeid,
        InputArguments=[
            ua.Variant(raised.EventId, ua.VariantType.ByteString),
            ua.Variant(ua.LocalizedText("seen"), ua.VariantType.LocalizedText),
        ],
    )
    (result,) = await client.uaclient.call([good])
    assert result.StatusCode.is_good()
    await changes.until(lambda: len(changes.events) >= 2)
    acked = changes.events[-1]
    assert acked.Retain is True  # still active: retained until the fault ends
    (result,) = await client.uaclient.call([good])
    assert result.StatusCode.value == ua.StatusCodes.BadEventIdUnknown  # a newer event exists
    assert (await call(client, "m1", "Reset")).StatusCode.is_good()
    await gateway.wait_for("m1", lambda s: s.status is not DriveStatus.FAULTED)
    await changes.until(lambda: not changes.events[-1].Retain)  # inactive and acknowledged


async def test_history_read_serves_the_history_store(gateway: Gateway, client: Client) -> None:
    speed = node(client, "m1", "SpeedRpm")
    start = datetime.fromtimestamp(HISTORY_START + 10, UTC)
    end = datetime.fromtimestamp(HISTORY_START + 19, UTC)
    values = await speed.read_raw_history(start, end)
    assert [v.Value.Value for v in values] == [10.0 * i for i in range(10, 20)]
    assert values[0].SourceTimestamp == start
    assert gateway.history.calls[-1][:3] == ("m1", HISTORY_START + 10, HISTORY_START + 19)
    current = await node(client, "m1", "CurrentA").read_raw_history(start, end)
    assert {v.StatusCode.value for v in current} == {ua.StatusCodes.BadNoData}
    # a limit per request: the rest comes with the continuation point
    everything = await speed.read_raw_history(
        datetime.fromtimestamp(HISTORY_START, UTC),
        datetime.fromtimestamp(HISTORY_START + 99, UTC),
        numvalues=0,
    )
    assert len(everything) == HISTORY_ROWS


def _at(offset: float) -> datetime:
    return datetime.fromtimestamp(HISTORY_START + offset, UTC)


async def test_history_read_of_events_serves_the_history_stores_events(
    gateway: Gateway, client: Client
) -> None:
    """A drive's events are read back from its object, every drive's from the Server."""
    m1 = client.get_node(ua.NodeId("m1", 2))
    notifier = await m1.read_attribute(ua.AttributeIds.EventNotifier)
    assert notifier.Value.Value & ua.EventNotifier.HistoryRead.mask  # it says it has history
    events = await m1.read_event_history(_at(10), _at(19))
    assert [e.Message.Text for e in events] == [f"m1: m1 {i}" for i in range(10, 20)]
    first = events[0]
    assert (first.SourceName, first.SourceNode, first.Time) == ("m1", m1.nodeid, _at(10))
    assert first.EventType == ua.NodeId(ua.ObjectIds.BaseEventType)
    assert [e.Severity for e in events[:2]] == [800, 200]  # a fault as its alarm, a command
    again = await m1.read_event_history(_at(10), _at(19))
    assert [e.EventId for e in again] == [e.EventId for e in events]  # the same on every read
    assert len({e.EventId for e in events}) == len(events)
    # the newest first when the range is given backwards
    backwards = await m1.read_event_history(_at(19), _at(10))
    assert [e.Message.Text for e in backwards] == [f"m1: m1 {i}" for i in range(19, 9, -1)]
    # every drive's events from the Server object, each with its drive's object as source
    every = await client.get_node(ua.ObjectIds.Server).read_event_history(_at(0), _at(4.9))
    assert [(e.SourceName, e.SourceNode.Identifier) for e in every] == [
        (d, d) for i in range(5) for d in ("m1", "m2")
    ]


async def test_history_read_of_events_continues_where_a_page_ended(
    gateway: Gateway, client: Client
) -> None:
    """At most NumValuesPerNode events a response; the continuation point reads on."""
    m1 = client.get_node(ua.NodeId("m1", 2))
    details = ua.ReadEventDetails()
    details.StartTime, details.EndTime = _at(0), _at(100)
    details.NumValuesPerNode = 7
    details.Filter = await get_filter_from_event_type([client.get_node(ua.ObjectIds.BaseEventType)])
    seen: list[str] = []
    value = ua.HistoryReadValueId()
    value.NodeId = m1.nodeid
    for _ in range(HISTORY_EVENTS):
        params = ua.HistoryReadParameters()
        params.HistoryReadDetails = details
        params.TimestampsToReturn = ua.TimestampsToReturn.Both
        params.NodesToRead = [value]
        (result,) = await client.uaclient.history_read(params)
        result.StatusCode.check()
        fields = [
            Event.from_event_fields(details.Filter.SelectClauses, f.EventFields)
            for f in result.HistoryData.Events
        ]
        assert len(fields) <= 7
        seen += [e.Message.Text for e in fields]
        if not result.ContinuationPoint:
            break
        value = ua.HistoryReadValueId()
        value.NodeId = m1.nodeid
        value.ContinuationPoint = result.ContinuationPoint
    assert seen == [f"m1: m1 {i}" for i in range(HISTORY_EVENTS)]
    assert gateway.history.event_calls[-1][3] == 7  # the store was asked for one page


async def test_history_read_of_events_of_a_node_without_events_is_refused(
    gateway: Gateway, client: Client
) -> None:
    details = ua.ReadEventDetails()
    details.StartTime, details.EndTime = _at(0), _at(100)
    details.Filter = await get_filter_from_event_type([client.get_node(ua.ObjectIds.BaseEventType)])
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await node(client, "m1", "SpeedRpm").history_read_events(details)
    assert refused.value.code == ua.StatusCodes.BadHistoryOperationUnsupported


async def test_a_session_in_control_feeds_the_watchdog_while_its_client_is_there(
    tmp_path: Path,
) -> None:
    async with running_gateway(tmp_path, command_timeout=2.0) as gw:
        front_end = gw.daemon.front_ends["opcua"]
        assert isinstance(front_end, OpcuaFrontEnd)
        with gw.daemon.hub.subscribe_events() as events:
            async with Client(gw.endpoint, timeout=TIMEOUT) as client:
                await client.create_subscription(100, Changes())  # its publish requests
                assert (await call(client, "m1", "SetSpeed", 600.0)).StatusCode.is_good()
                assert (await call(client, "m1", "Run")).StatusCode.is_good()
                await gw.wait_for("m1", lambda s: s.running)
                for _ in range(4):  # twice the command_timeout with the client there
                    front_end.slow_pass.clear()
                    await asyncio.wait_for(front_end.slow_pass.wait(), TIMEOUT)
                assert gw.daemon.hub.desired("m1").run
                assert not [e for e in events.drain() if e.kind.value == "safety"]
            # the client went: nothing feeds the watchdog, the drive is stopped
            state = await gw.wait_for("m1", lambda s: not s.running)
            assert state.control_source is Source.GATEWAY
            texts = [e.text for e in events.drain() if e.kind.value == "safety"]
            assert any(
                "no command from opcua session" in t and "ramp_stop applied" in t for t in texts
            )


async def test_history_read_serves_the_gateways_own_store(tmp_path: Path) -> None:
    """HistoryRead against the SQLite history the daemon records (``[history]`` on): the
    samples a client reads are the store's own."""
    history = f"""
[history]
enabled = true
path = "{tmp_path / "history.sqlite"}"
period = 0.1
batch_interval = 0.1
"""
    async with running_gateway(tmp_path, fake_history=False, extra_root=history) as gateway:
        store = gateway.daemon.runtime.history
        assert store is not None
        gateway.daemon.hub.submit("m1", Source.ZENOH, DriveCommand(run=True, speed_rpm=300.0))
        start = time.time() - 1.0

        def recorded() -> list[Any]:
            return [
                r for r in store.readings("m1", start, time.time()) if r.values.get("speed_rpm")
            ]

        await until(lambda: len(recorded()) >= 5)  # the writer commits every batch_interval
        await until(lambda: bool(store.events("m1", start, time.time())))
        rows = recorded()
        stored = store.events("m1", start, time.time())
        async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
            # a datetime holds microseconds (rounded): ask from just before the first row
            first = datetime.fromtimestamp(rows[0].t - 0.01, UTC)
            last = datetime.fromtimestamp(rows[-1].t + 0.01, UTC)  # the last one within
            values = await node(client, "m1", "SpeedRpm").read_raw_history(first, last)
            events = await client.get_node(ua.NodeId("m1", 2)).read_event_history(
                datetime.fromtimestamp(start, UTC),
                datetime.fromtimestamp(stored[-1].t + 0.01, UTC),
            )
        assert [(e.Message.Text, e.SourceName) for e in events] == [
            (f"m1: {e.text}", "m1") for e in stored
        ]
        served = [(v.SourceTimestamp.timestamp(), v.Value.Value) for v in values]
        assert len(served) >= len(rows)
        for row in rows:
            near = [value for t, value in served if abs(t - row.t) < 1e-3]
            assert near == [row.values["speed_rpm"]], (row, served)
