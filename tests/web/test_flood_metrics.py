"""The flood counters of ``/metrics`` (gateway/web/floodmetrics.py): each moves when its
flood comes. The collector on its own against lines' figures, then the demo daemon scraped
while its lines and its web page are flooded: forged EMCY frames on the CANopen line,
Duplicate MAC ID requests for the DeviceNet scanner's MAC, a burst of events bigger than a
line's hand-over holds, wrong command tokens."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import can
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.parser import text_string_to_metric_families

from adapters.canopen.codec import frames as co
from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind
from gateway.adapter import EventKind
from gateway.runtime.lineport import OUTBOX_EVENTS
from gateway.web.counters import WebCounters
from gateway.web.floodmetrics import FLOOD_METRICS, FloodCollector
from gateway.web.metrics import METRICS
from gateway.webconfig import WebLimits
from tests.support.timing import scaled
from tests.web.harness import TOKEN_SHA256, Demo, demo_daemon, web_section
from tests.web.test_metrics_api import scrape, value

EMCY_FLOOD = 200
DUPMAC_FLOOD = 40
WRONG_TOKENS = 3


class Line:
    def __init__(self, diag: dict[str, Any]) -> None:
        self.diag = diag

    def diagnostics(self) -> dict[str, Any]:
        return self.diag


def collected(collector: FloodCollector) -> dict[str, dict[tuple[tuple[str, str], ...], float]]:
    registry = CollectorRegistry(auto_describe=False)
    registry.register(collector)
    out: dict[str, dict[tuple[tuple[str, str], ...], float]] = {}
    for family in text_string_to_metric_families(generate_latest(registry).decode()):
        out[family.name] = {
            tuple(sorted(s.labels.items())): s.value
            for s in family.samples
            if s.name.endswith("_total")
        }
    return out


def test_the_collector_reads_each_lines_figures_and_the_hubs_and_webs_counts() -> None:
    diags = {
        "profibus": {"events_dropped": 0, "cycles": 10},
        "devicenet": {"events_dropped": 2, "own_mac_claims_unanswered": 4998},
        "canopen": {"events_dropped": 0, "emcy_dropped": 19_980},
        "starting": {},  # a line without figures yet: no sample, never a made-up 0
    }
    runtime = SimpleNamespace(
        config=SimpleNamespace(buses=[SimpleNamespace(name=n) for n in diags]),
        adapters={n: Line(d) for n, d in diags.items()},
        hub=SimpleNamespace(events_folded=20_043),
    )
    web = WebCounters()
    web.refused["token"] = 7
    web.refused["token_limit"] = 300  # refused unchecked: not a token given wrong
    got = collected(FloodCollector(runtime, web))
    assert set(got) == set(FLOOD_METRICS) and set(FLOOD_METRICS) <= set(METRICS)
    assert got["drive_gateway_events_folded"] == {(): 20_043}
    assert got["drive_gateway_web_tokens_failed"] == {(): 7}
    assert got["drive_gateway_bus_events_dropped"] == {
        (("bus", "profibus"),): 0,
        (("bus", "devicenet"),): 2,
        (("bus", "canopen"),): 0,
    }
    assert got["drive_gateway_bus_emcy_dropped"] == {(("bus", "canopen"),): 19_980}
    assert got["drive_gateway_bus_duplicate_mac_unanswered"] == {(("bus", "devicenet"),): 4998}


def send(channel: str, frames: list[tuple[int, bytes]]) -> None:
    """``frames`` on the demo's CAN channel from another station, back to back."""
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        for arbitration_id, data in frames:
            bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False))
    finally:
        bus.shutdown()


async def figures_until(demo: Demo, bus: str, done: Callable[[dict[str, Any]], bool]) -> None:
    """Until the line's figures, as its own loop builds them, satisfy ``done``."""
    line = demo.line(bus)
    async with asyncio.timeout(scaled(30.0)):
        while not done(line.diagnostics()):
            await line.next_diagnostics()


def emcy_heard(diag: dict[str, Any]) -> int:
    """EMCY frames of the demo's first CiA 402 drive the line took or dropped."""
    return int(diag.get("emcy_dropped", 0)) + int(
        diag.get("drives", {}).get("cia402a", {}).get("emcy_rx", 0)
    )


async def test_each_flood_moves_its_counter_in_a_scrape_of_the_demo() -> None:
    section = web_section(
        commands=True, token_sha256=TOKEN_SHA256, limits=WebLimits(token_failures=10)
    )
    async with demo_daemon(section) as demo:
        for bus in ("devicenet", "canopen"):
            await figures_until(demo, bus, lambda d: "events_dropped" in d)
        first = await scrape(demo)
        co_before = emcy_heard(demo.line("canopen").diagnostics())
        dn_before = demo.line("devicenet").diagnostics()["own_mac_claims"]

        # forged EMCY frames of node 10 (cia402a), all alike
        emcy = co.encode_emcy(10, co.Emcy(0x8110, 0x11))
        send("demo-canopen", [(emcy.arbitration_id, emcy.data)] * EMCY_FLOOD)
        # Duplicate MAC ID requests for the scanner's MAC 0
        claim = DupMacCheck(0, DupMacKind.REQUEST, 0, 0x1234, 0x5678).to_frame()
        send("demo-devicenet", [(claim.arbitration_id, claim.data)] * DUPMAC_FLOOD)
        # a line's burst of events beyond its hand-over's bound, said while the daemon's
        # loop cannot apply any of them (this test holds it)
        port = demo.line("canopen").port
        assert port is not None
        for _ in range(OUTBOX_EVENTS + 50):
            port.event("cia402b", EventKind.BUS, "the same again")
        # wrong tokens on the web page
        for guess in range(WRONG_TOKENS):
            headers = {"Authorization": f"Bearer guess {guess}"}
            url = f"{demo.url}api/drives/cfw11/command"
            async with demo.http.post(url, json={"run": True}, headers=headers) as r:
                assert r.status == 401

        await figures_until(demo, "canopen", lambda d: emcy_heard(d) >= co_before + EMCY_FLOOD)
        await figures_until(
            demo, "devicenet", lambda d: d["own_mac_claims"] >= dn_before + DUPMAC_FLOOD
        )
        second = await scrape(demo)

    def moved(name: str, **labels: str) -> float:
        return value(second, name, **labels) - value(first, name, **labels)

    assert moved("drive_gateway_bus_emcy_dropped", bus="canopen") > 0
    assert moved("drive_gateway_bus_duplicate_mac_unanswered", bus="devicenet") > 0
    dropped = moved("drive_gateway_bus_events_dropped", bus="canopen")
    assert dropped >= 50  # more when the line's own events were waiting too
    assert moved("drive_gateway_bus_events_dropped", bus="devicenet") == 0
    # the burst's events the outbox took are one run: the first told, the rest folded
    assert moved("drive_gateway_events_folded") >= OUTBOX_EVENTS + 50 - dropped - 1
    assert moved("drive_gateway_web_tokens_failed") == WRONG_TOKENS
