"""End to end: the daemon in-process with a simulated CFW-08 on a python-can ``virtual``
DeviceNet line (``simulate = true``), commanded and read through Zenoh and Modbus TCP."""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import pytest_asyncio

from adapters.devicenet.cfw08 import AssemblyPair
from adapters.devicenet.sim import Cfw08Node, SimRunner
from gateway.config import DEFAULT_CONFIG, load
from gateway.model import CommState, Device
from tests.e2e.harness import PREFIX, RESET, REVERSE, RUN, TIMEOUT, Gateway, parsed, running_gateway
from tests.support import simulated

UNIT = 5
MAC = 5
EPR = 0.05
POLL = 0.01


def buses(channel: str, assembly: int = 21, extra: str = "") -> str:
    return f"""
[buses.dn]
adapter = "devicenet"
interface = "virtual"
channel = "{channel}"
simulate = true
poll_interval = {POLL}
expected_packet_rate = {EPR}
response_timeout = 0.05
explicit_timeout = 0.3
dupmac_timeout = 0.05
retry_max = 0.3
[[buses.dn.drives]]
id = "cfw08"
device = "CFW-08"
address = {MAC}
modbus_unit = {UNIT}
assembly = {assembly}
max_rpm = 1800
writable_params = [100, 313]
sim_ramp_time = 0.3
{extra}"""


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    channel = f"e2e-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: buses(channel), ["cfw08"]) as gw:
        yield gw


def sim(gateway: Gateway) -> SimRunner:
    runner = simulated.sim_runner(gateway.adapter("dn"))
    assert runner is not None
    return runner


def state_key() -> str:
    return f"{PREFIX}/drives/cfw08/state"


async def test_run_speed_reverse_stop_and_fault_reset_by_zenoh(gateway: Gateway) -> None:
    with gateway.client.subscribe(state_key()) as states:
        await gateway.client.settled(PREFIX)
        await gateway.command("cfw08", {"run": True, "speed_rpm": 900})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT))
        assert s.at_reference and (s.speed_rpm, s.speed_ref_rpm, s.status.label) == (
            900.0,
            900.0,
            "running",
        )
        # the speed word is whole rpm (round): a reported 900 means within 0.5 rpm of it
        assert sim(gateway).node(MAC).drive.motor.speed == pytest.approx(900.0, abs=0.5)
        await gateway.command("cfw08", {"direction": "reverse"})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == -900.0, TIMEOUT))
        assert s.direction.value == "reverse" and s.at_reference
        await gateway.command("cfw08", {"run": False})
        s = parsed(await states.auntil(lambda g: not parsed(g).running, TIMEOUT))
        assert s.status.label == "ready"
        with gateway.client.subscribe(f"{PREFIX}/drives/cfw08/events") as events:
            await gateway.client.settled(PREFIX)
            node = sim(gateway).node(MAC)
            await gateway.on_line("dn", lambda: node.inject_fault(6))
            await states.auntil(lambda g: parsed(g).status.label == "faulted", TIMEOUT)
            await gateway.command("cfw08", {"fault_reset": True})
            await events.auntil(lambda e: "fault reset sent" in e.json()["text"], TIMEOUT)
            await events.auntil(lambda e: "after a fault reset" in e.json()["text"], TIMEOUT)
        s = parsed(
            await states.auntil(lambda g: parsed(g).online and not parsed(g).faulted, TIMEOUT)
        )
        assert not s.running and s.status.label == "ready"


async def test_run_speed_reverse_stop_and_fault_reset_by_modbus(gateway: Gateway) -> None:
    await gateway.write(UNIT, 1, 600)  # speed_ref_rpm
    await gateway.write(UNIT, 0, 0)  # a new client's first word never starts a drive: 0, then run
    await gateway.write(UNIT, 0, RUN)
    s = await gateway.wait_for("cfw08", lambda s: s.speed_rpm == 600.0)
    assert s.at_reference
    regs = await gateway.inputs(UNIT)
    assert regs[0] & 0b10111 == 0b10111  # online, ready, running, at reference
    assert (regs[2], regs[19], regs[20]) == (600, 4, MAC)  # speed, CFW-08, MAC
    await gateway.write(UNIT, 0, RUN | REVERSE)
    await gateway.wait_for("cfw08", lambda s: s.speed_rpm == -600.0)
    regs = await gateway.inputs(UNIT)
    assert regs[0] & 0b1000 and regs[2] == (-600) & 0xFFFF
    await gateway.write(UNIT, 0, 0)
    await gateway.wait_for("cfw08", lambda s: s.speed_rpm == 0.0)
    node = sim(gateway).node(MAC)
    await gateway.on_line("dn", lambda: node.inject_fault(6))
    await gateway.wait_for("cfw08", lambda s: s.faulted)
    assert (await gateway.inputs(UNIT))[0] & 0b100000  # faulted bit
    await gateway.write(UNIT, 0, RESET)
    await gateway.wait_for("cfw08", lambda s: not s.online)
    s = await gateway.wait_for("cfw08", lambda s: s.online)
    assert not s.faulted and not s.running


