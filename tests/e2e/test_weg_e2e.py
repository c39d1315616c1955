"""End to end: the daemon in-process with the demo's three WEG drives simulated on one
Profibus DP line (``simulate = true``), commanded and read through Zenoh and Modbus TCP.

The line is the demo's: the CFW-11 in the PROFIdrive profile with frame type 20 (6 words),
the CFW700 in the manufacturer profile with 4 words (P0003 and P0049 mapped), the CFW320 in
the manufacturer profile with 2 words. Each drive is programmed at connect by its
``startup_params`` (short ramps, the command sources on the network), as a real drive would
be; the CFW320 reads and writes its parameters through the WEG record 48, the others
through the PROFIdrive record 47.

Every test does the same thing to the three models at once (one daemon start per test keeps
the file short); a failure names the model.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest
import pytest_asyncio

from adapters.profibus.sim.slave import DpSlave
from adapters.profibus.weg.sim.drive import WegSim
from gateway.adapter import EventKind
from gateway.config import DEFAULT_CONFIG
from gateway.model import CommState, Direction, DriveState, DriveStatus
from tests.e2e.harness import (
    PREFIX,
    REVERSE,
    RUN,
    TIMEOUT,
    Gateway,
    exchanges,
    for_each,
    parsed,
    running_gateway,
    simulated_profibus,
)
from tests.support import simulated
from tests.zenoh.client import Got, Inbox

BUS = "pb"
RAMP_P0100 = 3  # P0100 = P0101 = 0.3 s from 0 to P0134 = 1800 rpm: 6000 rpm/s
SLOPE = 1800.0 / (RAMP_P0100 / 10.0)  # rpm/s
# A drive that ignored the demo's ramp (20 s by default) runs past the wait (TIMEOUT);
# one that ignored ramps altogether arrives before 0.9 x the ramp time.


@dataclass(frozen=True)
class Model:
    id: str
    device: str
    address: int
    unit: int  # Modbus unit
    table: str  # the profile's keys
    speed: dict[str, float]  # the Zenoh speed reference: 900 rpm or its CFW320 equivalent
    modbus_speed: tuple[int, int]  # (holding register, value): the same reference
    fault: tuple[int, str]  # an injected fault code and the text the state must show
    refused: tuple[str, int]  # the drive's text and code for P0313 = 9 (range 0-5)


MODELS = (
    Model(
        "cfw11",
        "CFW-11",
        3,
        1,
        'data_profile = "profidrive"\nframe = 20',
        {"speed_rpm": 900.0},
        (1, 900),  # speed_ref_rpm
        (71, "motor overload"),  # Table 3.7 NAMUR bit 6 (F0071/F0072); P0049 read by DP-V1
        ("parameter value out of the limits", 0x0002),  # record 47, Table 4.2
    ),
    Model(
        "cfw700",
        "CFW700",
        4,
        2,
        'data_profile = "manufacturer"\nwords = 4\nwords_in = [3, 49]',
        {"speed_rpm": 900.0},
        (1, 900),
        (71, "F071"),  # not in the CFW700 manual: shown as its code, never a guessed text
        ("parameter value out of the limits", 0x0002),
    ),
    Model(
        "cfw320",
        "CFW320",
        5,
        3,
        'data_profile = "manufacturer"\nwords = 2\nparam_record = 48',
        {"speed_pct": 50.0},  # 50 % of P403 = 30 Hz (P685 example): 900 rpm, 4 poles
        (2, 5000),  # speed_ref_pct, 0.01 %
        (32, "Comm. plug-in module communication lost"),  # section 7; P049 read by DP-V1
        ("access error - incorrect values for parameter access", 0xB7),  # record 48
    ),
)
# P0105 and P0220-P0228 on the network (the simulator's numbering, docs/devices.md)
NETWORK = "P0105 = 5, P0220 = 10, P0222 = 11, P0226 = 9, P0227 = 4, P0228 = 5"


def buses(extra_startup: Mapping[str, str] | None = None) -> str:
    """The line; ``extra_startup``: more startup_params entries per drive id."""
    extra = extra_startup or {}
    drives = "".join(
        f"""
