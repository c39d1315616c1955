"""``/metrics`` read with prometheus_client's own parser, and the JSON API, from the demo
daemon (config/demo.toml) with its real buses, a real Modbus client and a Zenoh client."""

from __future__ import annotations

import asyncio
import itertools
from pathlib import Path

from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.samples import Sample
from pymodbus.client import AsyncModbusTcpClient

from gateway.web.metrics import METRICS
from gateway.web.views import BUS_FIGURES, figures
from tests.support.timing import scaled
from tests.web.harness import DEMO_DRIVES, ROOT, TIMEOUT, Demo, demo_daemon

PROCESS = ("process_cpu_seconds", "process_resident_memory_bytes", "process_open_fds")


_TICKS = itertools.count()


async def scrape(demo: Demo) -> dict[str, list[Sample]]:
    # each scrape a second after the last as the snapshot sees it: a fresh render, for the
    # test reads counters it has just moved (one render per web.metrics_max_age otherwise)
    demo.web.metrics.clock = lambda: float(next(_TICKS))
    async with demo.http.get(f"{demo.url}metrics") as r:
        assert r.status == 200
        assert r.headers["Content-Type"].startswith("text/plain; version=")
        text = await r.text()
    out: dict[str, list[Sample]] = {}
    for family in text_string_to_metric_families(text):
        out[family.name] = list(family.samples)
    return out


def value(samples: dict[str, list[Sample]], name: str, **labels: str) -> float:
    found = [
        s.value
        for s in samples[name]
        if s.name in (name, f"{name}_total")
        and all(s.labels.get(k) == v for k, v in labels.items())
    ]
    assert len(found) == 1, (name, labels, found)
    return found[0]


async def cycles_measured(demo: Demo, buses: tuple[str, ...]) -> None:
    """Until each line's figures (built on its own loop every 0.25 s) have a cycle in them."""
    async with asyncio.timeout(scaled(10.0)):
        for bus in buses:
            line = demo.line(bus)
            while not figures(line.diagnostics(), BUS_FIGURES).get("cycle_last_ms"):
                await line.next_diagnostics()


async def new_figures(demo: Demo) -> None:
    """Until every line has built its figures again."""
    async with asyncio.timeout(scaled(10.0)):
        for bus in ("profibus", "devicenet", "canopen"):
            await demo.line(bus).next_diagnostics()


async def test_every_documented_metric_is_there_and_the_counters_move() -> None:
    async with demo_daemon() as demo:
        await cycles_measured(demo, ("profibus", "devicenet"))
        first = await scrape(demo)
        for name in METRICS:
            assert name in first or f"{name}_info" in first, name
        for name in PROCESS:
            assert name in first, name
        for drive in DEMO_DRIVES:
            assert value(first, "drive_gateway_drive_online", drive=drive) == 1.0
        assert value(first, "drive_gateway_drive_speed_rpm", drive="cfw11") == 0.0
        assert value(first, "drive_gateway_drive_current_flc_ratio", drive="mcd600") >= 0.0
        for bus in ("profibus", "devicenet"):
            assert value(first, "drive_gateway_bus_cycle_seconds", bus=bus, stat="last") > 0
            assert value(first, "drive_gateway_bus_live_stations", bus=bus) >= 1
        assert (
            value(first, "drive_gateway_station_response_seconds", drive="cfw11", stat="last") > 0
        )

        # traffic: Modbus reads, a refused and an accepted Zenoh command
        port = demo.daemon.config.modbus.port
        modbus = AsyncModbusTcpClient("127.0.0.1", port=port, retries=0, timeout=TIMEOUT)
        assert await modbus.connect()
        try:
            for _ in range(3):
                rr = await modbus.read_input_registers(0, count=21, device_id=1)
                assert not rr.isError()
        finally:
            modbus.close()
        reply = await demo.client.aone(
            "demo/drives/cfw11/command", {"run": True, "fault_reset": True}
        )
        assert reply.json()["accepted"] is False
        await demo.command("cfw11", {"run": True, "speed_rpm": 600})
        # running, and the reference reported back: bus cycles went by since the first scrape
        await demo.wait_for(
            "cfw11",
            lambda s: s.running and s.speed_ref_rpm is not None and abs(s.speed_ref_rpm - 600) < 1,
        )
        await new_figures(demo)
        second = await scrape(demo)
        moved = {
            "drive_gateway_modbus_requests": (),
            "drive_gateway_bus_cycles": (("bus", "profibus"),),
            "drive_gateway_zenoh_requests": (("kind", "query"),),
        }
        for name, labels in moved.items():
            assert value(second, name, **dict(labels)) > value(first, name, **dict(labels)), name
        assert value(second, "drive_gateway_modbus_requests") >= 3
        assert value(second, "drive_gateway_zenoh_commands", result="accepted") == 1
        assert value(second, "drive_gateway_zenoh_commands", result="refused") == 1
        assert value(second, "drive_gateway_drive_running", drive="cfw11") == 1.0
        turning = [
            value(second, "drive_gateway_drive_status", drive="cfw11", status=s)
            for s in ("starting", "running")
        ]
        assert sum(turning) == 1.0  # accelerating or at speed, one of the two
        # the reference as the drive reports it back (its 13-bit or 0x4000 scale)
        assert (
            abs(value(second, "drive_gateway_drive_speed_reference_rpm", drive="cfw11") - 600) < 1
        )


async def test_the_json_api_for_scripts() -> None:
    async with demo_daemon() as demo:
        await cycles_measured(demo, ("profibus", "devicenet"))
        async with demo.http.get(f"{demo.url}api/health") as r:
            assert r.status == 200 and r.content_type == "application/json"
            health = await r.json()
        assert health["name"] == "demo" and health["drives"] == 7 and health["online"] == 7
        assert set(health["buses"]) == {"profibus", "devicenet", "canopen"}
        assert health["buses"]["profibus"]["live"] == ["cfw11", "cfw700", "cfw320", "mcd600"]
        async with demo.http.get(f"{demo.url}api/drives") as r:
            drives = (await r.json())["drives"]
        assert [d["id"] for d in drives] == list(DEMO_DRIVES)
        for d in drives:
            assert d["comm"] == "online" and "desired" in d and "current_unit" in d
        async with demo.http.get(f"{demo.url}api/drives/cfw08") as r:
            assert (await r.json())["device"] == "CFW-08"
        async with demo.http.get(f"{demo.url}api/drives/nope") as r:
            assert r.status == 404 and "nope" in (await r.json())["error"]
        async with demo.http.get(f"{demo.url}api/buses") as r:
            buses = {b["name"]: b for b in (await r.json())["buses"]}
        assert (
            len(buses["profibus"]["stations"]) == 4
            and "cycle_last_ms" in buses["devicenet"]["figures"]
        )
        await demo.command("cfw08", {"run": True, "speed_rpm": 300})
        async with asyncio.timeout(TIMEOUT):
            while True:
                async with demo.http.get(f"{demo.url}api/history/cfw08") as r:
                    history = await r.json()
                if 300.0 in history["ref"]:
                    break
                await asyncio.sleep(0.25)
        assert history["period"] == 0.5 and history["span"] == 600.0
        async with demo.http.get(f"{demo.url}api/events") as r:
            events = (await r.json())["events"]
        assert any(e["kind"] == "command" and e["drive"] == "cfw08" for e in events)


def test_operations_md_lists_every_metric() -> None:
    text = (ROOT / "docs" / "operations.md").read_text()
    missing = [name for name in METRICS if f"`{name}" not in text]
    assert not missing, missing
    assert Path(ROOT / "docs" / "operations.md").exists()