async def test_parameters_through_zenoh(gateway: Gateway) -> None:
    c = gateway.client
    key = f"{PREFIX}/drives/cfw08/params"
    read = await c.aone(f"{key}/100")
    assert read.ok and read.json()["value"] == 3  # sim_ramp_time 0.3 s -> P100 = 3 (0.1 s)
    written = await c.aone(f"{key}/100", {"value": 12})
    assert written.ok, written.json()
    assert (await c.aone(f"{key}/100")).json()["value"] == 12
    assert sim(gateway).node(MAC).drive.params[100] == 12
    refused = await c.aone(f"{key}/313", {"value": 9})  # P313 is 0-3
    assert not refused.ok
    assert refused.json() == {"error": "Invalid attribute value", "code": 9}
    not_allowed = await c.aone(f"{key}/710", {"value": 0})
    assert not not_allowed.ok and "writable_params" in not_allowed.json()["error"]
    missing = await c.aone(f"{key}/99")
    assert missing.json() == {"error": "Attribute not supported", "code": 0x14}


async def test_a_stopped_node_goes_offline_and_comes_back_stopped(gateway: Gateway) -> None:
    with gateway.client.subscribe(state_key()) as states:
        await gateway.client.settled(PREFIX)
        await gateway.command("cfw08", {"run": True, "speed_rpm": 300})
        await states.auntil(lambda g: parsed(g).running, TIMEOUT)
        stopped_at = time.monotonic()
        runner = sim(gateway)
        await gateway.on_line("dn", lambda: runner.power_off(MAC))
        offline = await states.auntil(lambda g: parsed(g).comm is CommState.OFFLINE, TIMEOUT)
        # not before 4 x EPR without data (the last poll may have been answered just
        # before the power went); how late is a benchmark matter, bounded by the wait
        assert offline.at - stopped_at >= 4 * EPR - 2 * POLL
        await gateway.on_line("dn", lambda: runner.power_on(MAC))
        back = parsed(await states.auntil(lambda g: parsed(g).online, TIMEOUT))
        assert not back.running and back.status.label == "ready"
        assert not gateway.daemon.hub.desired("cfw08").run  # a new run command is needed


def demo_devicenet(channel: str) -> str:
    """The demo's DeviceNet line verbatim (config/demo.toml), on a channel of its own."""
    text = DEFAULT_CONFIG.read_text()
    section = text[text.index("[buses.devicenet]") :]
    assert section.count('channel = "demo-devicenet"') == 1
    return section.replace('channel = "demo-devicenet"', f'channel = "{channel}"')


def test_the_demo_has_the_cfw08_next_to_the_profibus_drives() -> None:
    config = load(DEFAULT_CONFIG)
    (line,) = [b for b in config.buses if b.adapter == "devicenet"]
    (cfw08,) = line.drives
    assert (cfw08.id, cfw08.device, cfw08.modbus_unit) == ("cfw08", Device.CFW08, 5)
    assert cfw08.options.assembly is AssemblyPair.EXTENDED  # 21/71
    assert (line.options.interface, line.options.simulate) == ("virtual", True)
    profibus = [d.modbus_unit for b in config.buses if b.adapter == "profibus" for d in b.drives]
    assert profibus and 5 not in profibus


async def test_the_demo_line_comes_online(tmp_path: Path) -> None:
    """What `make run` shows for the CFW-08: online on Zenoh and on Modbus unit 5."""
    channel = f"demo-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: demo_devicenet(channel), ["cfw08"]) as gw:
        with gw.client.subscribe(state_key()) as states:
            await gw.client.settled(PREFIX)
            await gw.command("cfw08", {"run": True, "speed_rpm": 300})
            s = parsed(await states.auntil(lambda g: parsed(g).running, TIMEOUT))
            assert s.online and s.device is Device.CFW08
        regs = await gw.inputs(5)
        assert (regs[19], regs[20]) == (4, 5)  # CFW-08 at MAC 5
        diag = (await gw.diagnostics("devicenet"))["drives"]["cfw08"]
        assert diag["assembly"] == "21/71" and diag["state"] == "online"