[[buses.{BUS}.drives]]
id = "{m.id}"
device = "{m.device}"
address = {m.address}
modbus_unit = {m.unit}
writable_params = [100, 101, 313]
{m.table}
startup_params = {{ P0100 = {RAMP_P0100}, P0101 = {RAMP_P0100}, {NETWORK}{extra.get(m.id, "")} }}
"""
        for m in MODELS
    )
    return simulated_profibus(BUS, acyclic_timeout=0.5) + drives


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    async with running_gateway(tmp_path, buses, [m.id for m in MODELS]) as gw:
        yield gw


def every_model(
    test: Callable[[Gateway, Model], Awaitable[None]],
) -> Callable[..., Awaitable[None]]:
    """The test run for the three models at once on one gateway."""

    async def run(gateway: Gateway) -> None:
        await for_each(MODELS, lambda m: m.id, lambda m: test(gateway, m))

    run.__name__ = test.__name__
    run.__doc__ = test.__doc__
    return run


def slave(gw: Gateway, model: Model) -> DpSlave:
    line = simulated.sim_line(gw.adapter(BUS))
    assert line is not None
    return line[model.address]


def drive(gw: Gateway, model: Model) -> WegSim:
    device = slave(gw, model).device
    assert isinstance(device, WegSim)
    return device


def now() -> float:
    return asyncio.get_running_loop().time()


async def bus_cycles(gw: Gateway, model: Model, n: int) -> None:
    """Until the drive has exchanged ``n`` more telegrams with the master."""
    await exchanges(slave(gw, model).counters, n)


def follows(sent_at: float, got: Got, ramp_time: float) -> None:
    """The sample ``got`` did not come before the drive could have ramped. How late it
    may come is bounded by the wait; latency is a benchmark figure (`make bench`)."""
    elapsed = got.at - sent_at
    assert elapsed >= 0.9 * ramp_time, f"{elapsed:.3f} s for a {ramp_time} s ramp"


async def ramp(
    gw: Gateway,
    model: Model,
    states: Inbox[Got],
    send: Callable[[], Awaitable[None]],
    *,
    start: float,
    target: float,
) -> DriveState:
    """``send`` a command that takes the drive from ``start`` to ``target`` rpm: the state
    published on Zenoh goes through the ramp and is at the reference in time."""
    seen: list[float] = []

    def arrived(g: Got) -> bool:
        s = parsed(g)
        if s.speed_rpm is not None:
            seen.append(s.speed_rpm)
        return s.speed_rpm == target and s.at_reference and s.status is DriveStatus.RUNNING

    sent_at = time.monotonic()
    await send()
    got = await states.auntil(arrived, TIMEOUT)
    follows(sent_at, got, abs(target - start) / SLOPE)
    between = [v for v in seen if min(start, target) < v < max(start, target)]
    assert len(between) >= 3, f"a jump, not a ramp: {seen}"
    # the published speed is the 13-bit word's: the motor is within one step of it
    assert drive(gw, model).motor.speed == pytest.approx(target, abs=0.5)
    return parsed(got)


async def stop(
    gw: Gateway, states: Inbox[Got], send: Callable[[], Awaitable[None]], start: float
) -> DriveState:
    """``send`` a stop: the state ramps down to zero speed, ready, in time."""
    sent_at = time.monotonic()
    await send()
    got = await states.auntil(
        lambda g: parsed(g).speed_rpm == 0.0 and parsed(g).status is DriveStatus.READY, TIMEOUT
    )
    follows(sent_at, got, abs(start) / SLOPE)
    s = parsed(got)
    assert not s.running and not s.at_reference
    return s


def run_command(gw: Gateway, model: Model) -> Callable[[], Awaitable[None]]:
    return lambda: gw.command(model.id, {"run": True, **model.speed})


# ----------------------------------------------------------------------- commands


@every_model
async def test_run_reverse_stop_by_zenoh(gw: Gateway, model: Model) -> None:
    with gw.client.subscribe(gw.state_key(model.id)) as states:
        await gw.client.settled(PREFIX)
        s = await ramp(gw, model, states, run_command(gw, model), start=0.0, target=900.0)
        assert (s.direction, s.remote, s.speed_pct, s.speed_ref_rpm) == (
            Direction.FORWARD,
            True,
            50.0,
            900.0,
        )
        reverse = lambda: gw.command(model.id, {"direction": "reverse"})  # noqa: E731
        s = await ramp(gw, model, states, reverse, start=900.0, target=-900.0)
        assert (s.direction, s.speed_pct, s.speed_ref_rpm) == (Direction.REVERSE, -50.0, -900.0)
        await stop(gw, states, lambda: gw.command(model.id, {"run": False}), -900.0)
    if model.device == "CFW320":  # P684 bit 6 is reserved: no quick stop (Table 4.3)
        # a stop is never refused (issue 32): the quick stop becomes a ramp stop, said once
        with gw.daemon.hub.subscribe_events() as events:
            await gw.command(model.id, {"quick_stop": True})
            said = [e.text for e in events.drain() if e.kind is EventKind.SAFETY]
        assert "quick_stop is not in the CFW320: a ramp stop applied instead" in said, said
        assert not gw.daemon.hub.desired(model.id).run


@every_model
async def test_run_reverse_stop_by_modbus(gw: Gateway, model: Model) -> None:
    unit = model.unit
    register, value = model.modbus_speed
    with gw.client.subscribe(gw.state_key(model.id)) as states:
        await gw.client.settled(PREFIX)
        await gw.write(unit, register, value)
        await gw.write(unit, 0, 0)  # a new client's first word never starts a drive
        await ramp(gw, model, states, lambda: gw.write(unit, 0, RUN), start=0.0, target=900.0)
        regs = await gw.inputs(unit)
        assert regs[0] & 0b10111 == 0b10111  # online, ready, running, at reference
        assert (regs[2], regs[3], regs[20]) == (900, 5000, model.address)
        await ramp(
            gw, model, states, lambda: gw.write(unit, 0, RUN | REVERSE), start=900.0, target=-900.0
        )
        regs = await gw.inputs(unit)
        assert regs[0] & 0b1000 and (regs[2], regs[3]) == ((-900) & 0xFFFF, (-5000) & 0xFFFF)
        await stop(gw, states, lambda: gw.write(unit, 0, REVERSE), -900.0)
        assert (await gw.inputs(unit))[0] & 0b111 == 0b011  # online, ready, not running


# ----------------------------------------------------------------------- parameters


@every_model
async def test_parameters_through_zenoh(gw: Gateway, model: Model) -> None:
    ok, read = await gw.param(model.id, 100)
    assert ok and read["value"] == RAMP_P0100, read  # written at connect (startup_params)
    # the manual's table names it and scales it (P0750 / P746: "5.0 s is sent as 50")
    code = "P100" if model.device == "CFW320" else "P0100"
    assert (read["code"], read["name"], read["unit"]) == (code, "Acceleration time", "s"), read
    assert read["scaled"] == RAMP_P0100 / 10, read
    ok, answer = await gw.param(model.id, 101, {"value": 7})  # 0.7 s
    assert ok and (answer["value"], answer["scaled"], answer["name"]) == (
        7,
        0.7,
        "Deceleration time",
    ), answer
    ok, read = await gw.param(model.id, 101)
    assert ok and read["value"] == 7, read
    assert drive(gw, model).values[101] == 7
    ok, refused = await gw.param(model.id, 313, {"value": 9})  # P0313 is 0-5
    assert not ok
    assert refused == {"error": model.refused[0], "code": model.refused[1]}
    assert drive(gw, model).values[313] != 9
    ok, not_allowed = await gw.param(model.id, 134, {"value": 1500})
    assert not ok and "writable_params" in not_allowed["error"]


# ----------------------------------------------------------------------- faults


@every_model
async def test_injected_fault_needs_a_reset_and_does_not_restart(gw: Gateway, model: Model) -> None:
    code, text = model.fault
    c = gw.client
    events_key = f"{PREFIX}/drives/{model.id}/events"
    with c.subscribe(gw.state_key(model.id)) as states, c.subscribe(events_key) as events:
        await c.settled(PREFIX)
        sim = drive(gw, model)
        await gw.on_line(BUS, lambda: sim.inject_alarm(138))  # its code and the manual's text
        s = parsed(await states.auntil(lambda g: parsed(g).alarm_code == 138, TIMEOUT))
        assert s.alarm and not s.faulted
        # P0048 is in no telegram word: the status word's alarm bit, then the code by DP-V1
        event = await events.auntil(lambda e: e.json().get("code") == 138, TIMEOUT)
        assert event.json()["text"] == "alarm 138: Profibus DP interface in clear mode"
        await gw.on_line(BUS, sim.clear_alarm)
        await states.auntil(lambda g: not parsed(g).alarm, TIMEOUT)

        await run_command(gw, model)()
        await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT)
        await gw.on_line(BUS, lambda: sim.inject_fault(code, now()))
        s = parsed(await states.auntil(lambda g: parsed(g).fault_code == code, TIMEOUT))
        assert (s.status, s.fault_text, s.running) == (DriveStatus.FAULTED, text, False)
        event = await events.auntil(lambda e: e.json().get("code") == code, TIMEOUT)
        assert event.json()["text"] == f"fault {code}: {text}"
        assert not gw.daemon.hub.desired(model.id).run  # rule 1: the hub cleared run
        await bus_cycles(gw, model, 20)
        assert gw.daemon.hub.state(model.id).faulted  # it stays faulted until a reset

        await gw.command(model.id, {"fault_reset": True})
        cleared = parsed(await states.auntil(lambda g: not parsed(g).faulted, TIMEOUT))
        assert (cleared.fault_code, cleared.fault_text) == (None, None)
        await events.auntil(lambda e: e.json()["text"] == "fault cleared", TIMEOUT)
        await bus_cycles(gw, model, 20)  # it stays off: no restart by itself
        s = gw.daemon.hub.state(model.id)
        assert (s.status, s.running, s.at_reference) == (DriveStatus.READY, False, False)
        # the motor still coasts down from the trip (output off) and never speeds up again
        assert cleared.speed_rpm is not None and s.speed_rpm is not None
        assert 0.0 <= s.speed_rpm < cleared.speed_rpm < 900.0
        assert not sim.motor.enabled and not sim.fault and sim.motor.reference == 0.0


# ----------------------------------------------------------------------- power cycle


@every_model
async def test_power_cycle_comes_back_stopped(gw: Gateway, model: Model) -> None:
    with gw.client.subscribe(gw.state_key(model.id)) as states:
        await gw.client.settled(PREFIX)
        await run_command(gw, model)()
        await states.auntil(lambda g: parsed(g).at_reference, TIMEOUT)
        pb = slave(gw, model)
        await gw.on_line(BUS, lambda: pb.power_cycle(now(), off_time=0.2))
        # gone: offline, or already connecting again (a change a loaded machine conflates)
        await states.auntil(lambda g: not parsed(g).online, TIMEOUT)
        back = parsed(await states.auntil(lambda g: parsed(g).online, TIMEOUT))
        assert (back.status, back.running, back.fault_code) == (DriveStatus.READY, False, None)
        assert not gw.daemon.hub.desired(model.id).run  # a new run command is needed
        await bus_cycles(gw, model, 20)
        assert drive(gw, model).motor.speed == 0.0
        assert gw.daemon.hub.state(model.id).status is DriveStatus.READY

        await ramp(gw, model, states, run_command(gw, model), start=0.0, target=900.0)


# ----------------------------------------------------------------------- manual checks


async def test_cfw320_set_to_profidrive_is_refused_and_its_status_bits_are_published(
    gateway: Gateway,
) -> None:
    """Issue 20: fire mode (P680 bit 2) reaches the Zenoh state; P741 = 0 set at the HMI and a
    power cycle: the connect reads P741 and refuses (CFW320 Table 4.6 note), with an event on
    the drive's events key, and the drive is never online on a misread profile."""
    gw, cfw320 = gateway, MODELS[2]
    c = gw.client
    events_key = f"{PREFIX}/drives/{cfw320.id}/events"
    with c.subscribe(gw.state_key(cfw320.id)) as states, c.subscribe(events_key) as events:
        await c.settled(PREFIX)
        sim, pb = drive(gw, cfw320), slave(gw, cfw320)

        def fire_mode() -> None:  # at the drive, on its line's loop
            sim.fire_mode = True

        def p741_at_the_hmi_and_a_power_cycle() -> None:
            sim.fire_mode = False
            sim.values[741] = 0
            pb.power_cycle(now(), off_time=0.2)

        def p741_set_back() -> None:
            sim.values[741] = 1

        await gw.on_line(BUS, fire_mode)
        await states.auntil(lambda g: parsed(g).values.get("fire_mode") == 1, TIMEOUT)
        await gw.on_line(BUS, p741_at_the_hmi_and_a_power_cycle)
        event = await events.auntil(lambda e: "P741 = 0" in e.json()["text"], TIMEOUT)
        assert event.json()["kind"] == "config"
        assert event.json()["text"] == (
            "not configured: P741 = 0 (profidrive), the config's data_profile is manufacturer "
            "(P741 = 1): its words would be misread"
        )
        await bus_cycles(gw, cfw320, 10)
        assert gw.daemon.hub.state(cfw320.id).comm is CommState.CONNECTING
        reason = await gw.refused(cfw320.id, {"run": True, **cfw320.speed})
        assert reason == f"drive {cfw320.id} is connecting"
        await gw.on_line(BUS, p741_set_back)  # set back at the HMI: the next attempt connects
        await states.auntil(lambda g: parsed(g).online, TIMEOUT)


