"""End to end: the daemon in-process with a simulated Danfoss MCD 600 soft starter on a
simulated Profibus DP line it shares with a WEG CFW320 (the demo's mixed line), commanded and
read through Zenoh and Modbus TCP.

The starter under test runs in parameter mode (control, monitoring and programming
structures) so the same line also serves its parameters; its simulated power section runs
four times faster (``sim_time_scale``) with a 1 s start ramp and a 1 s soft stop
(``sim_params``): 0.25 s each. A second starter in extended mode, as in the demo, stays
stopped beside it: its monitoring values are its own, never the other starter's.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest_asyncio

from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.sim.slave import DpSlave
from gateway.model import DriveState, DriveStatus
from tests.e2e.harness import (
    PREFIX,
    RESET,
    RUN,
    TIMEOUT,
    Gateway,
    exchanges,
    parsed,
    running_gateway,
    simulated_profibus,
)
from tests.support import simulated
from tests.zenoh.client import Got, Inbox

BUS = "pb"
ID, ADDRESS, UNIT = "mcd600", 6, 4
WEG_ID, WEG_ADDRESS, WEG_UNIT = "cfw320", 5, 3
OTHER_ID, OTHER_ADDRESS, OTHER_UNIT = "mcd600x", 7, 7
FLC_A = 100
NULL16 = 0xFFFF  # docs/modbus-map.md: a uint16 register with no value
NULL_INT16 = 0x8000
MOTOR_OVERLOAD = 2  # guide 4.5
# simulated parameters (adapters/mcd600/paramtable.py): start ramp time 1 s, initial current
# 100 %FLC, current limit 300 %FLC, stop time 1 s
SIM_PARAMS = "{ 4 = 1, 5 = 100, 6 = 300, 9 = 1 }"
STOP_TIME = 9


def buses() -> str:
    return (
        simulated_profibus(BUS)
        + f"""
[[buses.{BUS}.drives]]
id = "{WEG_ID}"
device = "CFW320"
address = {WEG_ADDRESS}
modbus_unit = {WEG_UNIT}
data_profile = "manufacturer"
words = 2
startup_params = {{ P0100 = 4, P0101 = 4, P0220 = 10, P0222 = 11, P0226 = 9, P0227 = 4 }}

[[buses.{BUS}.drives]]
id = "{ID}"
device = "MCD 600"
address = {ADDRESS}
modbus_unit = {UNIT}
mode = "parameter"
flc_a = {FLC_A}
request_period = 0.005
reset_pulse = 0.05
writable_params = [{STOP_TIME}, 99]
sim_time_scale = 4.0
sim_params = {SIM_PARAMS}

[[buses.{BUS}.drives]]
id = "{OTHER_ID}"
device = "MCD 600"
address = {OTHER_ADDRESS}
modbus_unit = {OTHER_UNIT}
mode = "extended"
request_period = 0.005
"""
    )


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    async with running_gateway(tmp_path, buses, [WEG_ID, ID, OTHER_ID]) as gw:
        yield gw


def slave(gw: Gateway, address: int = ADDRESS) -> DpSlave:
    line = simulated.sim_line(gw.adapter(BUS))
    assert line is not None
    return line[address]


def starter(gw: Gateway) -> Mcd600Sim:
    device = slave(gw).device
    assert isinstance(device, Mcd600Sim)
    return device


def sim_pct(gw: Gateway) -> float:
    """The simulated starter's motor current in %FLC."""
    sim = starter(gw)
    return sim.starter.current_pct(sim.settings())


async def bus_cycles(gw: Gateway, n: int) -> None:
    """Until the starter has exchanged ``n`` more telegrams with the master."""
    await exchanges(slave(gw).counters, n)


class Statuses:
    """The published states of the starter and the distinct statuses they went through."""

    def __init__(self, states: Inbox[Got], first: DriveStatus) -> None:
        self.states = states
        self.order = [first]
        self.seen: list[DriveState] = []

    async def until(self, status: DriveStatus) -> list[DriveState]:
        """The states published until the status changes to ``status``."""
        start = len(self.seen)

        def step(g: Got) -> bool:
            s = parsed(g)
            self.seen.append(s)
            changed = self.order[-1] is not s.status
            if changed:
                self.order.append(s.status)
            return changed and s.status is status

        await self.states.auntil(step, TIMEOUT)
        return self.seen[start:]


def diagnosis_event(events: Inbox[Got], text: str) -> Any:
    """The next event from the starter's diagnosis telegram (the adapter adds its address;
    the hub's own trip event on the status change carries none) whose text has ``text``."""

    def match(e: Got) -> bool:
        body = e.json()
        return text in body["text"] and body.get("address") == ADDRESS

    return events.auntil(match, TIMEOUT)


