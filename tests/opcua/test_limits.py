"""What one OPC UA session may hold, through a real daemon with asyncua's client: the
subscriptions and monitored items over ``[opcua] max_subscriptions`` / ``max_monitored_items``
refused with their status codes (the items within the limit still created and changing),
the room freed by deleting and by closing the session, a publishing interval below
``min_publishing_interval`` revised up; and the parts on their own (gateway/opcua/limits.py)."""

from __future__ import annotations

import logging
import math
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from asyncua import Client, Node, ua
from asyncua.server.address_space import AddressSpace
from asyncua.server.internal_subscription import InternalSubscription
from asyncua.server.subscription_service import SubscriptionService
from hypothesis import given
from hypothesis import strategies as st
from prometheus_client import generate_latest

from gateway.opcua.frontend import OpcuaFrontEnd
from gateway.opcua.limits import (
    UAPROCESSOR_LOG,
    Held,
    Limit,
    OwnRefusalLines,
    Refusals,
    SessionLimits,
    held_by,
    monitored_items_in,
    server_wide_subscriptions,
)
from gateway.opcua.sessions import GatewaySession
from gateway.web.counters import WebCounters
from gateway.web.feed import FeedCounters
from gateway.web.metrics import make_registry
from tests.opcua.harness import TIMEOUT, Gateway, running_gateway
from tests.opcua.test_asyncua_e2e import Changes, node

LIMITS = "max_subscriptions = 2\nmax_monitored_items = 5\n"
READINGS = ("SpeedRpm", "Running", "Comm", "Status", "CurrentA", "ControlSource", "Remote")


@pytest.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    async with running_gateway(tmp_path, extra=LIMITS) as gw:
        yield gw


def front_end(gw: Gateway) -> OpcuaFrontEnd:
    fe = gw.daemon.front_ends["opcua"]
    assert isinstance(fe, OpcuaFrontEnd)
    return fe


def service(gw: Gateway) -> SubscriptionService:
    server = front_end(gw).server
    assert server is not None
    return server.iserver.subscription_service


def only_session(gw: Gateway) -> GatewaySession:
    sessions = front_end(gw).sessions
    assert sessions is not None
    (session,) = list(sessions)
    return session


def held(gw: Gateway) -> Held:
    return held_by(service(gw), only_session(gw).session_id)


def readings(client: Client, drive: str, names: tuple[str, ...]) -> list[Node]:
    return [node(client, drive, n) for n in names]


