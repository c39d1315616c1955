"""End to end: the daemon in-process with two simulated CiA 402 drives on a python-can
``virtual`` CANopen line (``simulate = true``), commanded and read through Zenoh and
Modbus TCP."""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import pytest_asyncio

from adapters.canopen.codec.cia402 import State
from adapters.canopen.sim.runner import SimRunner
from gateway.config import DEFAULT_CONFIG, load, shipped_file
from gateway.errors import ConfigErrors
from gateway.model import CommState, Device
from tests.e2e.harness import (
    PREFIX,
    QUICK_STOP,
    RESET,
    REVERSE,
    RUN,
    TIMEOUT,
    Gateway,
    parsed,
    running_gateway,
)
from tests.support import simulated

EDS = shipped_file("eds/cia402-drive.eds")
VL, PV = 5, 6  # node ids, Modbus units 5 and 6


def buses(channel: str) -> str:
    drives = ""
    for node, mode in ((VL, "velocity"), (PV, "profile_velocity")):
        drives += f"""
[[buses.co.drives]]
id = "n{node}"
device = "CiA 402"
address = {node}
modbus_unit = {node}
eds = "{EDS}"
mode = "{mode}"
max_rpm = 1800
heartbeat = 100
comm_loss_option = 1
quick_stop_option = 2
writable_params = ["0x605A", "0x2000:4"]
sim_ramp_time = 0.3
"""
    return f"""
[buses.co]
adapter = "canopen"
interface = "virtual"
channel = "{channel}"
simulate = true
sync_period = 0.02
sdo_timeout = 0.3
retry = 0.2
heartbeat = 100
# the drives' consumer time 1 s: these tests are about the command paths, and a loaded
# host's gaps in the gateway's heartbeat (hundreds of ms under a full test run) are not
heartbeat_factor = 10
{drives}"""


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    channel = f"e2e-co-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: buses(channel), ["n5", "n6"]) as gw:
        yield gw


def sim(gateway: Gateway) -> SimRunner:
    runner = simulated.canopen_runner(gateway.adapter("co"))
    assert runner is not None
    return runner


async def test_run_speed_reverse_quick_stop_by_zenoh(gateway: Gateway) -> None:
    with gateway.client.subscribe(gateway.state_key("n6")) as states:
        await gateway.client.settled(PREFIX)
        await gateway.command("n6", {"run": True, "speed_rpm": 900})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT))
        assert (s.status.label, s.speed_ref_rpm, s.device) == ("running", 900.0, Device.CIA402)
        assert s.at_reference and s.speed_pct == 50.0
        await gateway.command("n6", {"direction": "reverse"})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == -900.0, TIMEOUT))
        assert s.direction.value == "reverse"
        await gateway.command("n6", {"quick_stop": True})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == 0.0, TIMEOUT))
        assert not gateway.daemon.hub.desired("n6").run
        reason = await gateway.refused("n6", {"run": True})
        assert "latched in quick_stop" in reason
        await gateway.command("n6", {"quick_stop": False})
        s = parsed(await states.auntil(lambda g: parsed(g).status.label == "ready", TIMEOUT))
        assert not s.running
        assert sim(gateway).node(PV).drive.state is not State.OPERATION_ENABLED


