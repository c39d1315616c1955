"""What the page, the JSON API and ``/metrics`` show, made from the hub and the adapters'
public surface: ``hub.states()``, ``hub.desired()``, ``runtime.health()`` and
``adapter.diagnostics()``.

Each adapter words its diagnostics its own way (a Profibus master has ``cycle_ms`` with
last, median and max; a DeviceNet scanner ``cycle_time_ms`` and ``cycle_time_avg_ms``).
:data:`BUS_FIGURES` and :data:`STATION_FIGURES` are the tables that read them into one
form: the first key path found gives the figure; a figure no path finds is left out, so
an adapter that reports less shows less, never a made-up zero.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from gateway.devices import code_text
from gateway.frontend import RuntimeView
from gateway.model import DriveState
from gateway.web.history import current_unit

Path = tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Figure:
    """One figure of a bus or a station, and where each adapter's diagnostics keep it."""

    name: str
    paths: tuple[Path, ...]
    unit: str = ""  # "ms" for times; "" for counts


BUS_FIGURES: tuple[Figure, ...] = (
    Figure("cycle_last_ms", (("cycle_ms", "last"), ("cycle_time_ms",)), "ms"),
    Figure("cycle_median_ms", (("cycle_ms", "median"),), "ms"),
    Figure("cycle_avg_ms", (("cycle_time_avg_ms",),), "ms"),
    Figure("cycle_max_ms", (("cycle_ms", "max"), ("cycle_time_max_ms",)), "ms"),
    Figure("cycles", (("cycles",), ("poll_cycles",), ("syncs_tx",))),
    Figure("retries", (("retries",),)),
    Figure("timeouts", (("timeouts",),)),
    Figure("frames_tx", (("telegrams",), ("frames_tx",))),
    Figure("frames_rx", (("frames_rx",),)),
)
"""Line-level figures (Profibus master: adapters/profibus/master/figures.py; DeviceNet scanner:
adapters/devicenet/scanner/engine.py ``line_diagnostics``; CANopen master: a cycle is a
SYNC, adapters/canopen/master/engine.py ``figures``)."""

BUS_ERRORS: tuple[str, ...] = (
    "fcs_errors",
    "framing_errors",
    "invalid_replies",
    "unexpected_telegrams",
    "discarded_bytes",
    "errors",
    "error_frames",
    "tx_failures",
    "tx_dropped",
    "send_failures",
    "receive_failures",
    "link_bad_frames",
    "link_down",
    "reopens",
)
"""Line-level error counters, by the adapter's own name (each one a ``kind`` label)."""

STATION_FIGURES: tuple[Figure, ...] = (
    Figure("response_last_ms", (("response_ms", "last"), ("response_time_ms",)), "ms"),
    Figure("response_median_ms", (("response_ms", "median"),), "ms"),
    Figure("response_avg_ms", (("response_time_avg_ms",),), "ms"),
    Figure("response_max_ms", (("response_ms", "max"), ("response_time_max_ms",)), "ms"),
    Figure("retries", (("retries",),)),
    Figure("timeouts", (("timeouts",),)),
    Figure("errors", (("errors",), ("fcs_errors",))),
)


def _find(diag: Mapping[str, Any], path: Path) -> float | None:
    value: Any = diag
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def figures(diag: Mapping[str, Any], table: tuple[Figure, ...]) -> dict[str, float]:
    out: dict[str, float] = {}
    for figure in table:
        for path in figure.paths:
            value = _find(diag, path)
            if value is not None:
                out[figure.name] = value
                break
    return out


def bus_errors(diag: Mapping[str, Any]) -> dict[str, float]:
    out: dict[str, float] = {}
    for kind in BUS_ERRORS:
        value = _find(diag, (kind,))
        if value is not None:
            out[kind] = value
    return out


def _scalars(diag: Mapping[str, Any]) -> dict[str, Any]:
    """The line's own plain values (numbers, text, flags), for the page's details."""
    return {
        k: v
        for k, v in diag.items()
        if k != "drives" and (v is None or isinstance(v, str | int | float | bool))
    }


# ---------------------------------------------------------------- drives


def drive_row(runtime: RuntimeView, state: DriveState) -> dict[str, Any]:
    """One drive as the table and ``/api/drives`` show it: the state's JSON, the unit of
    its current in the trend, its fault and alarm codes as its documents write them
    (``fault_code_text``: ``0x8130`` for a CANopen EMCY code) and the command it is given."""
    row = state.to_json()
    row["current_unit"] = current_unit(state)
    for name in ("fault_code", "alarm_code"):  # as the device's documents write them
        code = getattr(state, name)
        row[f"{name}_text"] = None if code is None else code_text(state.device, code)
    row["desired"] = runtime.hub.desired(state.id).to_json()
    return row


def drives_json(runtime: RuntimeView) -> list[dict[str, Any]]:
    return [drive_row(runtime, s) for s in runtime.hub.states()]


# ---------------------------------------------------------------- buses


def bus_diagnostics(runtime: RuntimeView) -> dict[str, dict[str, Any]]:
    """Each bus's adapter diagnostics as it gives them ({} while it has none)."""
    out: dict[str, dict[str, Any]] = {}
    for bus in runtime.config.buses:
        adapter = runtime.adapters.get(bus.name)
        try:
            out[bus.name] = adapter.diagnostics() if adapter is not None else {}
        except Exception:  # an adapter between runs: no figures this time
            out[bus.name] = {}
    return out


def buses_json(
    runtime: RuntimeView, diags: Mapping[str, Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """Per bus: its live list (each station's state) and its figures."""
    hub = runtime.hub
    out = []
    for bus in runtime.config.buses:
        diag = diags.get(bus.name, {})
        per_drive = diag.get("drives", {})
        stations = []
        for d in bus.drives:
            station = per_drive.get(d.id) if isinstance(per_drive, Mapping) else None
            station = station if isinstance(station, Mapping) else {}
            station_state = station.get("state")
            stations.append(
                {
                    "drive": d.id,
                    "address": d.address,
                    "device": d.device.value,
                    "comm": hub.state(d.id).comm.value,
                    "station_state": station_state if isinstance(station_state, str) else None,
                    **figures(station, STATION_FIGURES),
                }
            )
        out.append(
            {
                "name": bus.name,
                "adapter": bus.adapter,
                "restarts": runtime.restarts.get(f"bus {bus.name}", 0),
                "figures": figures(diag, BUS_FIGURES),
                "errors": bus_errors(diag),
                "details": _scalars(diag),
                "stations": stations,
            }
        )
    return out


def health_json(runtime: RuntimeView) -> dict[str, Any]:
    """``/api/health``: the gateway's health, as the Zenoh health query answers it."""
    body = runtime.health()
    body["ts"] = round(time.time(), 3)
    return body