async def test_subscriptions_beyond_the_limit_are_refused_and_deleting_frees_room(
    gateway: Gateway, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    front_end(gateway).refusals.clock = lambda: 0.0  # however slow the machine: one period
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        first = await client.create_subscription(100, Changes())
        await client.create_subscription(100, Changes())
        for _ in range(6):  # a client that keeps asking
            with pytest.raises(ua.uaerrors.BadTooManySubscriptions):
                await client.create_subscription(100, Changes())
        assert held(gateway) == Held(subscriptions=2)
        await first.delete()
        assert held(gateway) == Held(subscriptions=1)
        changes = Changes()
        third = await client.create_subscription(100, changes)  # the room the delete freed
        await third.subscribe_data_change(node(client, "m1", "Comm"))
        await changes.until(lambda: "online" in changes.values.get("m1.Comm", []))
        # another session has its own room
        async with Client(gateway.endpoint, timeout=TIMEOUT) as other:
            await other.create_subscription(100, Changes())
            await other.create_subscription(100, Changes())
    assert front_end(gateway).counted().refused == {"subscriptions": 6, "monitored_items": 0}
    # and in /metrics, as the web front end renders them
    text = generate_latest(
        make_registry(gateway.daemon.runtime, FeedCounters(), WebCounters())
    ).decode()
    assert 'drive_gateway_opcua_refused_total{reason="subscriptions"} 6.0' in text
    assert 'drive_gateway_opcua_sessions_total{result="accepted"} 2.0' in text
    assert "drive_gateway_opcua_sessions_open 0.0" in text
    # one line for the six refusals, and none of asyncua's per request
    ours = [r for r in caplog.records if r.name == "gateway.opcua.limits"]
    assert [r.getMessage() for r in ours] == [
        f"OPC UA session {only_session_id(ours)}: 1 subscriptions refused, the session holds "
        "its limit of 2 ([opcua] max_subscriptions)"
    ]
    asyncuas = [r.getMessage() for r in caplog.records if r.name == UAPROCESSOR_LOG]
    assert [m for m in asyncuas if "BadTooManySubscriptions" in m] == []


def only_session_id(records: list[logging.LogRecord]) -> str:
    """The session id in the one line of a refusal (the server chose it)."""
    (record,) = records
    assert isinstance(record.args, tuple)
    client = str(record.args[0])
    assert client.startswith("session ")
    return client.removeprefix("session ")


async def test_monitored_items_beyond_the_limit_are_refused_one_by_one(gateway: Gateway) -> None:
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        first = await client.create_subscription(100, Changes())
        handles = await first.subscribe_data_change(readings(client, "m1", READINGS[:3]))
        assert all(isinstance(h, int) for h in handles)
        changes = Changes()
        second = await client.create_subscription(100, changes)
        # 5 per session, over both its subscriptions: two of these four fit
        results = await second.subscribe_data_change(readings(client, "m2", READINGS[:4]))
        assert [isinstance(r, int) for r in results] == [True, True, False, False]
        assert [r.value for r in results[2:] if isinstance(r, ua.StatusCode)] == [
            ua.StatusCodes.BadTooManyMonitoredItems
        ] * 2
        # the items within the limit work: their values arrive
        await changes.until(lambda: {"m2.SpeedRpm", "m2.Running"} <= set(changes.values))
        assert set(changes.values) <= {"m2.SpeedRpm", "m2.Running"}
        assert held(gateway) == Held(subscriptions=2, monitored_items=5)
        with pytest.raises(ua.uaerrors.BadTooManyMonitoredItems):
            await first.subscribe_data_change(node(client, "m1", "Status"))
        # deleting an item frees its room
        await first.unsubscribe(handles[0])
        assert isinstance(await first.subscribe_data_change(node(client, "m1", "Status")), int)
        # deleting a subscription frees its items' room
        await second.delete()
        assert held(gateway) == Held(subscriptions=1, monitored_items=3)
        more = await first.subscribe_data_change(readings(client, "soft", READINGS[:2]))
        assert all(isinstance(h, int) for h in more)
        assert held(gateway) == Held(subscriptions=1, monitored_items=5)
    assert front_end(gateway).counted().refused == {"subscriptions": 0, "monitored_items": 3}


async def test_items_added_to_another_sessions_subscription_count_for_its_owner(
    gateway: Gateway,
) -> None:
    async with (
        Client(gateway.endpoint, timeout=TIMEOUT) as owner,
        Client(gateway.endpoint, timeout=TIMEOUT) as other,
    ):
        sub = await owner.create_subscription(100, Changes())
        await sub.subscribe_data_change(readings(owner, "m1", READINGS[:4]))
        requests = [
            ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(
                    NodeId=ua.NodeId(f"m2.{name}", 2), AttributeId=ua.AttributeIds.Value
                ),
                MonitoringMode=ua.MonitoringMode.Reporting,
                RequestedParameters=ua.MonitoringParameters(ClientHandle=900 + i, QueueSize=1),
            )
            for i, name in enumerate(READINGS[:3])
        ]
        params = ua.CreateMonitoredItemsParameters(
            SubscriptionId=sub.subscription_id, ItemsToCreate=requests
        )
        results = await other.uaclient.create_monitored_items(params)
        assert [r.StatusCode.value for r in results] == [
            ua.StatusCodes.Good,
            ua.StatusCodes.BadTooManyMonitoredItems,
            ua.StatusCodes.BadTooManyMonitoredItems,
        ]
        owner_id = service(gateway).subscriptions[sub.subscription_id].session_id
        assert held_by(service(gateway), owner_id) == Held(subscriptions=1, monitored_items=5)


