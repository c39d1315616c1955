"""Profibus faults through the daemon, with the demo's drives simulated on the line:
line noise, a slave's power cycle, the serial port vanishing and coming back.

What a SCADA sees is checked on Zenoh (states, events, diag, liveliness), what the drive
does on the simulated device itself.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

import adapters.link.serial as serial_link
import adapters.profibus.adapter as profibus_adapter_module
from adapters.profibus.cli import build_line
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.port import SimPort
from adapters.profibus.weg.sim.drive import WegSim
from gateway.config import parse
from gateway.model import CommState
from tests.e2e.harness import PREFIX, TIMEOUT, parsed
from tests.reliability.demo import (
    PROFIBUS,
    WEG,
    Events,
    at_speed,
    demo_buses,
    demo_gateway,
    drain,
    figures,
    new_channel,
    now,
    on_line,
    sim_line,
    slave,
    stopped,
    until,
)
from tests.support.timing import scaled
from tests.zenoh.client import Got


def weg(device: Any) -> WegSim:
    assert isinstance(device, WegSim)
    return device


def seqs_in_order(samples: list[Got]) -> bool:
    seqs = [s.json()["seq"] for s in samples]
    return all(a <= b for a, b in itertools.pairwise(seqs))


def line_errors(diag: dict[str, Any]) -> int:
    return int(diag["fcs_errors"] + diag["framing_errors"] + diag["timeouts"])


async def test_line_noise_is_counted_and_never_starts_or_stops_a_drive(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        with Events(gw) as events, gw.client.subscribe(f"{PREFIX}/drives/*/state") as states:
            await gw.client.settled(PREFIX)
            await gw.command("cfw11", {"run": True, "speed_rpm": 900})
            await gw.command("cfw700", {"run": True, "speed_rpm": 600})
            await gw.wait_for("cfw11", at_speed(900.0))
            await gw.wait_for("cfw700", at_speed(600.0))
            before = line_errors(await gw.diagnostics(PROFIBUS))
            faults = sim_line(gw).faults

            def noise(rate: float) -> None:
                faults.bit_error_rate = rate  # per byte, both directions (seeded)

            await on_line(gw, PROFIBUS, lambda: noise(2e-3))
            await until(
                lambda: line_errors(figures(gw, PROFIBUS)) >= before + 10, within=scaled(20.0)
            )
            await on_line(gw, PROFIBUS, lambda: noise(0.0))
            diag = await gw.diagnostics(PROFIBUS)
            assert diag["retries"] > 0
            assert diag["fcs_errors"] + diag["framing_errors"] > 0
            # the same figures reach SCADA on the health query and each drive's diag key
            health = (await gw.client.aone(f"{PREFIX}/gateway/health")).json()
            assert line_errors(health["buses"][PROFIBUS]) >= before + 10
            with gw.client.subscribe(f"{PREFIX}/drives/cfw11/diag") as drive_diag:
                got = (await drive_diag.aget(TIMEOUT)).json()
            assert got["state"] == "data_exchange" or got["restarts"] > 0
            # Every drive is online again; one that missed its retries left data exchange
            # (an event says so) and came back stopped; the others never stopped.
            for drive in ("cfw11", "cfw700"):
                await gw.wait_for(drive, lambda s: s.online)
                dropped = any("left data exchange" in t for t in events.texts(drive))
                state = hub.state(drive)
                if dropped:
                    await gw.wait_for(drive, stopped)
                    assert not hub.desired(drive).run
                else:
                    assert state.running and hub.desired(drive).run
            samples = await drain(states)
        for drive in ("cfw11", "cfw700", "cfw320", "mcd600"):
            mine = [s for s in samples if s.json()["id"] == drive]
            assert seqs_in_order(mine), drive  # never an older state after a newer one
        assert hub.state("cfw320").online and not hub.state("cfw320").running


async def test_a_slave_power_cycle_brings_the_drive_back_stopped(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        with (
            Events(gw) as events,
            gw.client.subscribe(gw.state_key("cfw11")) as states,
            gw.client.liveliness(f"{PREFIX}/drives/cfw11") as token,
        ):
            await gw.client.settled(PREFIX)
            await gw.command("cfw11", {"run": True, "speed_rpm": 900})
            await gw.command("cfw700", {"run": True, "speed_rpm": 600})
            await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT)
            await gw.wait_for("cfw700", at_speed(600.0))
            await token.auntil(lambda g: g.put, TIMEOUT)
            cfw11 = slave(gw, "cfw11")
            await on_line(gw, PROFIBUS, lambda: cfw11.power_cycle(now(), off_time=0.3))
            await states.auntil(lambda g: parsed(g).comm is CommState.OFFLINE, TIMEOUT)
            await token.auntil(lambda g: not g.put, TIMEOUT)  # the live list says so too
            back = parsed(await states.auntil(lambda g: parsed(g).online, TIMEOUT))
            await token.auntil(lambda g: g.put, TIMEOUT)
            assert not back.running and back.status.label == "ready"
            await events.text("cfw11", "left data exchange")
            await events.text("cfw11", "configured")
            await events.text("cfw11", "run command cleared: drive left online")
            assert not hub.desired("cfw11").run
            assert not weg(slave(gw, "cfw11").device).running
            diag = (await gw.diagnostics(PROFIBUS))["drives"]["cfw11"]
            assert diag["restarts"] == 1 and diag["configured"]
            # the drive next to it never noticed
            assert "left data exchange" not in " ".join(events.texts("cfw700"))
            assert at_speed(600.0)(hub.state("cfw700"))
            # a new run command, and only that, runs it again
            await gw.command("cfw11", {"run": True})
            await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT)


@contextmanager
def external_line(tmp_path: Path, buses: dict[str, dict[str, Any]]) -> Iterator[SimLine]:
    """The demo's Profibus drives simulated by the test (the gateway sees a serial port)."""
    config = parse({"buses": buses}, str(tmp_path / "line.toml"))
    yield build_line([], config)


