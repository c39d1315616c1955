"""End to end, safety rule 1 (issue 17 item 1): a fault cleared at the drive itself never
restarts it.

One daemon with every simulated device model: the three WEG drives and an MCD 600 on a
Profibus line, a CFW-08 on a DeviceNet line. Each drive is faulted by the simulator; a run
command sent then is refused with the reason (Zenoh ``{"accepted": false, "error": ...}``,
Modbus exception 4), never held; the fault is then cleared behind the gateway's back, at
the drive (parametrised: the keypad's reset, the drive's own auto-reset, a power cycle),
and the drive stays stopped for many of its own bus cycles; a fresh run command starts it.

Each drive is commanded as it was seen to restart (the issue): the CFW320 and the CFW-11
(PROFIdrive profile) through Zenoh, the CFW700 by a Modbus 0->1 run edge; the MCD 600
through Modbus too, the CFW-08 through Zenoh.
"""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio

from adapters.devicenet.sim import SimRunner
from adapters.mcd600.paramtable import AUTO_RESET_ACTION, AUTO_RESET_DELAY, AutoResetAction
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.sim.slave import DpSlave
from adapters.profibus.weg.sim.drive import WegSim
from gateway.cli import main
from gateway.model import DriveState, DriveStatus
from tests.e2e.harness import (
    PREFIX,
    RUN,
    TIMEOUT,
    Gateway,
    exchanges,
    for_each,
    running_gateway,
    simulated_profibus,
)
from tests.support import simulated

PB, DN = "pb", "dn"
NETWORK = "P0105 = 5, P0220 = 10, P0222 = 11, P0226 = 9, P0227 = 4, P0228 = 5"
WEG_STARTUP = f"{{ P0100 = 3, P0101 = 3, {NETWORK} }}"  # 0.3 s ramps, sources on the network
CFW08_MAC = 5
AUTO_RESET_S = 1  # P0206 / P206 / the starter's auto-reset delay
STAYS_STOPPED = 60  # bus cycles (or CFW-08 polls) the drive is watched after the clear


class Clear(Enum):
    """How the fault ends, at the drive and behind the gateway's back."""

    KEYPAD = "keypad reset"
    AUTO = "auto-reset"
    POWER = "power cycle"


class Via(Enum):
    ZENOH = "zenoh"
    MODBUS = "modbus"


@dataclass(frozen=True)
class Drive:
    id: str
    via: Via
    unit: int  # Modbus unit
    fault: int  # the fault or trip code injected
    speed: dict[str, float]  # the Zenoh speed reference (none for the soft starter)
    modbus_speed: tuple[int, int] | None = None  # (holding register, value)
    address: int = 0  # Profibus address (the CFW-08's MAC is CFW08_MAC)


DRIVES = (
    Drive("cfw11", Via.ZENOH, 1, 71, {"speed_rpm": 600.0}, address=3),
    Drive("cfw700", Via.MODBUS, 2, 71, {}, (1, 600), address=4),  # speed_ref_rpm
    Drive("cfw320", Via.ZENOH, 3, 32, {"speed_pct": 50.0}, address=5),
    Drive("mcd600", Via.MODBUS, 4, 2, {}, address=6),  # 2: motor overload
    Drive("cfw08", Via.ZENOH, 5, 6, {"speed_rpm": 600.0}),
)


def buses(channel: str) -> str:
    return (
        simulated_profibus(PB, acyclic_timeout=0.5)
        + f"""
[[buses.{PB}.drives]]
id = "cfw11"
device = "CFW-11"
address = 3
modbus_unit = 1
data_profile = "profidrive"
frame = 20
startup_params = {WEG_STARTUP}

[[buses.{PB}.drives]]
id = "cfw700"
device = "CFW700"
address = 4
modbus_unit = 2
data_profile = "manufacturer"
words = 2
startup_params = {WEG_STARTUP}

[[buses.{PB}.drives]]
id = "cfw320"
device = "CFW320"
address = 5
modbus_unit = 3
data_profile = "manufacturer"
words = 2
param_record = 48
startup_params = {WEG_STARTUP}

[[buses.{PB}.drives]]
id = "mcd600"
device = "MCD 600"
address = 6
modbus_unit = 4
mode = "extended"
request_period = 0.005
sim_time_scale = 4.0
sim_params = {{ 4 = 1, 5 = 100, 6 = 300, 9 = 1 }}

[buses.{DN}]
adapter = "devicenet"
interface = "virtual"
channel = "{channel}"
simulate = true
poll_interval = 0.01
expected_packet_rate = 0.1
response_timeout = 0.05
explicit_timeout = 0.3
dupmac_timeout = 0.05
retry_max = 0.3
[[buses.{DN}.drives]]
id = "cfw08"
device = "CFW-08"
address = {CFW08_MAC}
modbus_unit = 5
assembly = 21
max_rpm = 1800
sim_ramp_time = 0.3
"""
    )


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    channel = f"rule1-{uuid.uuid4().hex[:8]}"
    async with running_gateway(tmp_path, lambda: buses(channel), [d.id for d in DRIVES]) as gw:
        yield gw


# ----------------------------------------------------------------------- the simulators