# ----------------------------------------------------------------------- the demo line


def demo_profibus() -> str:
    """The demo's Profibus line verbatim (config/demo.toml): `make run` shows these drives."""
    text = DEFAULT_CONFIG.read_text()
    return text[text.index("[buses.profibus]") : text.index("[buses.devicenet]")]


async def test_the_demo_line_comes_online_and_runs(tmp_path: Path) -> None:
    """The demo's WEG drives: online (their startup_params written and read back) on Zenoh
    and on Modbus units 1-3, and they run on a command from the network."""
    weg = {"cfw11": (1, 1, 3), "cfw700": (2, 2, 4), "cfw320": (3, 3, 5)}  # unit, code, address
    async with running_gateway(tmp_path, demo_profibus, list(weg)) as gw:

        async def check(drive_id: str) -> None:
            unit, device_code, address = weg[drive_id]
            with gw.client.subscribe(gw.state_key(drive_id)) as states:
                await gw.client.settled(PREFIX)
                # 225 rpm: 1024 of 8192 (13 bits), 2048 of 4000h (PROFIdrive), 7.5 Hz (CFW320)
                speed = {"speed_pct": 12.5} if drive_id == "cfw320" else {"speed_rpm": 225.0}
                await gw.command(drive_id, {"run": True, **speed})
                s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == 225.0, TIMEOUT))
                assert (s.at_reference, s.remote, s.online) == (True, True, True)
            regs = await gw.inputs(unit)
            assert (regs[0] & 0b111, regs[19], regs[20]) == (0b111, device_code, address)
            diag = (await gw.diagnostics("profibus"))["drives"][drive_id]
            assert diag["configured"] and diag["not_configured_reason"] is None

        await for_each(weg, str, check)