async def test_a_closed_session_frees_what_it_held(gateway: Gateway) -> None:
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        for drive in ("m1", "m2"):
            sub = await client.create_subscription(100, Changes())
            await sub.subscribe_data_change(readings(client, drive, READINGS[:2]))
        session_id = only_session(gateway).session_id
        assert held_by(service(gateway), session_id) == Held(2, 4)
        with pytest.raises(ua.uaerrors.BadTooManySubscriptions):
            await client.create_subscription(100, Changes())
    assert held_by(service(gateway), session_id) == Held()
    assert service(gateway).subscriptions == {}
    async with Client(gateway.endpoint, timeout=TIMEOUT) as again:  # the next one: all its room
        sub = await again.create_subscription(100, Changes())
        handles = await sub.subscribe_data_change(readings(again, "m1", READINGS[:5]))
        assert all(isinstance(h, int) for h in handles)


async def test_a_session_closed_keeping_its_subscriptions_takes_them_with_it(
    gateway: Gateway,
) -> None:
    """CloseSession with DeleteSubscriptions false: they would be held by no session."""
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        sub = await client.create_subscription(100, Changes())
        await sub.subscribe_data_change(readings(client, "m1", READINGS[:3]))
        await client.uaclient.close_session(False)
        assert service(gateway).subscriptions == {}


async def test_a_publishing_interval_below_the_floor_is_revised_up(gateway: Gateway) -> None:
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        revised = {}
        for asked in (0.0, -1.0, 10.0, math.nan, 200.0):
            params = ua.CreateSubscriptionParameters(
                RequestedPublishingInterval=asked,
                RequestedLifetimeCount=1000,
                RequestedMaxKeepAliveCount=10,
            )
            result = await client.uaclient.create_subscription(params, callback=_ignore)
            revised[asked if not math.isnan(asked) else "nan"] = result.RevisedPublishingInterval
            await client.uaclient.delete_subscriptions([result.SubscriptionId])
        # the default floor, 0.05 s
        assert revised == {0.0: 50.0, -1.0: 50.0, 10.0: 50.0, "nan": 50.0, 200.0: 200.0}
        sub = await client.create_subscription(0, Changes())
        assert (
            service(gateway).subscriptions[sub.subscription_id].data.RevisedPublishingInterval
            == 50.0
        )
        handle = await sub.subscribe_data_change(node(client, "m1", "Comm"))
        (modified,) = await sub.modify_monitored_item(handle, 1.0)
        assert modified.RevisedSamplingInterval == 50.0


async def test_a_modified_queue_size_is_revised_as_at_creation(gateway: Gateway) -> None:
    """asyncua takes a modify's queue size as asked: 0 would be a queue without end."""
    async with Client(gateway.endpoint, timeout=TIMEOUT) as client:
        sub = await client.create_subscription(100, Changes())
        handle = await sub.subscribe_data_change(node(client, "m1", "Comm"))
        cap = 10_000  # asyncua's max_monitored_item_queue_size
        for asked, revised in ((0, cap), (2**32 - 1, cap), (5, 5)):
            (modified,) = await sub.modify_monitored_item(handle, 100.0, new_queuesize=asked)
            assert modified.RevisedQueueSize == revised


async def _ignore(*_args: object) -> None:
    return None


async def test_a_transfer_over_the_limit_is_refused(gateway: Gateway) -> None:
    async with (
        Client(gateway.endpoint, timeout=TIMEOUT) as owner,
        Client(gateway.endpoint, timeout=TIMEOUT) as taker,
    ):
        given = await owner.create_subscription(100, Changes())
        owner_id = service(gateway).subscriptions[given.subscription_id].session_id
        await taker.create_subscription(100, Changes())
        kept = await taker.create_subscription(100, Changes())
        taker_id = service(gateway).subscriptions[kept.subscription_id].session_id
        params = ua.TransferSubscriptionsParameters(SubscriptionIds=[given.subscription_id])
        (result,) = await taker.uaclient.transfer_subscriptions(params)
        assert result.StatusCode.value == ua.StatusCodes.BadTooManySubscriptions
        assert service(gateway).subscriptions[given.subscription_id].session_id == owner_id
        # within the limit, it moves
        await kept.delete()
        (result,) = await taker.uaclient.transfer_subscriptions(params)
        assert result.StatusCode.is_good()
        assert service(gateway).subscriptions[given.subscription_id].session_id == taker_id
        assert held_by(service(gateway), taker_id) == Held(subscriptions=2)
    assert front_end(gateway).counted().refused["subscriptions"] == 1


