"""The gateway as a process (``python -m gateway run``): SIGHUP with a bad config file, and
SIGKILL followed by a restart.

SIGHUP reloads nothing (docs/decisions/0007-no-reload.md: a restart is the way): the gateway keeps
running on the configuration it started with, checks the file on disk and logs what a
restart would meet. SIGKILL gives the gateway no chance to stop anything: the drives do
what their own settings say (P0313) while no master talks to them, and the restarted
gateway brings every drive back stopped, whatever the clients keep writing.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from pymodbus.client import AsyncModbusTcpClient

from adapters.profibus.cli import build_line
from adapters.profibus.sim.port import SimPort
from adapters.profibus.weg.sim.drive import WegSim
from gateway.config import parse
from tests.e2e.harness import PREFIX, RUN, TIMEOUT, header
from tests.reliability.demo import (
    ADDRESSES,
    DRIVES,
    PROFIBUS,
    UNITS,
    WEG,
    demo_buses,
    new_channel,
    toml_buses,
    until,
)
from tests.support.net import free_port, zenoh_endpoint
from tests.zenoh.client import Client, Got, Inbox

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT = 30.0  # s: a gateway process on a loaded machine


class GatewayProcess:
    """``python -m gateway run --config FILE``; its log (stderr) read by a thread."""

    def __init__(self, config: Path) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        env.pop("NOTIFY_SOCKET", None)
        cmd = [sys.executable, "-m", "gateway", "run", "--config", str(config)]
        cmd += ["--zenoh-endpoint", zenoh_endpoint()]
        self.proc = subprocess.Popen(
            cmd, cwd=ROOT, env=env, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        self.log: list[str] = []
        self._lines: asyncio.Queue[str] = asyncio.Queue()
        self._loop = asyncio.get_running_loop()
        self._reader = threading.Thread(target=self._read, name="gateway-log", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.log.append(line)
            self._hand_over(line)
        self._hand_over("")

    def _hand_over(self, line: str) -> None:
        with contextlib.suppress(RuntimeError):  # the test's loop has closed
            self._loop.call_soon_threadsafe(self._lines.put_nowait, line)

    async def line(self, text: str, within: float = START_TIMEOUT) -> str:
        """The next log line holding ``text`` (handed over by the thread reading the log)."""
        async with asyncio.timeout(within):
            while True:
                line = await self._lines.get()
                if not line:
                    raise AssertionError(f"the gateway exited before {text!r}:\n{self.text()}")
                if text in line:
                    return line

    def text(self) -> str:
        return "".join(self.log)

    def alive(self) -> bool:
        return self.proc.poll() is None

    async def wait(self, within: float = TIMEOUT) -> int:
        async with asyncio.timeout(within):
            while (code := self.proc.poll()) is None:  # noqa: ASYNC110
                await asyncio.sleep(0.02)
        self._reader.join(5)
        return code

    def kill(self) -> None:
        if self.alive():
            self.proc.kill()
        self.proc.wait()
        self._reader.join(5)


@contextlib.asynccontextmanager
async def gateway_process(config: Path) -> AsyncIterator[GatewayProcess]:
    gw = GatewayProcess(config)
    try:
        yield gw
    finally:
        gw.kill()


async def live_tokens(client: Client, drives: tuple[str, ...]) -> None:
    """Every drive's liveliness token is there."""
    with client.liveliness(f"{PREFIX}/drives/*") as live:
        seen: set[str] = set()
        while not seen >= set(drives):
            got = await live.aget(START_TIMEOUT)
            if got.put:
                seen.add(got.key.rsplit("/", 1)[-1])


async def state_until(inbox: Inbox[Got], predicate: Callable[[dict[str, Any]], bool]) -> Any:
    return (await inbox.auntil(lambda g: predicate(g.json()), TIMEOUT)).json()


# ---------------------------------------------------------------- SIGHUP


async def test_sighup_with_a_bad_file_neither_stops_nor_changes_the_gateway(
    tmp_path: Path,
) -> None:
    cfg = tmp_path / "site.toml"
    client_endpoint = zenoh_endpoint()
    good = header(free_port(), client_endpoint) + toml_buses(demo_buses(new_channel()))
    cfg.write_text(good)
    client = Client(client_endpoint, asyncio.get_running_loop(), listen=True)
    try:
        async with gateway_process(cfg) as gw:
            await gw.line("zenoh front end serving")
            await live_tokens(client, DRIVES)
            with client.subscribe(f"{PREFIX}/drives/cfw08/state") as states:
                await client.settled(PREFIX)
                command = {"run": True, "speed_rpm": 600}
                reply = await client.aone(f"{PREFIX}/drives/cfw08/command", command)
                assert reply.json() == {"accepted": True}
                await state_until(states, lambda s: s["running"])

                # a bad file, then SIGHUP: the file is checked, nothing else happens
                cfg.write_text(good.replace('bind = "127.0.0.1:', 'bind = "nowhere:x'))
                gw.proc.send_signal(signal.SIGHUP)
                line = await gw.line("SIGHUP")
                assert "configuration is not reloaded" in line
                assert f"{cfg}: modbus.bind: 'nowhere:x" in line and "is not HOST:PORT" in line
                # a good but different file (one drive fewer): checked, not applied
                cfg.write_text(good.replace('id = "cfw08"', 'id = "renamed"'))
                gw.proc.send_signal(signal.SIGHUP)
                line = await gw.line("SIGHUP")
                assert f"checks ok: {len(DRIVES)} drive(s); restart the gateway to apply it" in line
                assert gw.alive()
                health = (await client.aone(f"{PREFIX}/gateway/health")).json()
                assert (health["drives"], health["online"]) == (len(DRIVES), len(DRIVES))
                state = await state_until(states, lambda s: True)
                assert (state["id"], state["comm"], state["running"]) == ("cfw08", "online", True)
                assert not (await client.aone(f"{PREFIX}/drives/renamed/state")).ok
            gw.proc.send_signal(signal.SIGTERM)
            assert await gw.wait() == 0
            assert "cfw08: safety: gateway shutting down: ramp_stop applied" in gw.text()
            assert "Traceback" not in gw.text()
    finally:
        client.close()