async def test_start_and_stop_by_zenoh_follow_the_starter(gateway: Gateway) -> None:
    sim = starter(gateway)
    ready = await gateway.wait_for(ID, lambda s: s.motor_temp_pct is not None)
    assert ready.status is DriveStatus.READY and ready.remote and not ready.running
    assert (ready.speed_rpm, ready.speed_pct, ready.speed_ref_rpm) == (None, None, None)
    assert ready.values["product_type"] == 15  # request 1: MCD 600
    with gateway.client.subscribe(gateway.state_key(ID)) as states:
        await gateway.client.settled(PREFIX)
        statuses = Statuses(states, DriveStatus.READY)
        await gateway.command(ID, {"run": True})
        seen = await statuses.until(DriveStatus.RUNNING)
        assert seen[-1].values["product_type"] == 15 and seen[-1].values["starter_state"] > 0
        starting = [s for s in seen if s.status is DriveStatus.STARTING]
        currents = [s.current_pct_flc for s in starting if s.current_pct_flc]
        assert currents and all(95.0 <= c <= 200.0 for c in currents)  # 100 % ramping to 200 %
        assert currents == sorted(currents)  # the start current rises (6 bits saturate at 200 %)
        await bus_cycles(gateway, 3)
        running = gateway.daemon.hub.state(ID)
        assert running.running and running.at_reference and running.speed_rpm is None
        assert running.current_pct_flc is not None and running.current_a is not None
        assert abs(running.current_pct_flc - sim_pct(gateway)) <= 1.6  # 6-bit resolution
        assert running.current_a == round(running.current_pct_flc * FLC_A / 100, 2)
        assert running.values["current_avg_a"] > 0 and running.power_kw
        assert sim.starts == 1
        # the other starter's readings are its own: stopped, no current, no power
        other = await gateway.wait_for(OTHER_ID, lambda s: "current_avg_a" in s.values)
        assert other.status is DriveStatus.READY and not other.running
        assert (other.current_pct_flc, other.values["current_avg_a"]) == (0.0, 0)
        assert other.power_kw == 0.0 and other.current_a == 0.0  # no flc_a: request 3, in A

        await gateway.command(ID, {"run": False})
        seen = await statuses.until(DriveStatus.READY)
        stopping = [s.current_pct_flc or 0.0 for s in seen if s.status is DriveStatus.STOPPING]
        assert stopping and stopping == sorted(stopping, reverse=True)  # the current falls
        assert not seen[-1].running and seen[-1].current_pct_flc == 0.0
    assert statuses.order == [
        DriveStatus.READY,
        DriveStatus.STARTING,
        DriveStatus.RUNNING,
        DriveStatus.STOPPING,
        DriveStatus.READY,
    ]
    assert sim.starts == 1


async def test_speed_direction_and_jog_are_refused_with_a_reason(gateway: Gateway) -> None:
    reason = await gateway.refused(ID, {"run": True, "speed_rpm": 900})
    assert reason == "MCD 600 has no speed reference"
    assert "no direction" in await gateway.refused(ID, {"direction": "reverse"})
    assert "jog" in await gateway.refused(ID, {"jog": True})
    speed = await gateway.modbus.write_register(1, 900, device_id=UNIT)
    assert speed.isError() and speed.exception_code == 4  # the hub refuses it
    assert not gateway.daemon.hub.desired(ID).run and starter(gateway).starts == 0


async def test_start_and_stop_by_modbus_with_flc_current_in_the_registers(
    gateway: Gateway,
) -> None:
    await gateway.write(UNIT, 0, 0)  # a new client's first word never starts a drive
    await gateway.write(UNIT, 0, RUN)
    await gateway.wait_for(ID, lambda s: s.status is DriveStatus.STARTING)
    await gateway.wait_for(ID, lambda s: s.status is DriveStatus.RUNNING)
    await bus_cycles(gateway, 3)
    state = gateway.daemon.hub.state(ID)
    regs = await gateway.inputs(UNIT)
    assert regs[0] & 0b10010111 == 0b10010111  # online, ready, running, at line speed, remote
    assert regs[1] == 3  # running
    assert state.current_pct_flc is not None and state.current_a is not None
    assert regs[7] == round(state.current_pct_flc * 10)  # 0.1 %FLC
    assert regs[6] == round(state.current_a * 10)  # 0.1 A, with flc_a
    assert 40.0 <= regs[7] / 10 <= 100.0 and abs(regs[7] / 10 - sim_pct(gateway)) <= 1.6
    assert regs[2:6] == [NULL_INT16] * 4  # no speed, no speed reference: a soft starter
    assert regs[11] == NULL16  # no trip
    assert (regs[19], regs[20]) == (5, ADDRESS)  # MCD 600 at address 6
    await gateway.write(UNIT, 0, 0)
    await gateway.wait_for(ID, lambda s: s.status is DriveStatus.STOPPING)
    await gateway.wait_for(ID, lambda s: s.status is DriveStatus.READY)
    regs = await gateway.inputs(UNIT)
    assert regs[1] == 1 and regs[7] == 0 and not regs[0] & 0b100
    assert starter(gateway).starts == 1