def now() -> float:
    return asyncio.get_running_loop().time()


def slave(gw: Gateway, drive: Drive) -> DpSlave:
    line = simulated.sim_line(gw.adapter(PB))
    assert line is not None
    return line[drive.address]


def dn_sim(gw: Gateway) -> SimRunner:
    runner = simulated.sim_runner(gw.adapter(DN))
    assert runner is not None
    return runner


class Sim:
    """One drive's simulator, whatever its bus: fault, clear, progress, motor. A change to
    the simulator is made on its line's own loop (``Gateway.on_line``)."""

    def __init__(self, gw: Gateway, drive: Drive) -> None:
        self.gw, self.drive = gw, drive

    async def inject_fault(self) -> None:
        code = self.drive.fault
        if self.drive.id == "cfw08":
            runner = dn_sim(self.gw)
            await self.gw.on_line(
                DN, lambda: runner.call(CFW08_MAC, lambda node, t: node.inject_fault(code, t))
            )
            return
        device = slave(self.gw, self.drive).device
        if isinstance(device, Mcd600Sim):
            starter = device
            await self.gw.on_line(PB, lambda: starter.trip(code, now()))
        else:
            assert isinstance(device, WegSim)
            weg = device
            await self.gw.on_line(PB, lambda: weg.inject_fault(code, now()))

    async def clear(self, how: Clear) -> None:
        """End the fault at the drive: the gateway sends nothing for it."""
        if self.drive.id == "cfw08":
            await self.gw.on_line(DN, lambda: _clear_cfw08(dn_sim(self.gw), how))
            return
        pb = slave(self.gw, self.drive)
        if how is Clear.POWER:
            await self.gw.on_line(PB, lambda: pb.power_cycle(now(), off_time=0.2))
            return
        device = pb.device
        if isinstance(device, Mcd600Sim):
            starter = device
            if how is Clear.KEYPAD:
                assert await self.gw.on_line(PB, lambda: starter.keypad_reset(now()))
            else:
                await self.gw.on_line(PB, lambda: _set_auto_reset(starter))
        else:
            assert isinstance(device, WegSim)
            weg = device
            if how is Clear.KEYPAD:
                await self.gw.on_line(PB, lambda: weg.keypad_reset(now()))
            else:
                await self.gw.on_line(PB, lambda: _set_p0206(weg))

    async def progress(self, n: int) -> None:
        """Until the drive has seen ``n`` more cycles of the master (its own clock)."""
        if self.drive.id != "cfw08":
            await exchanges(slave(self.gw, self.drive).counters, n)
            return
        runner = dn_sim(self.gw)
        figures = runner.node(CFW08_MAC).figures
        target = figures.polls + n
        async with asyncio.timeout(TIMEOUT):
            await runner.until(lambda: figures.polls >= target)

    def motor_still(self) -> bool:
        if self.drive.id == "cfw08":
            motor = dn_sim(self.gw).node(CFW08_MAC).drive.motor
            return motor.speed == 0.0 and not motor.enabled
        device = slave(self.gw, self.drive).device
        if isinstance(device, Mcd600Sim):
            return not device.starter.active and device.starter.motor.speed == 0.0
        assert isinstance(device, WegSim)
        return device.motor.speed == 0.0 and not device.motor.enabled


def _set_p206(params: dict[int, int]) -> None:
    params[206] = AUTO_RESET_S  # P206, set at the HMI


def _set_p0206(device: WegSim) -> None:
    device.values[206] = AUTO_RESET_S  # P0206, set at the HMI


def _clear_cfw08(runner: SimRunner, how: Clear) -> None:
    """The CFW-08's fault ended at the drive (on its line's loop)."""
    if how is Clear.KEYPAD:
        runner.call(CFW08_MAC, lambda node, t: node.keypad_reset(t))
    elif how is Clear.AUTO:  # P206: due AUTO_RESET_S after the fault began
        runner.call(CFW08_MAC, lambda node, _: _set_p206(node.drive.params))
    else:
        runner.power_off(CFW08_MAC)
        runner.power_on(CFW08_MAC)


def _set_auto_reset(starter: Mcd600Sim) -> None:
    """The starter's auto-reset set at its keypad (on its line's loop)."""
    starter.params.set(AUTO_RESET_DELAY, AUTO_RESET_S)
    starter.params.set(AUTO_RESET_ACTION, AutoResetAction.RESET_TRIP)


# ----------------------------------------------------------------------- commands


async def send_run(gw: Gateway, drive: Drive) -> Any:
    """A run command by the drive's way in: the Zenoh reply, or the Modbus response."""
    if drive.via is Via.ZENOH:
        key = f"{PREFIX}/drives/{drive.id}/command"
        reply = await gw.client.aone(key, {"run": True, **drive.speed})
        return reply.json()
    return await gw.modbus.write_register(0, RUN, device_id=drive.unit)


# A loaded machine may make the line blip (a reconnect) just then: the refusal then names
# the link state; either way the run is refused, never held.
REASONS = ("faulted", "tripped", "is connecting", "is offline")


def faulted(s: DriveState) -> bool:
    return s.online and s.faulted