# ---------------------------------------------------------------- SIGKILL


class Plc:
    """A PLC writing its command block cyclically (speed, then the word), reconnecting
    whenever the gateway is not there: what a real PLC keeps doing through a restart."""

    def __init__(self, port: int, unit: int, speed: int) -> None:
        self.port, self.unit, self.speed = port, unit, speed
        self.word = 0
        self.writes_ok = 0
        self._task: asyncio.Task[None] | None = None

    async def _run(self) -> None:
        while True:
            client = AsyncModbusTcpClient(
                "127.0.0.1", port=self.port, reconnect_delay=0, retries=0, timeout=1.0
            )
            try:
                if await client.connect():
                    while client.connected:
                        await client.write_register(1, self.speed, device_id=self.unit)
                        await client.write_register(0, self.word, device_id=self.unit)
                        self.writes_ok += 1
                        await asyncio.sleep(0.05)
            except Exception:  # the gateway went away: reconnect, as a PLC does
                pass
            finally:
                client.close()
            await asyncio.sleep(0.1)

    def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="plc")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task


def weg(line: Any, drive: str) -> WegSim:
    device = line[ADDRESSES[drive]].device
    assert isinstance(device, WegSim)
    return device


async def test_sigkill_and_restart_bring_every_drive_back_stopped(tmp_path: Path) -> None:
    """The Profibus drives are simulated by the test on a pty, so they outlive the gateway."""
    loop = asyncio.get_running_loop()
    port = tmp_path / "ttyRS485"
    # the worst case: each drive keeps its last command while no master talks to it
    no_action = {d: {"startup_params": {"P0313": 0}} for d in WEG}
    buses = demo_buses(new_channel(), no_action, profibus={"simulate": False, "port": str(port)})
    del buses["devicenet"]  # a virtual CAN bus cannot be shared with another process
    line = build_line([], parse({"buses": buses}, str(tmp_path / "line.toml")))
    sim, path = SimPort.on_pty(line)
    sim.start()
    os.symlink(path, port)
    modbus_port, client_endpoint = free_port(), zenoh_endpoint()
    cfg = tmp_path / "site.toml"
    cfg.write_text(header(modbus_port, client_endpoint) + toml_buses(buses))
    client = Client(client_endpoint, loop, listen=True)
    plc = Plc(modbus_port, UNITS["cfw700"], 900)
    profibus_drives = tuple(d["id"] for d in buses[PROFIBUS]["drives"])
    cfw11, cfw700 = weg(line, "cfw11"), weg(line, "cfw700")
    try:
        plc.start()
        async with gateway_process(cfg) as gw:
            await live_tokens(client, profibus_drives)
            reply = await client.aone(
                f"{PREFIX}/drives/cfw11/command", {"run": True, "speed_rpm": 900}
            )
            assert reply.json() == {"accepted": True}
            await until(lambda: plc.writes_ok > 2)
            plc.word = RUN  # the PLC's run: after its word 0, an edge
            await until(lambda: cfw11.motor.speed == 900.0 and cfw700.motor.speed == 900.0)
            gw.proc.send_signal(signal.SIGKILL)
            assert await gw.wait() == -signal.SIGKILL
        # No master: after the DP watchdog (0.5 s) each drive applies its P0313; with 0 (no
        # action, the factory setting) they keep turning.
        await until(lambda: line[ADDRESSES["cfw11"]].counters.comm_lost >= 1)
        assert cfw11.running and cfw700.running
        writes_before = plc.writes_ok
        async with gateway_process(cfg) as gw:
            await live_tokens(client, profibus_drives)
            # back under the gateway every drive is stopped, though the PLC keeps
            # writing run (its first word to a new gateway never starts a drive)
            await until(lambda: cfw11.motor.speed == 0.0 and cfw700.motor.speed == 0.0)
            await until(lambda: plc.writes_ok > writes_before + 10)
            assert not cfw11.running and not cfw700.running
            for drive in profibus_drives:
                state = (await client.aone(f"{PREFIX}/drives/{drive}/state")).json()
                assert (state["comm"], state["running"]) == ("online", False), state
            # new commands, and only they, run the drives again
            command = {"run": True, "speed_rpm": 900}
            reply = await client.aone(f"{PREFIX}/drives/cfw11/command", command)
            assert reply.json() == {"accepted": True}
            plc.word = 0  # the PLC's edge: its 0 must reach the gateway before its run
            zero_from = plc.writes_ok
            await until(lambda: plc.writes_ok > zero_from + 2)
            plc.word = RUN
            await until(lambda: cfw11.motor.speed == 900.0 and cfw700.motor.speed == 900.0)
            gw.proc.send_signal(signal.SIGTERM)
            assert await gw.wait() == 0
        assert line[ADDRESSES["cfw11"]].counters.clears >= 1  # left the line with Clear
    finally:
        await plc.stop()
        client.close()
        sim.close()
