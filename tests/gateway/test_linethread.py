"""A line on a thread and loop of its own (gateway/runtime/linethread.py): nothing on the
daemon's loop holds it up, its readings reach the hub in order, a stop leaves the bus on the
line's own loop, and what the adapter raises reaches the supervisor."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import pytest

from gateway.adapter import Capabilities, EventKind, HubPort, ParamValue
from gateway.errors import DriveOffline, LineHeld
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveState
from gateway.runtime.lineport import OUTBOX_EVENTS
from gateway.runtime.linethread import LineThread
from tests.support.timing import scaled


class StepAdapter:
    """A line that steps every millisecond on its own loop and reports each step."""

    name = "line"

    def __init__(self, fail: BaseException | None = None) -> None:
        self.fail = fail
        self.steps = 0
        self.threads: set[str] = set()
        self.left_on: str | None = None
        self.claimed = asyncio.Event()
        self.running = asyncio.Event()  # the test's, set from the line's thread
        self.test_loop = asyncio.get_running_loop()

    async def run(self, hub: HubPort) -> None:
        self.threads.add(threading.current_thread().name)
        if self.fail is not None:
            raise self.fail
        hub.set_capabilities("d", Capabilities(alarm_texts={1: "one"}))
        hub.update("d", comm=CommState.ONLINE)
        hub.event("d", EventKind.BUS, "line up")
        self.claimed.set()
        try:
            while True:
                self.steps += 1
                hub.update("d", speed_rpm=float(self.steps))
                if self.steps == 1:
                    self.test_loop.call_soon_threadsafe(self.running.set)
                await asyncio.sleep(0.001)
        finally:
            self.left_on = threading.current_thread().name
            hub.update("d", comm=CommState.OFFLINE)

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        self.threads.add(threading.current_thread().name)
        await asyncio.sleep(0)
        return number * 2

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        raise NotImplementedError

    def diagnostics(self) -> dict[str, Any]:
        return {"steps": self.steps, "drives": {}}


def make_hub() -> Hub:
    hub = Hub()
    hub.add_drive(DriveState(id="d", device=Device.CFW11, bus="line", address=1))
    return hub


async def wait_running(adapter: StepAdapter) -> None:
    await asyncio.wait_for(adapter.running.wait(), scaled(10.0))


async def test_the_line_keeps_stepping_while_the_daemons_loop_stands_still() -> None:
    hub, adapter = make_hub(), StepAdapter()
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    await wait_running(adapter)
    before = adapter.steps
    time.sleep(scaled(0.3))  # noqa: ASYNC251 - the daemon's loop held up, on purpose
    during = adapter.steps - before
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert during > 0, "the line stood still while the daemon's loop was held up"
    assert adapter.threads == {"line-line"} and adapter.left_on == "line-line"


async def test_readings_events_and_capabilities_reach_the_hub_in_order() -> None:
    hub, adapter = make_hub(), StepAdapter()
    line = LineThread(adapter, hub)
    with hub.subscribe_events() as events:
        task = asyncio.create_task(line.run())
        state = await asyncio.wait_for(
            hub.wait_for("d", lambda s: (s.speed_rpm or 0) > 5), scaled(10.0)
        )
        assert state.online and hub.capabilities("d").alarm_texts == {1: "one"}
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        kinds = [(e.kind, e.text) for e in events.drain()]
    # the comm event the hub raises comes before the line's own event, as the line said them
    assert kinds.index((EventKind.COMM, "comm offline -> online")) < kinds.index(
        (EventKind.BUS, "line up")
    )
    assert not hub.state("d").online, "what the line said while leaving reached the hub"
    assert line.port is not None and line.port.waiting == 0


async def test_a_stop_leaves_the_bus_on_the_lines_loop_and_ends_its_thread() -> None:
    hub, adapter = make_hub(), StepAdapter()
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    await wait_running(adapter)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert adapter.left_on == "line-line"
    assert line.thread is not None
    line.thread.join(scaled(5.0))
    assert not line.thread.is_alive()


async def test_a_stop_before_the_line_started_still_ends_it() -> None:
    hub, adapter = make_hub(), StepAdapter()
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    await asyncio.sleep(0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert line.thread is not None
    line.thread.join(scaled(5.0))
    assert not line.thread.is_alive()


async def test_what_the_adapter_raises_reaches_the_supervisor() -> None:
    hub = make_hub()
    line = LineThread(StepAdapter(fail=LineHeld("another master holds the line")), hub)
    with pytest.raises(LineHeld, match="another master"):
        await line.run()


async def test_parameters_claimed_and_figures_come_from_the_line() -> None:
    hub, adapter = make_hub(), StepAdapter()
    line = LineThread(adapter, hub)
    with pytest.raises(DriveOffline, match="not running"):
        await line.read_param("d", 100, 0)
    task = asyncio.create_task(line.run())
    await asyncio.wait_for(line.claimed.wait(), scaled(10.0))
    assert await line.read_param("d", 100, 0) == 200
    assert await line.call(lambda: threading.current_thread().name) == "line-line"
    await wait_running(adapter)
    built = await asyncio.wait_for(line.next_diagnostics(), scaled(10.0))
    assert built["steps"] >= 1
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert adapter.threads == {"line-line"}
    with pytest.raises(DriveOffline):
        await line.read_param("d", 100, 0)


class SlowParams(StepAdapter):
    def __init__(self) -> None:
        super().__init__()
        self.asked = asyncio.Event()  # the test's, set from the line's thread

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        self.test_loop.call_soon_threadsafe(self.asked.set)
        await asyncio.Event().wait()  # a drive that never answers
        return 0


async def test_a_request_under_way_when_the_line_stops_is_answered() -> None:
    hub, adapter = make_hub(), SlowParams()
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    await wait_running(adapter)
    request = asyncio.create_task(line.read_param("d", 100, 0))
    await asyncio.wait_for(adapter.asked.wait(), scaled(10.0))  # under way on the line
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    with pytest.raises(DriveOffline, match="stopped during the request"):
        await asyncio.wait_for(request, scaled(5.0))


class EventFlood(StepAdapter):
    """A line that says ``count`` identical events at once when its test asks."""

    def __init__(self, count: int) -> None:
        super().__init__()
        self.count = count
        self.flood = threading.Event()  # set by the test
        self.flooded = threading.Event()  # set by the line once every event is said

    async def run(self, hub: HubPort) -> None:
        self.hub = hub
        await super().run(hub)

    def diagnostics(self) -> dict[str, Any]:
        if self.flood.is_set() and not self.flooded.is_set():
            for _ in range(self.count):
                self.hub.event("d", EventKind.BUS, "the same again")
            self.flooded.set()
        return super().diagnostics()


async def test_events_the_outbox_drops_are_in_the_lines_figures() -> None:
    hub, adapter = make_hub(), EventFlood(OUTBOX_EVENTS + 100)
    line = LineThread(adapter, hub)
    task = asyncio.create_task(line.run())
    await wait_running(adapter)  # "line up" applied: the flush before it ran first
    first = await asyncio.wait_for(line.next_diagnostics(), scaled(10.0))
    assert first["events_dropped"] == 0
    adapter.flood.set()
    # the daemon's loop held up until the line has said them all: none is applied meanwhile
    assert adapter.flooded.wait(scaled(10.0))
    built = await asyncio.wait_for(line.next_diagnostics(), scaled(10.0))
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert built["events_dropped"] == 100
    assert built["steps"] >= 1  # the adapter's own figures beside it
    assert hub.events_folded == OUTBOX_EVENTS - 1  # those applied: one told, the rest folded
