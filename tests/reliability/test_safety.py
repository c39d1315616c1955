"""The six safety rules of the architecture, end to end through the daemon with the demo's
simulated drives, commanded over Zenoh and Modbus TCP as SCADA and a PLC would.

Each test names its rule. What the drive does is read on the simulated device itself;
what a client sees on Zenoh and Modbus.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can

from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.weg.sim.drive import WegSim
from gateway.model import Source
from tests.e2e.harness import COAST_STOP, PREFIX, RESET, RUN, TIMEOUT, Gateway
from tests.reliability.demo import (
    ADDRESSES,
    CIA402,
    DEVICENET,
    DRIVES,
    PROFIBUS,
    UNITS,
    WEG,
    Events,
    at_speed,
    can_sim,
    canopen_sim,
    demo_gateway,
    devicenet_adapter,
    figures,
    now,
    on_line,
    sim_line,
    slave,
    stopped,
    until,
)
from tests.support.timing import scaled

KEEP_ALIVE = 3  # holding register 3: the keep-alive a PLC writes (docs/modbus-map.md)
P0684_FAULT_RESET = 0x80  # WEG control word bit 7 (CFW700 manual, P0684)


def weg(gw: Gateway, drive: str) -> WegSim:
    device = slave(gw, drive).device
    assert isinstance(device, WegSim)
    return device


def mcd(gw: Gateway) -> Mcd600Sim:
    device = slave(gw, "mcd600").device
    assert isinstance(device, Mcd600Sim)
    return device


def turning(gw: Gateway, drive: str) -> float:
    """The motor speed of the simulated drive (rpm; the soft starter: 100 while active)."""
    if drive == "cfw08":
        return float(can_sim(gw).node(ADDRESSES[drive]).drive.motor.speed)
    if drive in CIA402:
        return float(canopen_sim(gw).node(ADDRESSES[drive]).drive.motor.speed)
    if drive == "mcd600":
        return 100.0 if mcd(gw).starter.active else 0.0
    return float(weg(gw, drive).motor.speed)


async def command(gw: Gateway, drive: str, payload: Any) -> dict[str, Any]:
    reply = await gw.client.aone(f"{PREFIX}/drives/{drive}/command", payload)
    answer: dict[str, Any] = reply.json()
    return answer


async def plc_run(gw: Gateway, drive: str, rpm: int) -> None:
    """A PLC's start: the speed, then its command word 0 and run (an edge)."""
    unit = UNITS[drive]
    await gw.write(unit, 1, rpm)
    await gw.write(unit, 0, 0)
    await gw.write(unit, 0, RUN)


async def spy_outputs(gw: Gateway, drive: str) -> list[int]:
    """Every control word the simulated WEG drive receives from now on (word 0 of the
    outputs), recorded as the drive sees it (on its line's loop)."""
    device = weg(gw, drive)
    words: list[int] = []
    original = device.exchange

    def exchange(outputs: bytes, now: float) -> bytes:
        words.append(struct.unpack_from(">H", outputs)[0])
        return original(outputs, now)

    def spy() -> None:
        device.exchange = exchange  # type: ignore[method-assign]

    await on_line(gw, PROFIBUS, spy)
    return words


def pulses(words: list[int], bit: int) -> int:
    """How many separate pulses of ``bit`` the words hold."""
    count, level = 0, False
    for word in words:
        high = bool(word & bit)
        count += high and not level
        level = high
    return count


# ---------------------------------------------------------------- rule 1


