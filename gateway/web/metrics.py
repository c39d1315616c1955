"""``/metrics``: the gateway in the Prometheus exposition format, through prometheus_client.

A registry of the web front end's own (never the library's global one) holds one custom
collector, :class:`GatewayCollector`, which reads the hub's states, the adapters'
``diagnostics()``, the other front ends' counters (``FrontEnd.counted()``, typed in
:mod:`gateway.frontend`) and the web feed's own at scrape time: nothing is updated per
sample on a fieldbus path. The process figures come from the library's
``ProcessCollector`` on the same registry. Every metric is listed, with its labels, in
docs/operations.md ("Web status page and metrics"); :data:`METRICS` is that list, checked
by the tests.

A scrape is served from :class:`MetricsSnapshot`: one render serves every scrape within
``web.metrics_max_age`` seconds of it, so scrapers, however many and however often, cost
at most one render per that time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING

from prometheus_client import CollectorRegistry, ProcessCollector, generate_latest
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    InfoMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from gateway.frontend import FrontEndCounters, RuntimeView
from gateway.model import CommState, DriveStatus
from gateway.web.counters import WebCounters
from gateway.web.floodmetrics import FLOOD_METRICS, FloodCollector
from gateway.web.views import (
    BUS_FIGURES,
    STATION_FIGURES,
    bus_diagnostics,
    bus_errors,
    figures,
)

if TYPE_CHECKING:
    from gateway.web.feed import FeedCounters

NS = "drive_gateway"

METRICS: dict[str, str] = {
    # name (as a scrape shows it, without _total/_info) -> help
    f"{NS}_build": "The gateway's name and version (always 1).",
    f"{NS}_uptime_seconds": "Seconds since the daemon started.",
    f"{NS}_drive_online": "1 when the drive's comm state is online.",
    f"{NS}_drive_comm_state": "1 for the drive's comm state, 0 for the others.",
    f"{NS}_drive_status": "1 for the drive's status, 0 for the others.",
    f"{NS}_drive_running": "1 when the drive reports the motor running.",
    f"{NS}_drive_faulted": "1 when the drive is faulted or tripped.",
    f"{NS}_drive_fault_code": "The device's fault code (only while it gives one).",
    f"{NS}_drive_speed_rpm": "Actual speed in rpm (drives with a speed).",
    f"{NS}_drive_speed_reference_rpm": "Speed reference in rpm (drives with a speed).",
    f"{NS}_drive_current_amperes": "Motor current in A (drives that give it in A).",
    f"{NS}_drive_current_flc_ratio": "Motor current / full-load current (soft starters).",
    f"{NS}_drive_state_age_seconds": "Seconds since the drive's state last changed.",
    f"{NS}_bus_cycle_seconds": "Bus cycle time, by statistic (last, median, avg, max).",
    f"{NS}_bus_cycles": "Bus cycles (Profibus polling, DeviceNet poll, CANopen SYNC cycles).",
    f"{NS}_bus_retries": "Requests repeated on the bus.",
    f"{NS}_bus_timeouts": "Requests that ended without a valid reply.",
    f"{NS}_bus_errors": "Bus error counters, by the adapter's own kind.",
    f"{NS}_bus_frames": "Frames on the bus, by direction (tx, rx).",
    f"{NS}_bus_live_stations": "Configured stations online on the bus.",
    f"{NS}_bus_restarts": "Times the bus's adapter was restarted after a crash.",
    f"{NS}_station_response_seconds": "A station's response time, by statistic.",
    f"{NS}_station_retries": "Requests repeated to one station.",
    f"{NS}_station_timeouts": "Requests to one station that ended without a reply.",
    f"{NS}_modbus_requests": "Modbus TCP requests served.",
    f"{NS}_modbus_exceptions": "Modbus TCP requests answered with an exception.",
    f"{NS}_modbus_commands": "Modbus commands, by result (accepted, refused).",
    f"{NS}_modbus_connections": (
        "Modbus connections by result (accepted, refused, over_limit, accept_failed)."
    ),
    f"{NS}_modbus_connections_open": "Modbus TCP connections open now.",
    f"{NS}_zenoh_requests": "Zenoh requests taken, by kind (put, query).",
    f"{NS}_zenoh_commands": "Zenoh commands, by result (accepted, refused).",
    f"{NS}_zenoh_dropped": "Zenoh puts and queries dropped: the hand-over to the loop was full.",
    f"{NS}_history_samples": "History samples by result (written, dropped, failed).",
    f"{NS}_history_events": "History events by result (written, dropped, failed).",
    f"{NS}_history_moved_aside": "History files moved aside as corrupt (a new one started).",
    f"{NS}_opcua_calls": "OPC UA method calls (Run, Stop, QuickStop, Reset, SetSpeed).",
    f"{NS}_opcua_commands": "OPC UA commands the hub accepted or refused.",
    f"{NS}_opcua_refused": "OPC UA requests refused, by reason (a session's limits, roles).",
    f"{NS}_opcua_sessions": "OPC UA sessions opened, or refused at max_sessions.",
    f"{NS}_opcua_sessions_open": "OPC UA sessions open now.",
    f"{NS}_web_clients": "Web pages connected now (WebSocket).",
    f"{NS}_web_messages_dropped": "Push messages slow pages lost (each replaced by a snapshot).",
    f"{NS}_web_clients_disconnected": "Pages disconnected because they stayed stuck.",
    f"{NS}_web_clients_over_budget": "Pages dropped: more unsent than web.page_send_budget_kib.",
    f"{NS}_web_requests_refused": (
        "Refused requests (host, origin, token, token_limit, commands_off, pages, pages_per_peer,"
        " login, login_limit, login_busy, role, csrf, login_required)."
    ),
    f"{NS}_web_logins": "Web logins by result (success, failure, limited: refused unchecked).",
    f"{NS}_audit_records": "Audit records written, by type and result.",
    f"{NS}_web_commands": "Commands from the page, by result (accepted, refused).",
    f"{NS}_web_connections": (
        "Web connections by result (accepted, refused, over_limit, over_peer_limit)."
    ),
    f"{NS}_web_connections_open": "Web connections open now.",
    f"{NS}_web_timeouts": "Web requests cut: a head or body came, or an answer went, too slowly.",
    f"{NS}_web_metrics_renders": "/metrics renders (the scrapes in between share one).",
    f"{NS}_web_requests_throttled": "Requests held back: their address was over web.request_rate.",
    **FLOOD_METRICS,  # gateway/web/floodmetrics.py
}
"""Every metric the collector exposes (the process figures come from prometheus_client)."""

DRIVE_LABELS = ["drive", "bus", "device"]


def _help(name: str) -> str:
    return METRICS[name]


def _gauge(name: str, labels: list[str] | None = None) -> GaugeMetricFamily:
    return GaugeMetricFamily(name, _help(name), labels=labels or [])


def _counter(name: str, labels: list[str] | None = None) -> CounterMetricFamily:
    return CounterMetricFamily(name, _help(name), labels=labels or [])


class MetricsSnapshot:
    """The exposition text of ``registry``, rendered at most once per ``max_age`` seconds:
    every scrape in between gets the same bytes."""

    def __init__(
        self,
        registry: CollectorRegistry,
        max_age: float,
        counters: WebCounters,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.registry = registry
        self.max_age = max_age
        self.counters = counters
        self.clock = clock
        self._body = b""
        self._rendered_at: float | None = None

    def body(self) -> bytes:
        now = self.clock()
        if self._rendered_at is None or now - self._rendered_at >= self.max_age:
            self.counters.metrics_renders += 1
            self._body = generate_latest(self.registry)
            self._rendered_at = now
        return self._body


class GatewayCollector(Collector):
    """Reads the running gateway at scrape time (see the module docstring)."""

    def __init__(self, runtime: RuntimeView, feed: FeedCounters, web: WebCounters) -> None:
        self.runtime = runtime
        self.feed = feed
        self.web = web

    def collect(self) -> Iterator[Metric]:
        yield from self._gateway()
        yield from self._drives()
        yield from self._buses()
        yield from self._modbus()
        yield from self._zenoh()
        yield from self._history()
        yield from self._opcua()
        yield from self._web()

    def describe(self) -> Iterator[Metric]:
        return iter(())  # collected at scrape time only: no describe pass at register

    # ------------------------------------------------------------ parts

    def _gateway(self) -> Iterator[Metric]:
        runtime = self.runtime
        info = InfoMetricFamily(f"{NS}_build", _help(f"{NS}_build"), labels=[])
        info.add_metric([], {"name": runtime.config.gateway.name, "version": runtime.version})
        yield info
        uptime = _gauge(f"{NS}_uptime_seconds")
        uptime.add_metric([], time.monotonic() - runtime.started)
        yield uptime

    def _drives(self) -> Iterator[Metric]:
        states = self.runtime.hub.states()
        online = _gauge(f"{NS}_drive_online", DRIVE_LABELS)
        comm = _gauge(f"{NS}_drive_comm_state", [*DRIVE_LABELS, "state"])
        status = _gauge(f"{NS}_drive_status", [*DRIVE_LABELS, "status"])
        running = _gauge(f"{NS}_drive_running", DRIVE_LABELS)
        faulted = _gauge(f"{NS}_drive_faulted", DRIVE_LABELS)
        fault_code = _gauge(f"{NS}_drive_fault_code", DRIVE_LABELS)
        speed = _gauge(f"{NS}_drive_speed_rpm", DRIVE_LABELS)
        reference = _gauge(f"{NS}_drive_speed_reference_rpm", DRIVE_LABELS)
        amperes = _gauge(f"{NS}_drive_current_amperes", DRIVE_LABELS)
        flc = _gauge(f"{NS}_drive_current_flc_ratio", DRIVE_LABELS)
        age = _gauge(f"{NS}_drive_state_age_seconds", DRIVE_LABELS)
        now = time.time()
        for s in states:
            labels = [s.id, s.bus, s.device.value]
            online.add_metric(labels, float(s.online))
            for c in CommState:
                comm.add_metric([*labels, c.value], float(s.comm is c))
            for st in DriveStatus:
                status.add_metric([*labels, st.label], float(s.status is st))
            running.add_metric(labels, float(s.running))
            faulted.add_metric(labels, float(s.faulted))
            if s.fault_code is not None:
                fault_code.add_metric(labels, float(s.fault_code))
            _maybe(speed, labels, s.speed_rpm)
            _maybe(reference, labels, s.speed_ref_rpm)
            _maybe(amperes, labels, s.current_a)
            pct = s.current_pct_flc
            _maybe(flc, labels, None if pct is None else pct / 100.0)
            if s.ts:
                age.add_metric(labels, max(0.0, now - s.ts))
        yield from (online, comm, status, running, faulted, fault_code)
        yield from (speed, reference, amperes, flc, age)

    def _buses(self) -> Iterator[Metric]:
        runtime = self.runtime
        diags = bus_diagnostics(runtime)
        cycle = _gauge(f"{NS}_bus_cycle_seconds", ["bus", "stat"])
        cycles = _counter(f"{NS}_bus_cycles", ["bus"])
        retries = _counter(f"{NS}_bus_retries", ["bus"])
        timeouts = _counter(f"{NS}_bus_timeouts", ["bus"])
        errors = _counter(f"{NS}_bus_errors", ["bus", "kind"])
        frames = _counter(f"{NS}_bus_frames", ["bus", "direction"])
        live = _gauge(f"{NS}_bus_live_stations", ["bus"])
        restarts = _counter(f"{NS}_bus_restarts", ["bus"])
        response = _gauge(f"{NS}_station_response_seconds", ["bus", "drive", "stat"])
        station_retries = _counter(f"{NS}_station_retries", ["bus", "drive"])
        station_timeouts = _counter(f"{NS}_station_timeouts", ["bus", "drive"])
        hub = runtime.hub
        for bus in runtime.config.buses:
            diag = diags.get(bus.name, {})
            figs = figures(diag, BUS_FIGURES)
            for stat in ("last", "median", "avg", "max"):
                value = figs.get(f"cycle_{stat}_ms")
                if value is not None:
                    cycle.add_metric([bus.name, stat], value / 1e3)
            _maybe(cycles, [bus.name], figs.get("cycles"))
            _maybe(retries, [bus.name], figs.get("retries"))
            _maybe(timeouts, [bus.name], figs.get("timeouts"))
            for kind, count in bus_errors(diag).items():
                errors.add_metric([bus.name, kind], count)
            _maybe(frames, [bus.name, "tx"], figs.get("frames_tx"))
            _maybe(frames, [bus.name, "rx"], figs.get("frames_rx"))
            live.add_metric([bus.name], float(sum(hub.state(d.id).online for d in bus.drives)))
            restarts.add_metric([bus.name], float(runtime.restarts.get(f"bus {bus.name}", 0)))
            per_drive = diag.get("drives", {})
            for d in bus.drives:
                station = per_drive.get(d.id) if isinstance(per_drive, Mapping) else None
                if not isinstance(station, Mapping):
                    continue
                sf = figures(station, STATION_FIGURES)
                for stat in ("last", "median", "avg", "max"):
                    value = sf.get(f"response_{stat}_ms")
                    if value is not None:
                        response.add_metric([bus.name, d.id, stat], value / 1e3)
                _maybe(station_retries, [bus.name, d.id], sf.get("retries"))
                _maybe(station_timeouts, [bus.name, d.id], sf.get("timeouts"))
        yield from (cycle, cycles, retries, timeouts, errors, frames, live, restarts)
        yield from (response, station_retries, station_timeouts)

    def _modbus(self) -> Iterator[Metric]:
        front_end = self.runtime.front_ends.get("modbus")
        requests = _counter(f"{NS}_modbus_requests")
        exceptions = _counter(f"{NS}_modbus_exceptions")
        commands = _counter(f"{NS}_modbus_commands", ["result"])
        connections = _counter(f"{NS}_modbus_connections", ["result"])
        open_now = _gauge(f"{NS}_modbus_connections_open")
        if front_end is not None:
            counted = front_end.counted()
            requests.add_metric([], sum(counted.requests.values()))
            exceptions.add_metric([], counted.exceptions)
            _add_commands(commands, counted)
            connections.add_metric(["accepted"], counted.connections_accepted)
            connections.add_metric(["refused"], counted.connections_refused)
            connections.add_metric(["over_limit"], counted.connections_over_limit)
            connections.add_metric(["accept_failed"], counted.accept_failures)
            open_now.add_metric([], float(counted.connections_open))
        yield from (requests, exceptions, commands, connections, open_now)

    def _zenoh(self) -> Iterator[Metric]:
        front_end = self.runtime.front_ends.get("zenoh")
        requests = _counter(f"{NS}_zenoh_requests", ["kind"])
        commands = _counter(f"{NS}_zenoh_commands", ["result"])
        dropped = _counter(f"{NS}_zenoh_dropped")
        if front_end is not None:
            counted = front_end.counted()
            for kind, count in counted.requests.items():
                requests.add_metric([kind], count)
            _add_commands(commands, counted)
            dropped.add_metric([], counted.dropped)
        yield from (requests, commands, dropped)

    def _opcua(self) -> Iterator[Metric]:
        front_end = self.runtime.front_ends.get("opcua")
        calls = _counter(f"{NS}_opcua_calls")
        commands = _counter(f"{NS}_opcua_commands", ["result"])
        refused = _counter(f"{NS}_opcua_refused", ["reason"])
        sessions = _counter(f"{NS}_opcua_sessions", ["result"])
        open_now = _gauge(f"{NS}_opcua_sessions_open")
        if front_end is not None:
            counted = front_end.counted()
            calls.add_metric([], sum(counted.requests.values()))
            _add_commands(commands, counted)
            for reason, count in counted.refused.items():
                refused.add_metric([reason], count)
            sessions.add_metric(["accepted"], counted.connections_accepted)
            sessions.add_metric(["over_limit"], counted.connections_over_limit)
            open_now.add_metric([], float(counted.connections_open))
        yield from (calls, commands, refused, sessions, open_now)

    def _history(self) -> Iterator[Metric]:
        store = self.runtime.history
        counted = None if store is None else store.counters
        samples = _counter(f"{NS}_history_samples", ["result"])
        events = _counter(f"{NS}_history_events", ["result"])
        moved = _counter(f"{NS}_history_moved_aside")
        if counted is not None:
            for result in ("", "_dropped", "_failed"):
                label = result.lstrip("_") or "written"
                samples.add_metric([label], getattr(counted, f"samples{result}"))
                events.add_metric([label], getattr(counted, f"events{result}"))
            moved.add_metric([], counted.moved_aside)
        yield from (samples, events, moved)

    def _web(self) -> Iterator[Metric]:
        clients = _gauge(f"{NS}_web_clients")
        clients.add_metric([], self.web.clients_open)
        dropped = _counter(f"{NS}_web_messages_dropped")
        dropped.add_metric([], self.feed.dropped)
        stuck = _counter(f"{NS}_web_clients_disconnected")
        stuck.add_metric([], self.feed.clients_stuck)
        refused = _counter(f"{NS}_web_requests_refused", ["reason"])
        for reason, count in self.web.refused.items():
            refused.add_metric([reason], count)
        commands = _counter(f"{NS}_web_commands", ["result"])
        for result, count in self.web.commands.items():
            commands.add_metric([result], count)
        yield from (clients, dropped, stuck, refused, commands)
        yield from self._web_admission()

    def _web_admission(self) -> Iterator[Metric]:
        web = self.web
        over_budget = _counter(f"{NS}_web_clients_over_budget")
        over_budget.add_metric([], web.clients_over_budget)
        connections = _counter(f"{NS}_web_connections", ["result"])
        for result, count in web.connections.items():
            connections.add_metric([result], count)
        open_now = _gauge(f"{NS}_web_connections_open")
        open_now.add_metric([], web.connections_open)
        timeouts = _counter(f"{NS}_web_timeouts", ["phase"])
        for phase, count in web.timeouts.items():
            timeouts.add_metric([phase], count)
        renders = _counter(f"{NS}_web_metrics_renders")
        renders.add_metric([], web.metrics_renders)
        throttled = _counter(f"{NS}_web_requests_throttled")
        throttled.add_metric([], web.throttled)
        yield from (over_budget, connections, open_now, timeouts, renders, throttled)
        logins = _counter(f"{NS}_web_logins", ["result"])
        for result, count in web.logins.items():
            logins.add_metric([result], count)
        audit = _counter(f"{NS}_audit_records", ["type", "result"])
        for key, count in sorted(self.runtime.audit.counts.items()):
            kind, _, result = key.partition(":")
            audit.add_metric([kind, result], count)
        yield from (logins, audit)


def _maybe(
    family: GaugeMetricFamily | CounterMetricFamily, labels: list[str], value: float | None
) -> None:
    if value is not None:
        family.add_metric(labels, value)


def make_registry(runtime: RuntimeView, feed: FeedCounters, web: WebCounters) -> CollectorRegistry:
    """The front end's own registry: the gateway's collector and the process figures."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(GatewayCollector(runtime, feed, web))
    registry.register(FloodCollector(runtime, web))
    ProcessCollector(registry=registry)
    return registry


def _add_commands(family: CounterMetricFamily, counted: FrontEndCounters) -> None:
    """A front end's commands by result (the hub's answer)."""
    family.add_metric(["accepted"], counted.commands_accepted)
    family.add_metric(["refused"], counted.commands_refused)