# ------------------------------------------------------------------ the parts on their own


@pytest.mark.parametrize(
    ("asked", "revised"),
    [
        (0.0, 50.0),
        (-1.0, 50.0),
        (49.9, 50.0),
        (50.0, 50.0),
        (1000.0, 1000.0),
        (math.nan, 50.0),
        (math.inf, 3_600_000.0),
        (1e12, 3_600_000.0),
    ],
)
def test_the_publishing_interval_a_subscription_gets(asked: float, revised: float) -> None:
    assert SessionLimits(20, 10_000, 0.05).publishing_interval(asked) == revised


@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(0.01, 60.0))
def test_a_revised_publishing_interval_is_never_below_the_floor(asked: float, floor: float) -> None:
    revised = SessionLimits(1, 1, floor).publishing_interval(asked)
    assert floor * 1000.0 <= revised <= 3_600_000.0
    if floor * 1000.0 <= asked <= 3_600_000.0:
        assert revised == asked


def test_asyncuas_bound_on_the_whole_server_never_speaks_before_a_sessions_limit() -> None:
    assert server_wide_subscriptions(32, SessionLimits(20, 10_000, 0.05)) == 1_000
    assert server_wide_subscriptions(100, SessionLimits(20, 10_000, 0.05)) == 2_000


def test_refusals_are_counted_each_and_logged_once_per_period_per_session(
    caplog: pytest.LogCaptureFixture,
) -> None:
    now = [0.0]
    refusals = Refusals(clock=lambda: now[0], period=10.0)
    with caplog.at_level(logging.WARNING, logger="gateway.opcua.limits"):
        for _ in range(50):
            refusals.refuse("session 1", Limit.SUBSCRIPTIONS, 1, 20)
        refusals.refuse("session 1", Limit.MONITORED_ITEMS, 7, 10_000)
        refusals.refuse("session 2", Limit.SUBSCRIPTIONS, 1, 20)
        now[0] = 10.0
        refusals.refuse("session 1", Limit.SUBSCRIPTIONS, 1, 20)
    assert refusals.by_reason() == {"subscriptions": 52, "monitored_items": 7}
    assert [r.getMessage() for r in caplog.records] == [
        "OPC UA session 1: 1 subscriptions refused, the session holds its limit of 20 "
        "([opcua] max_subscriptions)",
        "OPC UA session 1: 7 monitored items refused, the session holds its limit of 10000 "
        "([opcua] max_monitored_items)",
        "OPC UA session 2: 1 subscriptions refused, the session holds its limit of 20 "
        "([opcua] max_subscriptions)",
        "OPC UA session 1: 1 subscriptions refused, the session holds its limit of 20 "
        "([opcua] max_subscriptions) (49 more refused since the last line)",
    ]


def test_only_asyncuas_line_of_an_own_refusal_is_dropped() -> None:
    def record(msg: str, *args: object) -> logging.LogRecord:
        return logging.LogRecord(UAPROCESSOR_LOG, logging.ERROR, "", 0, msg, args, None)

    fault = "sending service fault response: %s (%s)"
    lines = OwnRefusalLines()
    assert not lines.filter(record(fault, "too many", "BadTooManySubscriptions"))
    assert lines.filter(record(fault, "no session", "BadSessionIdInvalid"))
    assert lines.filter(record("Error while processing message"))


def test_the_monitored_items_of_a_subscription_are_read_where_asyncua_keeps_them() -> None:
    """The one private read of asyncua (gateway/opcua/limits.py): it fails here when an
    asyncua release moves the items of a subscription."""
    sub = InternalSubscription(
        ua.CreateSubscriptionResult(SubscriptionId=1), AddressSpace(), _ignore, ua.NodeId(1)
    )
    assert monitored_items_in(sub) == 0
    assert isinstance(sub.monitored_item_srv._monitored_items, dict)
