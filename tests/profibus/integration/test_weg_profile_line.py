"""Issue 32 items 2 and 5 on a simulated Profibus line: adapter, master, pty, simulators.

Three CFW700 in V/f (P0202 = 0: P0684 bit 6 ignored) with the network as command source,
each left at the factory data profile P0741 = 1 (manufacturer) while its config says
PROFIdrive: one with ``verify_mapping``, one without, one whose ``startup_params`` write
P0741 = 0. The PROFIdrive idle word 045Eh is a JOG in the manufacturer profile (probes 1, 2,
5, 6 of the WEG audit): no motor may move, the written one is parameterised again and then
runs as PROFIdrive. A CFW320 with ``watchdog = 0`` is published without a fail-safe reaction.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.sim.devices import SIM_DEVICES
from adapters.profibus.sim.simulated import SimulatedLine
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.drive import Cfw700Sim, WegSim
from adapters.profibus.weg.spec import DataProfile
from gateway.adapter import EventKind
from gateway.config import DriveConfig, parse
from gateway.hub import Hub
from gateway.model import CommState, Device, DriveCommand, Source
from gateway.runtime.daemon import build_hub
from tests.support import simulated
from tests.support.heard import Heard

LIMIT = 20.0  # s: a bound on a busy machine, never a wait
PD = {"device": "CFW700", "data_profile": "profidrive"}
DRIVES: list[dict[str, Any]] = [
    {"id": "verify", "address": 3, **PD},
    {"id": "noverify", "address": 4, **PD, "verify_mapping": False},
    {"id": "written", "address": 5, **PD, "startup_params": {"P0741": 0}},
    {"id": "nowd", "address": 6, "device": "CFW320", "watchdog": 0},
]
CFW700S = {"verify": 3, "noverify": 4, "written": 5}


class FactoryProfileCfw700(Cfw700Sim):
    """A CFW700 at factory P0741 = 1 whatever its config says, in V/f, network sources."""

    @classmethod
    def for_drive(cls, drive: DriveConfig | None) -> WegSim:
        sim = super().for_drive(drive)
        sim.values.update({**sp.NETWORK_SOURCES, 741: 1, 202: 0, 100: 10, 101: 10, 313: 1})
        sim.set_prm(b"")  # powered up with that programming
        return sim


@contextlib.asynccontextmanager
async def line() -> AsyncIterator[tuple[Hub, ProfibusAdapter]]:
    table = {"adapter": "profibus", "simulate": True, "latency": 0.02, "drives": DRIVES}
    config = parse({"buses": {"profibus": table}}, "weg-profile-line.toml")
    hub = build_hub(config)
    here = f"{__name__}:FactoryProfileCfw700"
    links = SimulatedLine(config.buses[0], {**SIM_DEVICES, Device.CFW700: here})
    adapter = ProfibusAdapter(config.buses[0], links=links)
    task = asyncio.create_task(adapter.run(hub))
    try:
        yield hub, adapter
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def sims(adapter: ProfibusAdapter) -> dict[str, WegSim]:
    sim_line = simulated.sim_line(adapter)
    assert sim_line is not None
    out = {}
    for drive_id, address in CFW700S.items():
        device = sim_line[address].device
        assert isinstance(device, WegSim)
        out[drive_id] = device
    return out


async def test_no_profidrive_word_moves_a_drive_still_in_the_manufacturer_profile() -> None:
    async with line() as (hub, adapter):
        with hub.subscribe_events() as events:
            async with asyncio.timeout(LIMIT):
                await adapter.claimed.wait()  # the port opened: the simulated line runs
                drives = sims(adapter)
                sim_line = simulated.sim_line(adapter)
                assert sim_line is not None
                # the motors are watched after every telegram until the written drive is
                # back online and the two mismatched ones had 40 more data exchanges
                done_at: int | None = None
                with Heard(*(s.counters for s in sim_line.slaves.values())) as heard:
                    while True:
                        for drive_id, sim in drives.items():
                            assert sim.motor.speed == 0.0, f"{drive_id} moves: {sim.net}"
                            assert not sim.net.jog, f"{drive_id} jogs"
                        exchanges = min(sim_line[a].counters.exchanges for a in (3, 4))
                        if done_at is None and hub.state("written").comm is CommState.ONLINE:
                            done_at = exchanges + 40
                        if done_at is not None and exchanges >= done_at:
                            break
                        await heard.next()
            said = [e for e in events.drain() if e.drive_id == "written"]
        diag = adapter.diagnostics()["drives"]
        assert not diag["verify"]["configured"] and not diag["noverify"]["configured"]
        assert "P0741 = 1" in str(diag["noverify"]["not_configured_reason"])
        assert diag["written"]["configured"]
        assert drives["written"].data_profile is DataProfile.PROFIDRIVE
        assert any(e.kind is EventKind.PARAMETER and "P0741 written" in e.text for e in said)
        # the written drive speaks PROFIdrive now: a run runs, a stop stops
        hub.submit("written", Source.ZENOH, DriveCommand(run=True, speed_rpm=600.0), "scada")
        async with asyncio.timeout(LIMIT):
            await hub.wait_for("written", lambda s: s.running and (s.speed_rpm or 0) > 300)
        hub.submit("written", Source.ZENOH, DriveCommand(run=False), "scada")
        async with asyncio.timeout(LIMIT):
            await hub.wait_for("written", lambda s: not s.running)


async def test_watchdog_off_is_no_failsafe() -> None:
    async with line() as (hub, _adapter):
        async with asyncio.timeout(LIMIT):
            state = await hub.wait_for("nowd", lambda s: s.failsafe is not None)
    assert state.failsafe is False
    assert str(state.failsafe_text).startswith("watchdog = 0: the DP watchdog is off")
    assert "P313 = 1: ramp stop" in str(state.failsafe_text)