async def run_refused(gw: Gateway, drive: Drive) -> None:
    await gw.wait_for(drive.id, faulted)
    answer = await send_run(gw, drive)
    if drive.via is Via.ZENOH:
        assert answer["accepted"] is False, answer
        reason = answer["error"]
        assert isinstance(reason, str) and any(r in reason for r in REASONS), reason
    else:
        assert answer.isError() and answer.exception_code == 4, answer  # SERVER_DEVICE_FAILURE


async def run_accepted(gw: Gateway, drive: Drive) -> None:
    if drive.via is Via.MODBUS:
        await gw.write(drive.unit, 0, 0)  # a fresh 0->1 edge
    answer = await send_run(gw, drive)
    if drive.via is Via.ZENOH:
        assert answer == {"accepted": True}, answer
    else:
        assert not answer.isError(), answer


def still(s: DriveState) -> bool:
    """Not running, not turning, not faulted (whatever the link does meanwhile)."""
    return (
        not s.running
        and s.status not in (DriveStatus.STARTING, DriveStatus.RUNNING)
        and s.speed_rpm in (None, 0.0)
        and not s.faulted
    )


def stopped(s: DriveState) -> bool:
    """Online and ready, and still."""
    return s.online and s.status is DriveStatus.READY and still(s)


async def never_restarts(gw: Gateway, drive: Drive, how: Clear) -> None:
    sim = Sim(gw, drive)
    if drive.via is Via.MODBUS:
        if drive.modbus_speed is not None:
            await gw.write(drive.unit, *drive.modbus_speed)
        await gw.write(drive.unit, 0, 0)  # the client's first word: the edge starts from 0
    await gw.wait_for(drive.id, stopped)

    await sim.inject_fault()
    await run_refused(gw, drive)  # refused with the reason, never held for later
    assert not gw.daemon.hub.desired(drive.id).run

    await sim.clear(how)
    await gw.wait_for(drive.id, lambda s: s.online and not s.faulted)
    await sim.progress(STAYS_STOPPED)  # the drive's own cycles, not a fixed sleep
    # on a loaded machine the link may blip meanwhile (a reconnect): the drive stays still
    state = gw.daemon.hub.state(drive.id)
    assert still(state), state
    assert sim.motor_still() and not gw.daemon.hub.desired(drive.id).run

    await start_again(gw, drive)  # a fresh run command starts it


async def start_again(gw: Gateway, drive: Drive, attempts: int = 3) -> None:
    """A fresh run command starts the drive. A link blip before it runs (a loaded machine)
    clears the run, as rule 1 says: then the run is sent again, a bounded number of times."""
    for _ in range(attempts):
        await gw.wait_for(drive.id, stopped)
        await run_accepted(gw, drive)
        s = await gw.wait_for(drive.id, lambda s: s.running or not s.online)
        if s.running:
            assert s.status in (DriveStatus.STARTING, DriveStatus.RUNNING), s
            return
    raise AssertionError(f"{drive.id}: the link dropped before each of {attempts} runs")


@pytest.mark.parametrize("how", list(Clear), ids=[c.name.lower() for c in Clear])
async def test_a_fault_cleared_at_the_drive_never_restarts_it(gateway: Gateway, how: Clear) -> None:
    async def check(drive: Drive) -> None:
        await never_restarts(gateway, drive, how)

    await for_each(DRIVES, lambda d: f"{d.id} ({d.via.value}, {how.value})", check)


async def cli(argv: list[str]) -> int:
    """The command line (blocking Zenoh calls) on a thread of its own, joined after."""
    with ThreadPoolExecutor(1) as pool:
        return await asyncio.get_running_loop().run_in_executor(pool, main, argv)


async def test_the_cli_cmd_prints_the_refusal_reason(
    gateway: Gateway, capsys: pytest.CaptureFixture[str]
) -> None:
    """``drive-gateway cmd`` against the daemon: a run while faulted prints the hub's reason
    on stderr and exits 1; once the fault is cleared at the drive, a run is accepted (exit 0)."""
    cfw320 = next(d for d in DRIVES if d.id == "cfw320")
    sim = Sim(gateway, cfw320)
    await sim.inject_fault()
    await gateway.wait_for(cfw320.id, faulted)
    (endpoint,) = gateway.daemon.config.zenoh.listen
    argv = ["cmd", "--connect", endpoint, "--prefix", PREFIX, cfw320.id, "run"]
    assert await cli([*argv, "--speed-pct", "50"]) == 1
    out = capsys.readouterr()
    assert out.out == "" and out.err.startswith(f"{cfw320.id}: refused: drive {cfw320.id} is")
    assert any(r in out.err for r in REASONS), out.err  # the hub's own reason, as answered
    assert not gateway.daemon.hub.desired(cfw320.id).run

    await sim.clear(Clear.KEYPAD)
    await gateway.wait_for(cfw320.id, lambda s: s.online and not s.faulted)
    assert await cli([*argv, "--speed-pct", "50"]) == 0
    assert capsys.readouterr().out.startswith(f"{cfw320.id}: accepted")
    await gateway.wait_for(cfw320.id, lambda s: s.running)