async def test_the_serial_port_vanishing_is_reopened_with_back_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A USB RS-485 adapter unplugged and plugged back: the port (a udev-style symlink
    here) disappears; the drives go offline, the port is retried with growing pauses, and
    when it is back the line restarts with every drive stopped."""
    port = tmp_path / "ttyRS485"
    bus = {"simulate": False, "port": str(port)}
    monkeypatch.setattr(profibus_adapter_module, "REOPEN_BACKOFF", (0.1, 0.8))
    attempts: list[float] = []
    real_open = serial_link.open_link

    async def counted(*args: Any, **kwargs: Any) -> Any:
        attempts.append(now())
        return await real_open(*args, **kwargs)

    monkeypatch.setattr(serial_link, "open_link", counted)  # the real port's factory opens it
    no_action = {d: {"startup_params": {"P0313": 0}} for d in WEG}  # drives keep turning
    with external_line(tmp_path, demo_buses(new_channel(), no_action, profibus=bus)) as line:
        sim, path = SimPort.on_pty(line)
        sim.start()
        os.symlink(path, port)
        try:
            async with demo_gateway(tmp_path, no_action, profibus=bus) as gw:
                hub = gw.daemon.hub
                with Events(gw) as events:
                    await gw.command("cfw11", {"run": True, "speed_rpm": 900})
                    await gw.wait_for("cfw11", at_speed(900.0))
                    sim.close()  # unplugged
                    port.unlink()
                    for drive in ("cfw11", "cfw700", "cfw320", "mcd600"):
                        await gw.wait_for(drive, lambda s: s.comm is CommState.OFFLINE)
                    await events.text("cfw11", f"serial port {port} lost")
                    await events.text("cfw11", f"cannot open {port}")
                    first = len(attempts)
                    await until(lambda: len(attempts) >= first + 3)
                    diag = await gw.diagnostics(PROFIBUS)
                    assert diag["port_state"] == "reopening"
                    assert "No such file" in diag["port_error"]
                    gaps = [b - a for a, b in itertools.pairwise(attempts[first - 1 :])]
                    assert gaps == sorted(gaps) and gaps[-1] > 1.5 * gaps[0], gaps  # back-off
                    sim, path = SimPort.on_pty(line)  # plugged back (a new tty behind it)
                    sim.start()
                    os.symlink(path, port)
                    for drive in ("cfw11", "cfw700", "cfw320", "mcd600"):
                        await gw.wait_for(drive, lambda s: s.online)
                    assert (await gw.diagnostics(PROFIBUS))["reopens"] == 1
                    # the drive had kept turning on its own (P0313 = 0, no action); the
                    # gateway stops it, and nothing starts again without a new command
                    await events.text("cfw11", "run command cleared: drive left online")
                    await gw.wait_for("cfw11", stopped)
                    assert not hub.desired("cfw11").run
                    assert weg(line[3].device).motor.speed == 0.0
                    assert gw.daemon.runtime.restarts.get(f"bus {PROFIBUS}", 0) == 0
        finally:
            sim.close()
