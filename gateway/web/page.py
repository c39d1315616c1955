"""The status page as first served: the drive table, the header's counts and the gateway's
name rendered into index.html on the server, so the page shows the drives before (and
without) its script; the script's first snapshot then takes the same elements over.

Every value is put in as escaped text (``html.escape``), as the script puts it in with
``textContent``. The places filled are found by their elements' ids; a template without
one of them is a packaging error named at start (:func:`check_template`). The table body
says who rendered its rows last: ``data-rendered="server"``, then ``"feed"`` once the
script has shown the first snapshot.
"""

from __future__ import annotations

import html
import time
from collections.abc import Iterable, Mapping
from typing import Any

from gateway.errors import StartupError
from gateway.frontend import RuntimeView
from gateway.model import DriveState
from gateway.web.views import drive_row

NONE = "\u2013"
"""What an empty figure shows (an en dash, as app.js writes it)."""

COLUMNS: tuple[tuple[str, str], ...] = (
    ("id", "drive"),
    ("device", "device"),
    ("where", "bus / address"),
    ("comm", "comm"),
    ("status", "status"),
    ("speed", "speed rpm"),
    ("ref", "reference rpm"),
    ("current", "current"),
    ("fault", "fault"),
    ("control", "in control"),
    ("age", "last change"),
)
"""The drive table's columns, as app.js's ``COLUMNS`` (a test holds them equal)."""

SLOTS = {
    "name": '<span id="gw-name">drive-gateway</span>',
    "version": '<small id="gw-version"></small>',
    "summary": '<div id="summary" class="summary"></div>',
    "head": '<tr id="drives-head"></tr>',
    "body": '<tbody id="drives-body"></tbody>',
}
"""The empty elements of index.html the server fills (by their exact text)."""


def check_template(template: str) -> None:
    missing = [name for name, slot in SLOTS.items() if slot not in template]
    if missing:
        raise StartupError(
            "web: the status page",
            f"index.html lacks the element(s) the server fills: {', '.join(missing)}",
            "reinstall drive-gateway (the package's gateway/web/static is damaged)",
        )


# ---------------------------------------------------------------- the header's counts


def counts(states: Iterable[DriveState]) -> dict[str, int]:
    """Drives, online, ok (online, not faulted), faulted (online and faulted or tripped:
    an offline drive's status is not known) and offline."""
    out = {"drives": 0, "online": 0, "ok": 0, "faulted": 0, "offline": 0}
    for s in states:
        out["drives"] += 1
        if not s.online:
            out["offline"] += 1
            continue
        out["online"] += 1
        out["faulted" if s.faulted else "ok"] += 1
    return out


def summary_text(c: Mapping[str, int]) -> str:
    """``7 drives: 5 ok, 2 faulted, 0 offline`` (app.js ``summaryText`` says the same)."""
    return f"{c['drives']} drives: {c['ok']} ok, {c['faulted']} faulted, {c['offline']} offline"


# ---------------------------------------------------------------- the drive table


def _num(value: Any, digits: int) -> str:
    return NONE if value is None else f"{float(value):.{digits}f}"


def _age(ts: float, now: float) -> str:
    if not ts:
        return NONE
    age = max(0.0, now - ts)
    if age < 60:
        return f"{age:.1f} s"
    if age < 3600:
        return f"{age / 60:.1f} min"
    return f"{age / 3600:.1f} h"


def _current(d: Mapping[str, Any]) -> str:
    if d.get("current_a") is not None:
        return _num(d["current_a"], 2) + " A"
    if d.get("current_pct_flc") is not None:
        return _num(d["current_pct_flc"], 0) + " %FLC"
    return NONE


def _fault(d: Mapping[str, Any]) -> str:
    if d.get("fault_code") is None:
        if not d.get("alarm"):
            return ""
        return f"alarm {d.get('alarm_code_text') or ''}".rstrip()
    text = f": {d['fault_text']}" if d.get("fault_text") else ""
    return f"{d.get('fault_code_text') or d['fault_code']}{text}"


def _control(d: Mapping[str, Any]) -> str:
    if d.get("control_source") == "none":
        return NONE
    client = f" {d['control_client']}" if d.get("control_client") else ""
    return f"{d.get('control_source')}{client}"


def cells(d: Mapping[str, Any], now: float) -> dict[str, str]:
    """One drive row's cell texts, as app.js ``renderDrive`` writes them."""
    return {
        "id": str(d["id"]),
        "device": str(d["device"]),
        "where": f"{d['bus']} / {d['address']}",
        "comm": str(d["comm"]),
        "status": str(d["status"]),
        "speed": _num(d.get("speed_rpm"), 1),
        "ref": _num(d.get("speed_ref_rpm"), 1),
        "current": _current(d),
        "fault": _fault(d),
        "control": _control(d),
        "age": _age(float(d.get("ts") or 0.0), now),
    }


def _attr(name: str, value: Any) -> str:
    return f' {name}="{html.escape(str(value), quote=True)}"'


def row_html(d: Mapping[str, Any], now: float) -> str:
    texts = cells(d, now)
    tds = []
    for key, _ in COLUMNS:
        text = html.escape(texts[key], quote=False)
        if key in ("comm", "status"):
            text = f'<span class="badge"{_attr("data-v", texts[key])}>{text}</span>'
        extra = _attr("data-ts", d.get("ts") or 0) if key == "age" else ""
        kind = ' class="num"' if key in ("speed", "ref", "current") else ""
        kind = ' class="fault"' if key == "fault" else kind
        tds.append(f"<td{_attr('data-col', key)}{kind}{extra}>{text}</td>")
    tr = _attr("data-drive", d["id"]) + _attr("data-comm", d["comm"])
    return f"<tr{tr}{_attr('data-status', d['status'])}>{''.join(tds)}</tr>"


def render(
    template: str, runtime: RuntimeView, now: float | None = None, drives: bool = True
) -> str:
    """index.html with the drives as they are now (``drives`` False: none, for a visitor
    who may not read them)."""
    now = time.time() if now is None else now
    states = runtime.hub.states() if drives else []
    rows = "".join(row_html(drive_row(runtime, s), now) for s in states)
    head = "".join(f"<th{_attr('data-col', key)}>{html.escape(t)}</th>" for key, t in COLUMNS)
    name = html.escape(runtime.config.gateway.name, quote=False)
    fills = {
        "name": f'<span id="gw-name">{name}</span>',
        "version": f'<small id="gw-version">{html.escape(runtime.version, quote=False)}</small>',
        "summary": f'<div id="summary" class="summary">{summary_text(counts(states))}</div>',
        "head": f'<tr id="drives-head">{head}</tr>',
        "body": f'<tbody id="drives-body" data-rendered="server">{rows}</tbody>',
    }
    for slot, text in fills.items():
        template = template.replace(SLOTS[slot], text, 1)
    return template
