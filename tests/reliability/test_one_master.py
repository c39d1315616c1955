"""One master per line (safety rule 3, issue 17 item 7): a gateway holds its lines, and a
second master is refused before it sends anything.

* Profibus: the demo's WEG drives simulated by the test on a pty (they outlive either
  gateway), a gateway in-process running the CFW-11 at 900 rpm. A second gateway process
  on the same line, and ``drive-gateway profibus scan`` on its port, are refused, naming
  the holder (this process); the motor keeps turning, the line is never disturbed.
* DeviceNet: the demo's CFW-08 on a virtual CAN channel, a gateway in-process running it;
  a second daemon on the same config finds the scanner's MAC ID 0 answered (Duplicate MAC
  ID check, fact sheet 2.3) and does not start.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from adapters.profibus.cli import build_line
from adapters.profibus.link import open_port
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.port import SimPort
from adapters.profibus.weg.sim.drive import WegSim
from gateway.config import load, parse
from gateway.model import CommState
from gateway.runtime.daemon import EXIT_LINE_HELD, Daemon
from gateway.runtime.systemd import Notifier
from tests.e2e.harness import Gateway, running_gateway
from tests.reliability.demo import (
    ADDRESSES,
    CANOPEN,
    DEVICENET,
    PROFIBUS,
    WEG,
    Events,
    at_speed,
    demo_buses,
    new_channel,
    toml_buses,
)

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT = 30.0  # s: a gateway process on a loaded machine
NO_FRONT_ENDS = "[zenoh]\nenabled = false\n[modbus]\nenabled = false\n"
# Reply waits and DP watchdog long enough that a loaded machine starting a process beside
# the test (the event loop here lags by up to 0.2 s) loses no slave: what would disturb
# the line is then a second master only.
TOLERANT = {"latency": 0.5, "watchdog": 3.0}


@dataclass
class HeldLine:
    gw: Gateway
    line: SimLine
    sim: SimPort
    port: Path  # the gateway's configured port: a symlink to the pty
    buses: dict[str, dict[str, Any]]

    def weg(self, drive: str) -> WegSim:
        device = self.line[ADDRESSES[drive]].device
        assert isinstance(device, WegSim)
        return device


@contextlib.asynccontextmanager
async def profibus_gateway(tmp_path: Path) -> AsyncIterator[HeldLine]:
    """The demo's Profibus line simulated by the test on a pty; the gateway in-process on
    it, with the CFW-11 running at 900 rpm."""
    port = tmp_path / "ttyRS485"
    buses = demo_buses(new_channel(), profibus={"simulate": False, "port": str(port), **TOLERANT})
    del buses[DEVICENET]
    line = build_line([], parse({"buses": buses}, str(tmp_path / "line.toml")))
    sim, path = SimPort.on_pty(line)
    sim.start()
    try:
        os.symlink(path, port)
        async with running_gateway(tmp_path, lambda: toml_buses(buses), list(WEG)) as gw:
            held = HeldLine(gw, line, sim, port, buses)
            await gw.command("cfw11", {"run": True, "speed_rpm": 900})
            await gw.wait_for("cfw11", at_speed(900.0))
            yield held
    finally:
        sim.close()


async def run_process(*args: str, within: float = START_TIMEOUT) -> tuple[int, str]:
    """``python -m gateway ARGS``: its exit status and its stderr."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("NOTIFY_SOCKET", None)
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "gateway",
        *args,
        cwd=ROOT,
        env=env,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        async with asyncio.timeout(within):
            _, err = await proc.communicate()
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode is not None
    return proc.returncode, err.decode()


def undisturbed(held: HeldLine, events: Events) -> None:
    """The first gateway's line as it was: the CFW-11 online at 900 rpm, no slave lost."""
    state = held.gw.daemon.hub.state("cfw11")
    assert state.online and at_speed(900.0)(state), (state, events.texts())
    assert held.weg("cfw11").motor.speed == pytest.approx(900.0, abs=1.0)  # 13-bit speed word
    lost = {d: held.line[ADDRESSES[d]].counters.comm_lost for d in WEG}
    assert not any(lost.values()), (lost, events.texts())
    assert not [t for t in events.texts() if "offline" in t or "lost" in t], events.texts()


def holder_named(text: str, port: Path) -> None:
    assert f"serial port {port} is held by pid {os.getpid()} (" in text, text
    assert "another master is on this line" in text, text


