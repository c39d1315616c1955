"""The steady poll on a simulated line (docs/decisions/0097): the adapter, the CFW-08 profile
and the hub see a quiet node's inputs about every ``INPUTS_REFRESH``, not on every poll, and a command
reaches the node's outputs within its next polls all the same.

Two simulated CFW-08s on python-can ``virtual``, the adapter on the test's loop with the hub.
"""

from __future__ import annotations

import asyncio
import contextlib
import uuid
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

from adapters.devicenet import adapter as adapter_module
from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.scanner import InputData, machine
from adapters.devicenet.scanner import engine as scanner_engine
from adapters.devicenet.sim import SimRunner
from gateway.config import parse
from gateway.hub import Hub
from gateway.model import DriveCommand, Source
from gateway.runtime.daemon import build_hub
from tests.support import simulated
from tests.support.timing import scaled

LIMIT = 20.0  # s, times the machine's time scale: a bound, never a wait
POLL = 0.005  # s: the poll interval
DRIVES: list[dict[str, Any]] = [
    {"id": "a", "address": 3, "device": "CFW-08", "max_rpm": 1800, "sim_ramp_time": 0.1},
    {"id": "b", "address": 4, "device": "CFW-08", "max_rpm": 1800, "sim_ramp_time": 0.1},
]


@contextlib.asynccontextmanager
async def line() -> AsyncIterator[tuple[Hub, DeviceNetAdapter, SimRunner]]:
    table = {
        "adapter": "devicenet",
        "simulate": True,
        "interface": "virtual",
        "channel": f"steady-{uuid.uuid4().hex[:8]}",
        "poll_interval": POLL,
        "expected_packet_rate": scaled(0.2),
        "response_timeout": scaled(0.05),
        "explicit_timeout": scaled(0.2),
        "dupmac_timeout": 0.05,
        "status_interval": 60.0,
        "drives": DRIVES,
    }
    config = parse({"buses": {"dn": table}}, "steady-lane.toml")
    hub = build_hub(config)
    adapter = simulated.devicenet(config.buses[0])
    task = asyncio.create_task(adapter.run(hub))
    try:
        for d in DRIVES:
            await hub.wait_for(str(d["id"]), lambda s: s.online)
        runner = simulated.sim_runner(adapter)
        assert runner is not None
        yield hub, adapter, runner
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def _counting(adapter: DeviceNetAdapter) -> list[int]:
    """The InputData the scanner hands the adapter, by MAC."""
    handled: list[int] = []
    original = adapter._handlers[InputData]

    def on_input(now: float, action: InputData) -> None:
        handled.append(action.mac)
        original(now, action)

    adapter._handlers[InputData] = on_input
    return handled


def _polls(adapter: DeviceNetAdapter, mac: int) -> int:
    engine = adapter.engine
    assert engine is not None
    return engine.nodes[mac].figures.rtt_count


async def _until(runner: SimRunner, predicate: Callable[[], bool]) -> None:
    """Until ``predicate`` holds, checked after each pass of the simulated nodes."""
    await runner.until(predicate)


async def test_at_rest_the_adapter_sees_a_node_about_every_refresh() -> None:
    async with line() as (_hub, adapter, runner), asyncio.timeout(scaled(LIMIT)):
        await _until(runner, lambda: all(adapter.engine.nodes[m].quiet for m in (3, 4)))  # type: ignore[union-attr]
        handled = _counting(adapter)
        first = _polls(adapter, 3)
        await _until(runner, lambda: _polls(adapter, 3) >= first + 200 and handled.count(3) >= 2)
        polls = _polls(adapter, 3) - first
        # every poll answered the same: the adapter is handed node 3's inputs only every
        # INPUTS_REFRESH s (a poll every POLL s at best), the lane takes the rest
        assert handled.count(3) < polls / 4, (handled.count(3), polls)
        assert handled.count(3) >= 1


class Rest:
    """When node 3's inputs last changed, as the adapter is handed them."""

    def __init__(self, adapter: DeviceNetAdapter) -> None:
        self.changed = 0.0
        self.last: bytes | None = None
        original = adapter._handlers[InputData]

        def on_input(now: float, action: InputData) -> None:
            if action.mac == 3 and action.data != self.last:
                self.last, self.changed = action.data, asyncio.get_running_loop().time()
            original(now, action)

        adapter._handlers[InputData] = on_input

    def at_rest(self, quiet: bool) -> bool:
        """Quiet, and the inputs unchanged for a while (REST s: the next refresh of the
        inputs and of the outputs, every REFRESH s, far off)."""
        return quiet and asyncio.get_running_loop().time() > self.changed + REST


REFRESH = 2.0  # s: the refreshes of a quiet node, far apart (hundreds of polls)
REST = 0.2  # s


async def test_a_run_and_a_stop_reach_a_quiet_node_within_its_next_polls(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Only the command's own way to the outputs (the hub's ``on_command``) can bring it
    to the node within a few polls: the refreshes are seconds apart here."""
    monkeypatch.setattr(adapter_module, "INPUTS_REFRESH", REFRESH)
    monkeypatch.setattr(machine, "INPUTS_REFRESH", REFRESH)
    monkeypatch.setattr(scanner_engine, "INPUTS_REFRESH", REFRESH)
    async with line() as (hub, adapter, runner), asyncio.timeout(scaled(LIMIT) + 8 * REFRESH):
        engine = adapter.engine
        assert engine is not None
        node = engine.nodes[3]
        drive = runner.node(3).drive
        rest = Rest(adapter)
        for _ in range(2):
            await _until(runner, lambda: rest.at_rest(node.quiet))
            before = _polls(adapter, 3)
            hub.submit("a", Source.ZENOH, DriveCommand(run=True, speed_rpm=600.0))
            await _until(runner, lambda: drive.run_fwd)
            # the run went out within the next few polls, not at the next refresh
            assert _polls(adapter, 3) - before <= 3
            await _until(runner, lambda: rest.at_rest(node.quiet))  # at speed, quiet again
            before = _polls(adapter, 3)
            hub.submit("a", Source.ZENOH, DriveCommand(run=False))
            await _until(runner, lambda: not drive.run_fwd)
            assert _polls(adapter, 3) - before <= 3