async def test_run_reverse_quick_stop_and_reset_by_modbus(gateway: Gateway) -> None:
    await gateway.write(VL, 1, 600)  # speed_ref_rpm
    await gateway.write(VL, 0, 0)
    await gateway.write(VL, 0, RUN)
    s = await gateway.wait_for("n5", lambda s: s.speed_rpm == 600.0)
    assert s.at_reference
    regs = await gateway.inputs(VL)
    assert regs[0] & 0b10111 == 0b10111  # online, ready, running, at reference
    assert (regs[2], regs[19], regs[20]) == (600, 6, VL)  # speed, CiA 402, node id
    await gateway.write(VL, 0, RUN | REVERSE)
    await gateway.wait_for("n5", lambda s: s.speed_rpm == -600.0)
    await gateway.write(VL, 0, QUICK_STOP)
    await gateway.wait_for("n5", lambda s: s.speed_rpm == 0.0 and not s.running)
    await gateway.write(VL, 0, 0)
    node = sim(gateway).node(VL)
    await gateway.on_line("co", lambda: node.inject_fault(0x3210))
    s = await gateway.wait_for("n5", lambda s: s.faulted and s.fault_code == 0x3210)
    assert s.fault_text == "DC link over-voltage"
    assert (await gateway.inputs(VL))[0] & 0b100000  # faulted bit
    await gateway.write(VL, 0, RESET)
    s = await gateway.wait_for("n5", lambda s: not s.faulted)
    assert not s.running and s.online


async def test_fault_event_and_reset_edge_by_zenoh(gateway: Gateway) -> None:
    with gateway.client.subscribe(f"{PREFIX}/drives/n5/events") as events:
        await gateway.client.settled(PREFIX)
        await gateway.command("n5", {"run": True, "speed_rpm": 300})
        await gateway.wait_for("n5", lambda s: s.running)
        node = sim(gateway).node(VL)
        await gateway.on_line("co", lambda: node.inject_fault(0x2310))
        ev = await events.auntil(lambda e: e.json()["text"].startswith("EMCY 0x2310"), TIMEOUT)
        assert ev.json()["code"] == 0x2310
        assert "continuous over current" in ev.json()["text"]
        await events.auntil(lambda e: "0x603F = 0x2310" in e.json()["text"], TIMEOUT)
        reason = await gateway.refused("n5", {"run": True})
        assert "reset the fault" in reason
        await gateway.command("n5", {"fault_reset": True})
        await events.auntil(lambda e: "fault reset sent" in e.json()["text"], TIMEOUT)
        s = await gateway.wait_for("n5", lambda s: not s.faulted)
        assert not s.running and s.status.label == "ready"


async def test_heartbeat_loss_and_return_stopped(gateway: Gateway) -> None:
    with gateway.client.subscribe(gateway.state_key("n5")) as states:
        await gateway.client.settled(PREFIX)
        await gateway.command("n5", {"run": True, "speed_rpm": 300})
        await states.auntil(lambda g: parsed(g).running, TIMEOUT)
        node = sim(gateway).node(VL)
        await gateway.on_line("co", lambda: node.silence(True))
        await states.auntil(lambda g: parsed(g).comm is CommState.OFFLINE, TIMEOUT)
        await gateway.on_line("co", lambda: node.silence(False))
        await states.auntil(lambda g: parsed(g).online, TIMEOUT)
        # a drive that kept turning while it was not heard is shown turning when it is heard
        # again (never stopped while it turns, docs/safety.md); the gateway then stops it
        assert not gateway.daemon.hub.desired("n5").run  # a new run command is needed
        s = await gateway.wait_for("n5", lambda s: s.status.label in ("ready", "faulted"))
        assert not s.running
        assert sim(gateway).node(VL).drive.state is not State.OPERATION_ENABLED


async def test_parameters_through_zenoh_with_sdo_abort_texts(gateway: Gateway) -> None:
    ok, read = await gateway.param("n5", 0x6046)  # a record: subindex 0 is its count
    assert ok and read["value"] == 2
    c = gateway.client
    key = f"{PREFIX}/drives/n5/params"
    assert (await c.aone(f"{key}/0x6046/2")).json()["value"] == 1800
    assert (await c.aone(f"{key}/24646/2")).json()["value"] == 1800  # decimal, the same
    written = await c.aone(f"{key}/0x605A", {"value": 1})
    assert written.ok, written.json()
    assert (await c.aone(f"{key}/0x605A")).json()["value"] == 1
    refused = await c.aone(f"{key}/0x605A", {"value": 3})
    assert not refused.ok
    assert refused.json() == {
        "error": "0x06090030 value range of parameter exceeded (write 0x605A)",
        "code": 0x06090030,
    }
    assert (await c.aone(f"{key}/0x605A")).json()["value"] == 1  # nothing changed
    not_allowed = await c.aone(f"{key}/0x2000/1", {"value": 3})
    assert not not_allowed.ok and "writable_params" in not_allowed.json()["error"]
    allowed = await c.aone(f"{key}/0x2000/4", {"value": 1500})
    assert allowed.ok, allowed.json()
    missing = await c.aone(f"{key}/0x6099")
    assert missing.json()["error"].startswith("0x06020000 object does not exist")