async def test_20_70_refuses_a_reverse_by_zenoh_and_modbus(tmp_path: Path) -> None:
    """Issue 17 item 5: on 20/70 (Run Fwd only, seed table 5) a negative speed used to be
    accepted and sent as Run Fwd = 0, so the running drive ramped to a stop while the
    published reference said -900. Now it is refused with the reason, and the drive
    keeps running forward."""
    channel = f"e2e-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: buses(channel, 20), ["cfw08"]) as gw:
        with gw.client.subscribe(state_key()) as states:
            await gw.client.settled(PREFIX)
            await gw.command("cfw08", {"run": True, "speed_rpm": 900})
            await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT)
            reason = await gw.refused("cfw08", {"run": True, "speed_rpm": -900})
            assert reason == (
                "speed_rpm -900 asks for reverse: assembly 20/70 has no reverse "
                "(Run Fwd only); use 21/71 or 100/150"
            )
            assert "no reverse" in await gw.refused("cfw08", {"speed_pct": -25})
            refused = await gw.modbus.write_register(1, -900 & 0xFFFF, device_id=UNIT)
            assert refused.isError() and refused.exception_code == 4
            polls = sim(gw).node(MAC).figures.polls
            async with asyncio.timeout(TIMEOUT):  # the node's own polls, from its line
                await sim(gw).until(lambda: sim(gw).node(MAC).figures.polls > polls + 5)
            assert sim(gw).node(MAC).drive.run_fwd
            s = parsed(await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT))
            assert (s.speed_rpm, s.speed_ref_rpm, s.status.label) == (900.0, 900.0, "running")
            regs = await gw.inputs(UNIT)
            assert regs[0] & 0b10111 == 0b10111  # online, ready, running, at reference


def _p710_not_reset(channel: str) -> str:
    """P710 already selects 21/71, but the drive has run 20/70 since its last reset."""
    return buses(channel, 21, "sim_p710 = 0\nsim_p710_stored = 1\n")


async def test_the_assembly_in_force_keeps_the_drive_offline_until_a_reset(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Issue 17 item 6: P710 counts only after a reset (seed 4.1.8). With P710 changed and
    not reset the drive used to pass the check and its 70 bytes were read as 71 (a
    running drive published as not_ready). The I/O connection's paths (seed tables
    13-14) show 20/70 in force: the drive is not brought online, with the reason in the
    diagnostics and the log, until a reset applies P710."""
    caplog.set_level(logging.WARNING, logger="adapters.devicenet.adapter")
    channel = f"e2e-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: _p710_not_reset(channel), []) as gw:
        with (
            gw.client.subscribe(f"{PREFIX}/drives/cfw08/diag") as diags,
            gw.client.subscribe(state_key()) as states,
        ):
            await gw.client.settled(PREFIX)
            diag = (await diags.auntil(lambda g: g.json().get("problem"), TIMEOUT)).json()
            assert diag["problem"] == (
                "the drive's I/O uses assembly 20/70 (Connection 05h instance 2 paths), the "
                "config says 21/71; P710 = 1 selects 21/71 but takes effect only after a "
                "reset of the drive (seed 4.1.8): reset or power-cycle it"
            )
            assert diag["assembly_in_force"] == "20/70" and not diag["configured"]
            assert diag["problem"] in caplog.text
            assert gw.daemon.hub.state("cfw08").comm is CommState.CONNECTING
            assert "connecting" in await gw.refused("cfw08", {"run": True, "speed_rpm": 900})
            assert not (await gw.inputs(UNIT))[0] & 0b1  # not online on Modbus
            assert sim(gw).node(MAC).drive.idle  # idle I/O only: nothing commands it
            runner = sim(gw)  # the reset applies P710 = 1: 21/71
            await gw.on_line("dn", lambda: runner.call(MAC, Cfw08Node.reset))
            await states.auntil(lambda g: parsed(g).online, TIMEOUT)
            await gw.command("cfw08", {"run": True, "speed_rpm": -900})
            s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == -900.0, TIMEOUT))
            assert s.status.label == "running" and s.direction.value == "reverse"
