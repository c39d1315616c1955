"""The DeviceNet integration rig: the adapter (scanner + link) and simulated CFW-08s on a
python-can bus, with the real hub. Every test runs on ``virtual`` (a channel of its own)
and again on SocketCAN ``vcan0`` under the ``vcan`` marker where the kernel has one."""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import socket
import subprocess
import sys
import uuid
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.link import LinkConfig
from adapters.devicenet.sim import SimNodeConfig, SimPhase, SimRunner
from adapters.devicenet.sim.simulated import sim_configs
from gateway.adapter import Event
from gateway.config import parse
from gateway.hub import EventSubscription, Hub
from gateway.model import DriveState
from gateway.runtime.daemon import build_hub
from tests.support.timing import scaled

VCAN = "vcan0"
SIM_STOP_BOUND = 10.0  # s: a simulator process ends on SIGTERM within this (scaled)
# The rig's line timing; on a slow machine (the vcan VM) every timer grows with the suite's
# time scale, so that the protocol's timeouts keep their meaning (tests/support/timing.py).
FAST_BUS: dict[str, Any] = {
    key: scaled(seconds)
    for key, seconds in {
        "poll_interval": 0.01,
        "expected_packet_rate": 0.05,
        "response_timeout": 0.05,
        "explicit_timeout": 0.2,
        "explicit_epr": 2.5,  # 63 nodes' keep-alives filled the VM's explicit window at 2.5 s
        "dupmac_timeout": 0.05,
        "retry_max": 0.3,
        "status_interval": 0.2,
    }.items()
}
# the EPR attribute is 16-bit ms (fact sheet 2.9): a time scale over 26 would pass it
FAST_BUS["explicit_epr"] = min(FAST_BUS["explicit_epr"], 65.0)
EPR: float = FAST_BUS["expected_packet_rate"]
DUPMAC: float = FAST_BUS["dupmac_timeout"]


def vcan_problem() -> str | None:
    """Why the vcan tests cannot run here, or None when they can."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return f"the kernel has no AF_CAN ({exc.strerror})"
    if not Path(f"/sys/class/net/{VCAN}").exists():
        return f"no {VCAN} interface (sudo ip link add dev {VCAN} type vcan)"
    return None


def vcan_admin_problem() -> str | None:
    """Why a test cannot change vcan0 (down/up, its queue), or None when it can."""
    problem = vcan_problem()
    if problem is not None:
        return problem
    if os.geteuid() != 0:
        return f"not root: cannot set {VCAN} down/up or change its queue"
    for tool in ("ip", "tc"):
        if shutil.which(tool) is None:
            return f"no `{tool}` command (iproute2)"
    return None


def admin(*args: str) -> None:
    """An ``ip``/``tc`` command on the test interface; it must succeed."""
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    assert done.returncode == 0, f"{' '.join(args)}: {done.stderr.strip()}"


async def aadmin(*args: str) -> None:
    """:func:`admin` without blocking the event loop (the gateway keeps running meanwhile)."""
    proc = await asyncio.create_subprocess_exec(
        *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    _, err = await proc.communicate()
    assert proc.returncode == 0, f"{' '.join(args)}: {err.decode().strip()}"


@pytest.fixture
def vcan_line() -> LinkConfig:
    """SocketCAN vcan0 only (tests that ``virtual`` can never give); mark them ``vcan``."""
    problem = vcan_problem()
    if problem is not None:
        pytest.skip(problem)
    return LinkConfig("socketcan", VCAN)


@pytest.fixture
def vcan_admin(vcan_line: LinkConfig) -> Iterator[LinkConfig]:
    """vcan0 that the test may take down and throttle; left up, queue removed."""
    problem = vcan_admin_problem()
    if problem is not None:
        pytest.skip(problem)
    try:
        yield vcan_line
    finally:
        subprocess.run(
            ["tc", "qdisc", "del", "dev", VCAN, "root"], capture_output=True, check=False
        )
        admin("ip", "link", "set", "up", VCAN)


@pytest.fixture(params=["virtual", pytest.param("vcan", marks=pytest.mark.vcan)])
def can_line(request: pytest.FixtureRequest) -> LinkConfig:
    if request.param == "vcan":
        problem = vcan_problem()
        if problem is not None:
            pytest.skip(problem)
        return LinkConfig("socketcan", VCAN)
    return LinkConfig("virtual", f"dn-{uuid.uuid4().hex[:10]}")


def drive(mac: int, **keys: Any) -> dict[str, Any]:
    return {
        "id": f"d{mac}",
        "device": "CFW-08",
        "address": mac,
        "max_rpm": 1800.0,
        "sim_ramp_time": 0.2,
        **keys,
    }


@dataclass
class Rig:
    hub: Hub
    adapter: DeviceNetAdapter
    sim: SimRunner
    events: EventSubscription
    task: asyncio.Task[None]
    seen: list[Event] = field(default_factory=list)

    async def wait(
        self, drive_id: str, predicate: Callable[[DriveState], bool], within: float = 5.0
    ) -> DriveState:
        return await asyncio.wait_for(self.hub.wait_for(drive_id, predicate), scaled(within))

    async def until(
        self, predicate: Callable[[], bool], within: float = 5.0, runner: SimRunner | None = None
    ) -> None:
        """Wait for a condition on the simulated line (checked as the simulator works).

        Every wait here is ``within`` seconds times the suite's time scale (tests/support/timing.py)."""
        await asyncio.wait_for((runner or self.sim).until(predicate), scaled(within))

    async def event(self, predicate: Callable[[Event], bool], within: float = 5.0) -> Event:
        async def find() -> Event:
            while True:
                ev = await self.events.get()
                self.seen.append(ev)
                if predicate(ev):
                    return ev

        for ev in self.seen:
            if predicate(ev):
                return ev
        return await asyncio.wait_for(find(), scaled(within))