async def test_a_second_gateway_on_a_held_port_refuses_to_start(tmp_path: Path) -> None:
    async with profibus_gateway(tmp_path) as held:
        second = tmp_path / "second.toml"
        second.write_text(NO_FRONT_ENDS + toml_buses(held.buses))  # the same line
        with Events(held.gw) as events:
            status, log = await run_process("run", "--config", str(second))
            assert status == EXIT_LINE_HELD, log
            errors = [line for line in log.splitlines() if " ERROR " in line]
            assert len(errors) == 1, log  # one line: the port, the holder, what to do
            holder_named(errors[0], held.port)
            assert "bus profibus:" in errors[0] and "does not start (exit status 75)" in errors[0]
            assert "Traceback" not in log, log
            assert not re.search(r"drive-gateway \S+ running:", log), log  # never READY
            undisturbed(held, events)


async def test_profibus_scan_on_a_running_gateways_port_is_refused(tmp_path: Path) -> None:
    async with profibus_gateway(tmp_path) as held:
        baud = str(held.buses[PROFIBUS]["baudrate"])
        with Events(held.gw) as events:
            status, err = await run_process(
                "profibus", "scan", "--port", str(held.port), "--baud", baud
            )
            assert status == 1, err
            assert err.count("\n") == 1 and err.startswith("error: serial port"), err
            holder_named(err, held.port)
            undisturbed(held, events)


async def test_a_port_taken_while_ours_was_gone_is_waited_for(tmp_path: Path) -> None:
    """Once running, the gateway does not stop over its port: unplugged, then held by
    another process when it comes back, it is retried (the holder named in the events)
    and taken once that process lets it go."""
    async with profibus_gateway(tmp_path) as held:
        gw, port = held.gw, held.port
        with Events(gw) as events:
            held.sim.close()  # unplugged
            port.unlink()
            await gw.wait_for("cfw11", lambda s: s.comm is CommState.OFFLINE)
            sim, path = SimPort.on_pty(held.line)  # plugged back, but another process has it
            other = open_port(path, 500000)
            try:
                sim.start()
                os.symlink(path, port)
                ev = await events.text("cfw11", f"serial port {port} is held by pid {os.getpid()}")
                assert "another master is on this line" in ev.text
                diag = await gw.diagnostics(PROFIBUS)
                assert diag["port_state"] == "reopening" and "held by" in diag["port_error"]
                assert not gw.daemon.hub.state("cfw11").online
            finally:
                other.close()
            try:
                for drive in WEG:
                    await gw.wait_for(drive, lambda s: s.online)
                assert gw.daemon.exit_status == 0 and not gw.daemon.runtime.restarts
            finally:
                sim.close()


async def test_a_second_scanner_on_the_same_can_channel_does_not_start(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    buses = demo_buses(new_channel())
    # The DeviceNet line alone: the second daemon runs in this process, on the first one's
    # event loop, and starting a CANopen line there too (its EDS read, simulated nodes)
    # stalled that loop under load (once: 705 ms without a CANopen heartbeat, the CFW-08
    # past its 4 x EPR, so it came back online stopped, as the safety rules want).
    del buses[PROFIBUS], buses[CANOPEN]
    async with running_gateway(tmp_path, lambda: toml_buses(buses), ["cfw08"]) as gw:
        await gw.command("cfw08", {"run": True, "speed_rpm": 900})
        await gw.wait_for("cfw08", at_speed(900.0))
        second = tmp_path / "second.toml"
        second.write_text(NO_FRONT_ENDS + toml_buses(buses))  # the same line, simulated too
        daemon = Daemon(load(second), notifier=Notifier({}))
        with Events(gw) as events, caplog.at_level(logging.INFO):
            caplog.clear()
            status = await asyncio.wait_for(daemon.run(), START_TIMEOUT)
            assert status == EXIT_LINE_HELD
            assert not daemon.ready.is_set()  # READY waits for the check: never reported
            errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
            assert len(errors) == 1 and errors[0].exc_info is None, caplog.text
            text = errors[0].getMessage()
            assert f"DeviceNet virtual channel {buses[DEVICENET]['channel']}" in text, text
            assert "scanner MAC ID 0 is taken on the line" in text, text
            assert "another instance of this gateway" in text, text
            assert "does not start (exit status 75)" in text, text
            # the first scanner answered the check and kept its drive running
            await events.text("cfw08", "tried to claim the scanner's MAC ID 0")
            state = gw.daemon.hub.state("cfw08")
            assert state.online and at_speed(900.0)(state), state
            assert not [t for t in events.texts("cfw08") if "offline" in t], events.texts()
        # the second never allocated a node: the first still holds the CFW-08's connections
        assert not daemon.hub.state("cfw08").online