# ----------------------------------------------------------------------- startup_params


async def test_a_refused_startup_parameter_leaves_the_drive_not_configured(
    tmp_path: Path,
) -> None:
    """P0313 = 9 is out of range: the drive stays in data exchange with a stopped command,
    "connecting" in the model, with the drive's own error text as the reason."""
    cfw700 = MODELS[1]

    refused = lambda: buses({"cfw700": ", P0313 = 9"})  # noqa: E731
    async with running_gateway(tmp_path, refused, ["cfw11", "cfw320"]) as gw:
        line = gw.line(BUS)

        def reason() -> str | None:
            got: str | None = (
                line.diagnostics().get("drives", {}).get("cfw700", {}).get("not_configured_reason")
            )
            return got

        async with asyncio.timeout(TIMEOUT):
            while reason() is None:
                await line.next_diagnostics()
        assert reason() == (
            "not configured: startup P0313 = 9: parameter value out of the limits (error 0x0002)"
        )
        await bus_cycles(gw, cfw700, 10)  # exchanging, with the stopped command
        assert gw.daemon.hub.state("cfw700").comm is CommState.CONNECTING
        assert gw.daemon.hub.capabilities("cfw700").speed_scale is None  # no scale read
        reason_text = await gw.refused("cfw700", {"run": True, "speed_rpm": 900})
        assert reason_text == "drive cfw700 is connecting"  # no command reaches it
        await bus_cycles(gw, cfw700, 10)
        assert drive(gw, cfw700).motor.speed == 0.0 and drive(gw, cfw700).values[313] == 0
