"""Drives configured from GSD files reach data exchange with simulators configured from the
same files, through bytes that come from the files; a wrong module is a Cfg_Fault whose
event says why (issue 20, "Done means")."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.cli import build_line
from adapters.profibus.sim.gsdsim import GsdSim
from adapters.profibus.sim.port import SimPort
from gateway.adapter import EventKind
from gateway.config import parse
from gateway.hub import Hub
from gateway.model import CommState
from gateway.runtime.daemon import build_hub
from tests.support import simulated

GSD_DIR = Path(__file__).resolve().parents[2] / "data" / "gsd"
CONFIG = str(GSD_DIR / "site.toml")  # GSD paths are relative to the config file

DRIVES: list[dict[str, Any]] = [
    {
        "id": "cfw11",
        "device": "CFW-11",
        "address": 3,
        "gsd": "TEST_CFW11.gsd",
        "module": "4 words I/O (P0922 = 3)",
        "words": 4,
        "prm": {"Test: start delay": 7, "Test: diagnosis alarm": "desligado"},
    },
    {
        "id": "cfw700",
        "device": "CFW700",
        "address": 4,
        "gsd": "TEST_CFW700.gsd",
        "module": "2 words I/O",
        "prm": {"Test: reaction to Clear": "coast", "Test: word limit": 1500},
    },
    {
        "id": "cfw320",
        "device": "CFW320",
        "address": 5,
        "gsd": "TEST_CFW320.gsd",
        "modules": ["Control and speed (2 words I/O)", "Extra word I/O", "Extra word I/O"],
        "words": 4,
        "prm": {"Test: extra word filter": -3},
    },
    {
        "id": "mcd600",
        "device": "MCD 600",
        "address": 6,
        "gsd": "TEST_MCD600.gsd",
        "module": "Extended mode",
        "mode": "extended",
        "prm": {"Communication timeout": 30},
    },
]


@contextlib.asynccontextmanager
async def running(
    drives: list[dict[str, Any]], port: str | None = None
) -> AsyncIterator[tuple[ProfibusAdapter, Hub]]:
    table: dict[str, Any] = {"adapter": "profibus", "latency": 0.02, "drives": drives}
    table.update({"port": port} if port else {"simulate": True})
    config = parse({"buses": {"profibus": table}}, CONFIG)
    hub = build_hub(config)
    adapter = simulated.profibus(ProfibusAdapter, config.buses[0])
    hub.attach_params([d["id"] for d in drives], adapter)
    task = asyncio.create_task(adapter.run(hub))
    try:
        yield adapter, hub
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_every_device_from_its_gsd_reaches_data_exchange_with_the_files_bytes() -> None:
    async with running(DRIVES) as (adapter, hub):
        async with asyncio.timeout(10):
            for d in DRIVES:
                await hub.wait_for(d["id"], lambda s: s.comm is CommState.ONLINE)
        line = simulated.sim_line(adapter)
        assert line is not None
        sims = {a: s for a in (3, 4, 5, 6) if isinstance(s := line[a].device, GsdSim)}
        assert len(sims) == 4  # every simulated drive judges by its GSD
        # the bytes came from the files, not from the built-in F0h + n-1 guesses
        assert sims[3].modules is not None and sims[3].modules[0].name.startswith("4 words")
        params = {p.address: p for p in adapter.master.slave_params()}
        assert params[3].cfg == bytes.fromhex("C0C3C3")
        assert params[3].ident_number == 0x0C11
        assert params[3].user_prm == bytes([0x00, 7])  # bit 0 off by PrmText, delay 7
        assert params[4].cfg == bytes.fromhex("C0C1C1")
        assert params[4].user_prm == bytes([0x01, 0x05, 0xDC])  # coast = 1, 1500
        assert params[5].cfg == bytes.fromhex("C0C1C1F0F0")
        assert params[5].user_prm == bytes([0x00, 0xFD, 0xFD])  # one byte per extra word
        assert params[6].cfg == bytes.fromhex("F0A093")
        assert params[6].user_prm == bytes([30]) and not params[6].dpv1
        starter = sims[6].device
        assert isinstance(starter, Mcd600Sim) and starter.comm_timeout == 30  # from Set_Prm


async def test_a_wrong_module_is_a_cfg_fault_whose_event_names_the_bytes_and_the_module() -> None:
    """The drive is programmed for 2 words (P0922 = 1, its simulator configured so from the
    same GSD); the gateway's config names the 4-word module: Cfg_Fault, and the event says
    which bytes went out, what the slave has, and which GSD module they came from."""
    slave = dict(DRIVES[1], module="2 words I/O")
    sim_config = parse(
        {"buses": {"pb": {"adapter": "profibus", "simulate": True, "drives": [slave]}}}, CONFIG
    )
    line = build_line([], sim_config)
    sim, path = SimPort.on_pty(line)
    sim.start()
    try:
        drive = dict(DRIVES[1], module="4 words I/O", words=4)
        async with running([drive], port=path) as (_adapter, hub):
            with hub.subscribe_events() as events:
                async with asyncio.timeout(10):
                    event = await events.get()
                    while event.kind is not EventKind.CONFIG:
                        event = await events.get()
            assert hub.state("cfw700").comm is not CommState.ONLINE
    finally:
        sim.close()
    assert event.text == (
        "Cfg_Fault: the slave refused the configuration C0 C3 C3 (8 bytes in, 8 bytes out); "
        "it has C0 C1 C1 (4 bytes in, 4 bytes out); "
        f"sent as GSD {GSD_DIR / 'TEST_CFW700.gsd'}, module '4 words I/O' says; "
        "the slave's configuration is GSD module '2 words I/O': configure that, or program "
        "the drive for the one sent"
    )
    refusing = line[4].device
    assert isinstance(refusing, GsdSim)
    assert refusing.refusal == "modules ['4 words I/O'] do not fit the telegram (4, 4)"


async def test_a_prm_fault_event_names_the_user_data_sent_and_where_it_came_from() -> None:
    drive = {"id": "cfw700", "device": "CFW700", "address": 4, "user_prm": [1, 2]}
    async with running([drive]) as (_adapter, hub):
        with hub.subscribe_events() as events:
            async with asyncio.timeout(10):
                event = await events.get()
                while event.kind is not EventKind.CONFIG:
                    event = await events.get()
    assert event.text == (
        "Prm_Fault: the slave refused the parameters (Ident_Number 0x0C70, 2 bytes of user "
        "parameters: 01 02); sent as user_prm of the drive's config says"
    )