@contextlib.asynccontextmanager
async def rig(
    line: LinkConfig,
    drives: list[dict[str, Any]],
    *,
    bus: dict[str, Any] | None = None,
    sims: list[SimNodeConfig] | None = None,
    prepare: Callable[[SimRunner], None] | None = None,
    settle: bool = False,
) -> AsyncIterator[Rig]:
    table = {
        "adapter": "devicenet",
        "interface": line.interface,
        "channel": line.channel,
        **FAST_BUS,
        **(bus or {}),
        "drives": drives,
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"dn": table}},
        "test.toml",
    )
    hub = build_hub(config)
    adapter = DeviceNetAdapter(config.buses[0])
    hub.attach_params([d["id"] for d in drives], adapter)
    runner = SimRunner(line, sim_configs(config.buses[0]) if sims is None else sims)
    sim_task = asyncio.create_task(runner.run(), name="sim")
    await asyncio.wait_for(runner.started.wait(), scaled(5))
    if settle:  # the simulated nodes finish their Duplicate MAC ID check first
        checking = SimPhase.CHECKING
        await runner.until(lambda: all(n.phase is not checking for n in runner.nodes.values()))
    if prepare is not None:
        prepare(runner)
    with hub.subscribe_events() as events:
        task = asyncio.create_task(adapter.run(hub), name="adapter")
        try:
            yield Rig(hub, adapter, runner, events, task)
        finally:
            for t in (task, sim_task):
                t.cancel()
            await asyncio.gather(task, sim_task, return_exceptions=True)


@contextlib.asynccontextmanager
async def sim_process(macs: str, *extra: str) -> AsyncIterator[asyncio.subprocess.Process]:
    """``drive-gateway sim devicenet`` on vcan0 in a process of its own; ended with SIGTERM."""
    argv = ["-m", "gateway", "sim", "devicenet", "--interface", "socketcan", "--channel", VCAN,
            "--nodes", macs, "--log-level", "WARNING", *extra]  # fmt: skip
    proc = await asyncio.create_subprocess_exec(sys.executable, *argv)
    try:
        yield proc
    finally:
        if proc.returncode is None:
            proc.terminate()
        try:
            await asyncio.wait_for(proc.wait(), scaled(SIM_STOP_BOUND))
        except TimeoutError:
            proc.kill()
            await proc.wait()
            raise