def demo_canopen(channel: str) -> str:
    """The demo's CANopen line verbatim (config/demo.toml), on a channel of its own."""
    text = DEFAULT_CONFIG.read_text()
    section = text[text.index("[buses.canopen]") :]
    assert section.count('channel = "demo-canopen"') == 1
    section = section.replace('eds = "eds/', f'eds = "{DEFAULT_CONFIG.parent}/eds/')
    return section.replace('channel = "demo-canopen"', f'channel = "{channel}"')


def test_the_demo_has_two_cia402_drives_on_its_own_units() -> None:
    config = load(DEFAULT_CONFIG)
    (line,) = [b for b in config.buses if b.adapter == "canopen"]
    assert [(d.id, d.device, d.modbus_unit) for d in line.drives] == [
        ("cia402a", Device.CIA402, 6),
        ("cia402b", Device.CIA402, 7),
    ]
    assert (line.options.interface, line.options.simulate) == ("virtual", True)
    others = [d.modbus_unit for b in config.buses if b.adapter != "canopen" for d in b.drives]
    assert not {6, 7} & set(others)
    assert {b.adapter for b in config.buses} == {"profibus", "devicenet", "canopen"}


async def test_the_demo_line_comes_online(tmp_path: Path) -> None:
    """What `make run` shows for the CANopen line: both drives online and running."""
    channel = f"demo-{uuid.uuid4().hex[:8]}"
    drives = ["cia402a", "cia402b"]
    async with running_gateway(tmp_path, lambda: demo_canopen(channel), drives) as gw:
        for drive, unit in (("cia402a", 6), ("cia402b", 7)):
            await gw.command(drive, {"run": True, "speed_rpm": 300})
            s = await gw.wait_for(drive, lambda s: s.running)
            assert s.online and s.device is Device.CIA402
            regs = await gw.inputs(unit)
            assert regs[19] == 6
        diag = await gw.diagnostics("canopen")
        assert diag["syncs_tx"] > 0
        assert diag["drives"]["cia402b"]["phase"] == "online"


def test_a_config_with_a_broken_eds_or_a_missing_object_does_not_start(tmp_path: Path) -> None:
    """Bad input never starts the gateway: the error names the config file, the key, the
    EDS file and the object."""
    broken = tmp_path / "broken.eds"
    broken.write_text("[DeviceInfo]\nVendorName=x\n[1000]\nDataType=0x00ZZ\n")
    text = buses("unused").replace(f'eds = "{EDS}"', 'eds = "broken.eds"', 1)
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigErrors) as info:
        load(cfg)
    assert f"{cfg}: buses.co.drives[n5].eds: {broken}: does not parse as an EDS/DCF" in str(
        info.value
    )
    cut = tmp_path / "no-60ff.eds"
    eds = EDS.read_text()
    start = eds.index("[60FF]")
    cut.write_text(eds[:start] + eds[eds.index("[", start + 1) :])
    cfg.write_text(buses("unused").replace(f'eds = "{EDS}"', f'eds = "{cut}"'))
    with pytest.raises(ConfigErrors) as info:
        load(cfg)
    assert f"buses.co.drives[n6].mode: {cut}: 0x60FF: the EDS has no object 0x60FF" in str(
        info.value
    )