async def test_rule1_the_gateway_starts_with_every_drive_stopped(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        for drive in DRIVES:
            state = hub.state(drive)
            assert state.online and not state.running, drive
            assert state.control_source is Source.NONE and not hub.desired(drive).run
            assert turning(gw, drive) == 0.0, drive
            regs = await gw.inputs(UNITS[drive])
            assert regs[0] & 0b101 == 0b001, drive  # online, not running
        # a PLC that was writing run before the gateway started: its first word starts nothing
        for drive in DRIVES:
            await gw.write(UNITS[drive], 0, RUN)
        await until(lambda: sim_line(gw)[ADDRESSES["cfw11"]].counters.exchanges > 50)
        assert not any(hub.desired(d).run or hub.state(d).running for d in DRIVES)
        assert all(turning(gw, d) == 0.0 for d in DRIVES)


async def test_rule1_no_restart_after_a_fault_reset(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        with Events(gw) as events:
            await command(gw, "cfw700", {"run": True, "speed_rpm": 900})
            await command(gw, "mcd600", {"run": True})
            await gw.wait_for("cfw700", at_speed(900.0))
            await gw.wait_for("mcd600", lambda s: s.running)
            cfw700, starter = weg(gw, "cfw700"), mcd(gw)

            def fault_and_trip() -> None:
                cfw700.inject_fault(71, now())
                starter.trip(1)  # a trip the starter's table names (MCD 600 manual)

            await on_line(gw, PROFIBUS, fault_and_trip)
            faulted = await gw.wait_for("cfw700", lambda s: s.faulted)
            assert (faulted.fault_code, faulted.fault_text) == (71, "F071")
            await gw.wait_for("mcd600", lambda s: s.faulted)
            await events.text("cfw700", "run command cleared: drive fault")
            await events.text("mcd600", "run command cleared: drive trip")
            answer = await command(gw, "cfw700", {"run": True, "fault_reset": True})
            assert answer == {
                "accepted": False,
                "error": "send run after the fault reset, not in the same command",
            }

            def causes_gone() -> None:  # the cause is gone
                cfw700.faults.clear()
                starter.faults.clear()

            await on_line(gw, PROFIBUS, causes_gone)
            for drive in ("cfw700", "mcd600"):
                assert (await command(gw, drive, {"fault_reset": True}))["accepted"]
                await gw.wait_for(drive, lambda s: s.online and not s.faulted)
            await until(lambda: sim_line(gw)[ADDRESSES["cfw700"]].counters.exchanges > 100)
            for drive in ("cfw700", "mcd600"):
                assert not hub.state(drive).running and not hub.desired(drive).run
            assert not weg(gw, "cfw700").running and not mcd(gw).starter.active
            assert (await command(gw, "cfw700", {"run": True}))["accepted"]
            await gw.wait_for("cfw700", at_speed(900.0))


async def test_rule1_no_restart_when_control_passes_to_another_source(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        unit = UNITS["cfw320"]
        with Events(gw) as events:
            await command(gw, "cfw320", {"run": True, "speed_rpm": 900})
            await gw.wait_for("cfw320", at_speed(900.0))
            await gw.write(unit, 1, 600)  # a PLC changes the speed: it takes control
            await events.text("cfw320", "control passed from zenoh anonymous to modbus 127.0.0.1")
            state = await gw.wait_for("cfw320", stopped)
            assert state.control_source is Source.MODBUS and turning(gw, "cfw320") == 0.0
            await gw.write(unit, 0, 0)
            await gw.write(unit, 0, RUN)
            await gw.wait_for("cfw320", at_speed(600.0))
            assert (await command(gw, "cfw320", {"speed_rpm": 900}))["accepted"]
            await events.text("cfw320", "control passed from modbus 127.0.0.1 to zenoh anonymous")
            state = await gw.wait_for("cfw320", stopped)
            assert state.control_source is Source.ZENOH and not hub.desired("cfw320").run
            assert (await gw.inputs(unit))[14] == 1  # control_source: zenoh


# ---------------------------------------------------------------- rule 2


async def test_rule2_a_fault_reset_is_one_edge_never_repeated(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        unit = UNITS["cfw700"]
        device = weg(gw, "cfw700")
        reset = device._reset_fault

        def reset_but_the_cause_stays() -> None:
            reset()
            device._trip(71)  # e.g. the motor is still overloaded: F071 again at once

        def a_fault_that_stays() -> None:
            device._reset_fault = reset_but_the_cause_stays  # type: ignore[method-assign]
            device.inject_fault(71, now())

        await on_line(gw, PROFIBUS, a_fault_that_stays)
        await gw.wait_for("cfw700", lambda s: s.faulted)
        words = await spy_outputs(gw, "cfw700")
        exchanges = sim_line(gw)[ADDRESSES["cfw700"]].counters

        async def cycles(n: int) -> None:
            start = exchanges.exchanges
            await until(lambda: exchanges.exchanges > start + n)

        assert (await command(gw, "cfw700", {"fault_reset": True}))["accepted"]
        await cycles(100)
        assert pulses(words, P0684_FAULT_RESET) == 1  # the drive is still faulted: no repeat
        assert gw.daemon.hub.state("cfw700").faulted
        # a PLC holding the reset bit (its word rewritten cyclically): one more edge only
        await gw.write(unit, 0, 0)
        for _ in range(5):
            await gw.write(unit, 0, RESET)
        await cycles(100)
        assert pulses(words, P0684_FAULT_RESET) == 2


# ---------------------------------------------------------------- rule 3


async def test_rule3_the_command_watchdog_ramps_coasts_or_holds(tmp_path: Path) -> None:
    # long enough that a client refreshing every timeout/8 on a loaded machine (a round
    # of three requests and a sleep) never misses it
    timeout = scaled(2.0)
    drives: dict[str, dict[str, Any]] = {
        "cfw11": {"command_timeout": timeout},  # on_command_timeout: ramp_stop (default)
        "cfw700": {"command_timeout": timeout, "on_command_timeout": "coast"},
        "cfw320": {"command_timeout": timeout, "on_command_timeout": "hold"},
    }
    async with demo_gateway(tmp_path, drives) as gw:
        hub = gw.daemon.hub
        unit = UNITS["cfw700"]
        with Events(gw) as events:
            await command(gw, "cfw11", {"run": True, "speed_rpm": 900})
            await command(gw, "cfw320", {"run": True, "speed_rpm": 900})
            await plc_run(gw, "cfw700", 900)
            # while the clients refresh (Zenoh: any command, even {}; Modbus: the keep-alive
            # register), the drives run for many times command_timeout
            start = now()
            count = 0
            while now() - start < 2 * timeout:
                await command(gw, "cfw11", {})
                await command(gw, "cfw320", {})
                await gw.write(unit, KEEP_ALIVE, count := count + 1)
                await asyncio.sleep(timeout / 8)
            assert not [t for t in events.texts() if "no command from" in t]
            for drive in WEG:
                assert at_speed(900.0)(hub.state(drive)), drive
            # the clients go silent
            seen: list[float] = []
            with hub.subscribe_states() as sub:
                await events.text(
                    "cfw11", f"no command from zenoh anonymous for {timeout:g} s: ramp_stop"
                )
                await events.text(
                    "cfw700", f"no command from modbus 127.0.0.1 for {timeout:g} s: coast"
                )
                await events.text(
                    "cfw320", f"no command from zenoh anonymous for {timeout:g} s: hold"
                )
                while (state := await asyncio.wait_for(sub.get(), TIMEOUT)).running or (
                    state.id != "cfw11"
                ):
                    if state.id == "cfw11" and state.speed_rpm is not None:
                        seen.append(state.speed_rpm)
            # cfw11 ramps down (seen on the way when the loop samples it; under load the
            # conflating subscription may show only the end): the action was no coast
            assert not hub.desired("cfw11").coast_stop
            assert all(0.0 <= s <= 900.0 + 1.0 for s in seen)
            await gw.wait_for("cfw700", stopped)
            assert hub.desired("cfw700").coast_stop  # coast: output off at once
            assert weg(gw, "cfw700").running is False
            assert at_speed(900.0)(hub.state("cfw320"))  # hold: keeps running, reported
            for drive in WEG:
                assert hub.desired(drive).source is Source.GATEWAY
            # the next command from the silent client is a change of source: no restart
            assert (await command(gw, "cfw11", {"speed_rpm": 600}))["accepted"]
            assert not hub.desired("cfw11").run
            assert [t for t in events.texts("cfw11") if "no command from" in t] == [
                f"no command from zenoh anonymous for {timeout:g} s: ramp_stop applied"
            ]


# ---------------------------------------------------------------- rule 4


async def test_rule4_shutdown_stops_the_drives_then_leaves_the_buses(tmp_path: Path) -> None:
    drives = {"cfw700": {"on_shutdown": "coast"}}
    # The bound is the suite's (scaled): on a loaded box the simulated drives ramp down in
    # wall time, and a bound reached means leaving them turning (docs/safety.md, item 13).
    async with demo_gateway(tmp_path, drives, shutdown_timeout=scaled(20.0)) as gw:
        hub = gw.daemon.hub
        for drive in WEG:
            await command(gw, drive, {"run": True, "speed_rpm": 900})
        await command(gw, "cfw08", {"run": True, "speed_rpm": 900})
        await command(gw, "mcd600", {"run": True})
        for drive in (*WEG, "cfw08"):
            await gw.wait_for(drive, at_speed(900.0))
        await gw.wait_for("mcd600", lambda s: s.running)
        cfw11 = weg(gw, "cfw11")

        def slow_deceleration() -> None:
            cfw11.values[101] = 15  # 1.5 s deceleration: time to try a command

        await on_line(gw, PROFIBUS, slow_deceleration)
        at_clear: dict[str, tuple[float, bool]] = {}  # speed, output on
        watched: list[tuple[WegSim, Callable[..., None]]] = []
        for drive in WEG:
            device = weg(gw, drive)

            def clear_mode(
                now: float,
                active: bool = True,
                drive: str = drive,
                original: Callable[..., None] = device.clear_mode,
            ) -> None:
                if active:
                    at_clear.setdefault(drive, (turning(gw, drive), weg(gw, drive).running))
                original(now, active)

            watched.append((device, clear_mode))

        def watch_clear_modes() -> None:
            for device, clear_mode in watched:
                device.clear_mode = clear_mode  # type: ignore[method-assign]

        await on_line(gw, PROFIBUS, watch_clear_modes)
        node = can_sim(gw).node(ADDRESSES["cfw08"])
        with Events(gw) as events:
            gw.daemon.request_stop()
            await events.text("cfw11", "gateway shutting down: ramp_stop applied")
            await events.text("cfw700", "gateway shutting down: coast applied")
            answer = await command(gw, "cfw11", {"run": True})
            assert answer == {"accepted": False, "error": "the gateway is shutting down"}
            line = sim_line(gw)
            await until(lambda: all(line[ADDRESSES[d]].counters.clears for d in WEG), 10.0)
            await until(lambda: node.allocation == 0)  # DeviceNet: connections released
        # every drive was stopped before the master left the line with Global_Control Clear:
        # ramped down to 0, or (coast) its output off, the motor running down freely
        assert at_clear["cfw11"] == at_clear["cfw320"] == (0.0, False)
        assert at_clear["cfw700"][1] is False
        assert node.drive.motor.speed == 0.0 and not mcd(gw).starter.active
        assert not any(hub.state(d).running for d in DRIVES)


# ---------------------------------------------------------------- rule 5


async def test_rule5_parameter_writes_only_to_writable_params(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        records = sim_line(gw)[ADDRESSES["cfw11"]].counters
        ok, body = await gw.param("cfw11", 100, {"value": 50})
        assert ok and body["value"] == 50 and weg(gw, "cfw11").values[100] == 50
        ok, body = await gw.param("cfw08", 101, {"value": 12})
        assert ok and can_sim(gw).node(ADDRESSES["cfw08"]).drive.params[101] == 12
        before = (records.records, weg(gw, "cfw11").values[313])
        refused = {
            ("cfw11", 313): "parameter 313 is not in writable_params of drive cfw11",
            ("cfw08", 204): "parameter 204 is not in writable_params of drive cfw08",
            ("mcd600", 1): "parameter 1 is not in writable_params of drive mcd600",
        }
        for (drive, number), error in refused.items():
            assert await gw.param(drive, number, {"value": 1}) == (False, {"error": error})
        # nothing reached the drive: not even a DP-V1 request
        assert (records.records, weg(gw, "cfw11").values[313]) == before
        ok, body = await gw.param("cfw11", 313)  # reading is not writing
        assert ok and body["value"] == before[1]
        # Modbus has no way to a parameter: past the command block every write is refused
        rr = await gw.modbus.write_register(50, 1, device_id=UNITS["cfw11"])
        assert rr.isError() and rr.exception_code == 2


# ---------------------------------------------------------------- rule 6


async def test_rule6_bad_input_is_answered_never_obeyed_never_fatal(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        await command(gw, "cfw11", {"run": True, "speed_rpm": 900})
        await gw.wait_for("cfw11", at_speed(900.0))
        desired = hub.desired("cfw11")
        bad: dict[Any, str] = {
            b'{"run": fals': "invalid JSON",
            b"\xff\xfe": "not UTF-8",
            b"": "payload is empty",
            b"[1, 2]": "a command is a JSON object",
            b'{"run": "no"}': "run must be true or false",
            b'{"stop": true}': "unknown field(s): stop",
            b'{"speed_rpm": 99999}': "beyond the drive's scale",
        }
        for payload, reason in bad.items():
            reply = await gw.client.aone(f"{PREFIX}/drives/cfw11/command", payload)
            answer = reply.json()
            assert answer["accepted"] is False and reason in answer["error"], (payload, answer)
        ok, body = await gw.param("cfw11", 100, b'{"value": "fast"}')
        assert not ok and "value must be a number" in body["error"]
        wildcard = await gw.client.aquery(f"{PREFIX}/drives/*/command", {"run": False})
        assert [r.ok for r in wildcard] == [False]
        # a Modbus write outside a register's range: an exception, never a clamp
        rr = await gw.modbus.write_register(1, 0x7FFF, device_id=UNITS["cfw11"])
        assert rr.isError() and rr.exception_code == 3
        rr = await gw.modbus.write_register(0, RUN | COAST_STOP | 0x4000, device_id=UNITS["cfw11"])
        assert rr.isError() and rr.exception_code == 3
        # frames DeviceNet cannot carry, on the line: counted, dropped
        adapter = devicenet_adapter(gw)
        before = (await gw.diagnostics(DEVICENET))["link_bad_frames"]
        intruder = can.Bus(interface="virtual", channel=adapter.options.channel)
        try:
            intruder.send(can.Message(arbitration_id=0x1234567, is_extended_id=True, data=b"x"))
            intruder.send(
                can.Message(arbitration_id=0x3C5, is_extended_id=False, is_remote_frame=True)
            )
            await until(lambda: figures(gw, DEVICENET).get("link_bad_frames") == before + 2)
        finally:
            intruder.shutdown()
        # nothing of it was obeyed, and everything still runs
        assert hub.desired("cfw11") == desired
        assert at_speed(900.0)(hub.state("cfw11"))
        health = (await gw.client.aone(f"{PREFIX}/gateway/health")).json()
        assert health["online"] == len(DRIVES)
        assert all(v == 0 for v in gw.daemon.runtime.restarts.values())
