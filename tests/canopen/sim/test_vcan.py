"""``drive-gateway sim canopen`` as a process of its own on SocketCAN vcan0, against the
canopen library's client and against the gateway's CANopen adapter in this process: two
processes on one kernel bus, which ``virtual`` cannot give. Marked ``vcan``: ``make
test-vcan`` runs them (tests/vcan_vm)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from adapters.canopen.codec.cia402 import State, decode_state
from gateway.model import CommState, DriveCommand
from tests.canopen.integration.conftest import FAST_BUS, drive
from tests.canopen.sim.conftest import Client
from tests.canopen.sim.test_adapter import Z, online, rig
from tests.support.timing import scaled

pytestmark = pytest.mark.vcan

VCAN = "vcan0"
SIM_STOP_BOUND = 10.0  # s: the simulator process ends on SIGTERM within this (scaled)


def vcan_problem() -> str | None:
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return f"the kernel has no AF_CAN ({exc.strerror})"
    if not Path(f"/sys/class/net/{VCAN}").exists():
        return f"no {VCAN} interface (sudo ip link add dev {VCAN} type vcan)"
    return None


@pytest.fixture
async def vcan_client() -> AsyncIterator[Client]:
    problem = vcan_problem()
    if problem is not None:
        pytest.skip(problem)
    client = Client(VCAN, interface="socketcan")
    try:
        yield client
    finally:
        client.close()


@contextlib.asynccontextmanager
async def sim_process(*extra: str) -> AsyncIterator[asyncio.subprocess.Process]:
    """``drive-gateway sim canopen`` on vcan0 in a process of its own; ended with SIGTERM."""
    argv = ["-m", "gateway", "sim", "canopen", "--interface", "socketcan", "--channel", VCAN,
            "--log-level", "WARNING", *extra]  # fmt: skip
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


def booted(c: Client, node_id: int) -> Callable[[], bool]:
    def check() -> bool:
        beats = c.seen(0x700 + node_id)
        return beats[:1] == [b"\x00"] and b"\x7f" in beats

    return check


async def test_the_simulator_process_answers_the_canopen_client(vcan_client: Client) -> None:
    c = vcan_client
    args = ("--node", "21", "--node", "22", "--heartbeat-ms", "50", "--ramp-time", "0.3")
    async with sim_process(*args) as proc:
        for node_id in (21, 22):  # boot-up, then heartbeats in pre-operational
            await c.until(booted(c, node_id), seconds=15.0)
        node = c.remote(21)
        node.sdo.RESPONSE_TIMEOUT = scaled(1.0)
        assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192
        assert await c.call(lambda: node.sdo[0x1008].raw) == "CiA402 test drive"  # segmented
        node.nmt.send_command(0x01)
        await c.until(lambda: c.seen(0x715)[-1:] == [b"\x05"])
        await c.until(lambda: len(c.seen(0x195)) >= 1)  # TPDO1, event timer
        for word, rpm in ((0x06, 0), (0x07, 0), (0x7F, 600)):
            c.send(0x215, struct.pack("<Hh", word, rpm))

        def tpdo() -> tuple[int, int]:
            status, rpm = struct.unpack("<Hh", c.seen(0x195)[-1])
            return status, rpm

        await c.until(lambda: decode_state(tpdo()[0]) is State.OPERATION_ENABLED)
        await c.until(lambda: tpdo()[1] == 600, seconds=5.0)
        assert c.seen(0x196) == []  # node 22 stays pre-operational: no PDO
        proc.terminate()
        assert await asyncio.wait_for(proc.wait(), scaled(SIM_STOP_BOUND)) == 0


async def test_the_adapter_and_a_simulator_process_share_vcan0() -> None:
    """The gateway's adapter brings up a node of another process, runs and stops it, and
    takes it offline when that process ends (timings scaled: tests/support/timing.py)."""
    problem = vcan_problem()
    if problem is not None:
        pytest.skip(problem)
    async with (
        sim_process("--node", "31", "--ramp-time", "0.3") as proc,
        rig([drive(31)], interface="socketcan", channel=VCAN, bus=FAST_BUS) as r,
    ):
        await r.wait("d31", online, within=15.0)
        r.hub.submit("d31", Z, DriveCommand(run=True, speed_rpm=900.0))
        await r.wait("d31", lambda s: s.running and s.speed_rpm == 900.0)
        r.hub.submit("d31", Z, DriveCommand(run=False))
        await r.wait("d31", lambda s: not s.running and s.speed_rpm == 0.0)
        proc.terminate()
        assert await asyncio.wait_for(proc.wait(), scaled(SIM_STOP_BOUND)) == 0
        await r.wait("d31", lambda s: s.comm is CommState.OFFLINE, within=10.0)