async def test_injected_trip_shows_its_text_needs_a_reset_and_does_not_restart(
    gateway: Gateway,
) -> None:
    sim = starter(gateway)
    key = f"{PREFIX}/drives/{ID}/events"
    with (
        gateway.client.subscribe(key) as events,
        gateway.client.subscribe(gateway.state_key(ID)) as states,
    ):
        await gateway.client.settled(PREFIX)
        await gateway.command(ID, {"run": True})
        await gateway.wait_for(ID, lambda s: s.status is DriveStatus.RUNNING)
        await gateway.on_line(BUS, lambda: sim.trip(MOTOR_OVERLOAD))
        tripped = parsed(
            await states.auntil(lambda g: parsed(g).fault_code == MOTOR_OVERLOAD, TIMEOUT)
        )
        assert tripped.status is DriveStatus.TRIPPED and tripped.fault_text == "Motor overload"
        assert not tripped.running and tripped.current_pct_flc == 0.0
        event = (await diagnosis_event(events, "Motor overload")).json()
        assert event["kind"] == "trip" and event["code"] == MOTOR_OVERLOAD
        regs = await gateway.inputs(UNIT)
        assert (regs[1], regs[11]) == (6, MOTOR_OVERLOAD) and regs[0] & 0b100000  # tripped
        assert not gateway.daemon.hub.desired(ID).run  # the trip cleared the run command

        # a run while tripped is refused with the reason, never held (rule 1)
        reason = await gateway.refused(ID, {"run": True})
        assert "tripped" in reason and "Motor overload" in reason, reason
        assert not gateway.daemon.hub.desired(ID).run
        await bus_cycles(gateway, 20)
        assert gateway.daemon.hub.state(ID).status is DriveStatus.TRIPPED and sim.starts == 1

        await gateway.command(ID, {"fault_reset": True})
        back = await gateway.wait_for(ID, lambda s: not s.faulted)
        assert back.status is DriveStatus.READY and back.fault_code is None
        await bus_cycles(gateway, 20)  # and it stays stopped: no restart by itself
        state = gateway.daemon.hub.state(ID)
        assert state.status is DriveStatus.READY and not state.running and sim.starts == 1
        assert sim.reset_edges == 1

        # the same trip again, while stopped, reset by Modbus: reported again with its text
        await gateway.on_line(BUS, lambda: sim.trip(MOTOR_OVERLOAD))
        await gateway.wait_for(ID, lambda s: s.fault_code == MOTOR_OVERLOAD)
        await diagnosis_event(events, "Motor overload")
        await gateway.write(UNIT, 0, 0)
        await gateway.write(UNIT, 0, RESET)
        await gateway.wait_for(ID, lambda s: s.status is DriveStatus.READY)
        assert sim.reset_edges == 2 and sim.starts == 1


async def test_parameter_read_and_write_round_trip(gateway: Gateway) -> None:
    sim = starter(gateway)
    assert await gateway.param(ID, STOP_TIME) == (True, {"number": 9, "subindex": 0, "value": 1})
    ok, reply = await gateway.param(ID, STOP_TIME, {"value": 2})
    assert ok, reply
    assert sim.params[STOP_TIME] == 2
    assert await gateway.param(ID, STOP_TIME) == (True, {"number": 9, "subindex": 0, "value": 2})
    # the starter's own refusals, with their texts (guide 4.4.2 table 8 byte 7)
    assert await gateway.param(ID, STOP_TIME, {"value": 999}) == (
        False,
        {"error": "parameter 9: invalid parameter value", "code": 2},
    )
    assert await gateway.param(ID, 99) == (
        False,
        {"error": "parameter 99: invalid parameter number", "code": 1},
    )
    ok, reply = await gateway.param(ID, 4, {"value": 2})  # not in writable_params (rule 5)
    assert not ok and "writable_params" in reply["error"]
    assert sim.params[STOP_TIME] == 2 and sim.params[4] == 1


async def test_a_starter_and_an_inverter_share_the_line(gateway: Gateway) -> None:
    await gateway.command(WEG_ID, {"run": True, "speed_pct": 50.0})
    await gateway.command(ID, {"run": True})
    weg, ss = await asyncio.gather(
        gateway.wait_for(WEG_ID, lambda s: s.at_reference and s.speed_pct == 50.0),
        gateway.wait_for(ID, lambda s: s.status is DriveStatus.RUNNING),
    )
    assert weg.running and ss.running and ss.speed_rpm is None
    assert slave(gateway, WEG_ADDRESS).counters.exchanges > 0
    regs = await gateway.inputs(WEG_UNIT)
    assert regs[19] == 3 and regs[3] == 5000  # CFW320 at 50.00 %
    await gateway.command(WEG_ID, {"run": False})
    await gateway.command(ID, {"run": False})
    await asyncio.gather(
        gateway.wait_for(WEG_ID, lambda s: s.status is DriveStatus.READY and not s.running),
        gateway.wait_for(ID, lambda s: s.status is DriveStatus.READY),
    )
