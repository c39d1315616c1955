"""The Zenoh key space of drive-gateway: one table, used by the front end and the document.

The front end builds every key expression it declares from :data:`KEYS`, and
``docs/zenoh-keys.md`` is generated from the same table (``python -m
gateway.zenoh.keys > docs/zenoh-keys.md``); a test fails when the two disagree.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from gateway.adapter import EventKind
from gateway.devices import published
from gateway.model import COMMAND_FIELDS, EXTRA_JSON_FIELDS, JSON_FIELDS


class KeyKind(Enum):
    """Every kind of key the gateway uses."""

    STATE = "state"
    COMMAND = "command"
    PARAM = "params"
    EVENTS = "events"
    DIAG = "diag"
    DRIVE_TOKEN = "drive token"
    GATEWAY_TOKEN = "gateway token"
    HEALTH = "health"
    HISTORY = "history"
    AUDIT = "audit"


class Role(Enum):
    """What the gateway does on a key."""

    PUBLISHES = "publishes"
    SUBSCRIBES = "subscribes (put)"
    QUERYABLE = "queryable"
    TOKEN = "liveliness token"


@dataclass(frozen=True, slots=True)
class KeySpec:
    kind: KeyKind
    template: str  # "{prefix}", "{id}", "{number}", "{subindex}" are filled in
    roles: tuple[Role, ...]
    payload: str
    qos: str
    summary: str


KEYS: tuple[KeySpec, ...] = (
    KeySpec(
        KeyKind.STATE,
        "{prefix}/drives/{id}/state",
        (Role.PUBLISHES, Role.QUERYABLE),
        "DriveState JSON (see below), encoding application/json",
        "a change: DROP, at once; the newest state: BLOCK, 50 ms after the last change "
        "and at least once per heartbeat",
        "Published on every change, and again (same `seq`) once the drive has not changed "
        "for 50 ms and at least once per `zenoh.heartbeat`: on a slow link Zenoh may drop "
        "a change, never the newest state. A query (wildcards allowed, e.g. "
        "`{prefix}/drives/*/state`) answers the latest state of every matching drive.",
    ),
    KeySpec(
        KeyKind.COMMAND,
        "{prefix}/drives/{id}/command",
        (Role.SUBSCRIBES, Role.QUERYABLE),
        "command JSON object (fields below)",
        'reply: `{"accepted": true}` or `{"accepted": false, "error": "..."}`',
        "A put is fire and forget; a refused put is reported on the drive's `events` key. "
        "A query carries the command as its payload and gets exactly one reply. "
        "A command names one drive: a key with wildcards is answered with an error reply. "
        "Any accepted command (even `{}`) refreshes the drive's command watchdog.",
    ),
    KeySpec(
        KeyKind.PARAM,
        "{prefix}/drives/{id}/params/{number}[/{subindex}]",
        (Role.QUERYABLE,),
        'query payload: none (read) or `{"value": V}` (write)',
        'reply: `{"number": N, "subindex": S, "value": V}` plus, where the drive\'s '
        'parameter table knows it, `"code"`, `"name"`, `"unit"`, `"scaled"`; '
        'error reply: `{"error": "device text", "code": C}`',
        'A query without payload reads the parameter; with `{"value": V}` it writes it '
        "(only the drive's `writable_params`). Device and gateway refusals come back as an "
        "error reply (`Reply.err`) carrying the device's own text and code, never as a "
        "timeout. Subindex defaults to 0. The key must name one drive and one parameter; "
        "the number is decimal, or hexadecimal with 0x (a CANopen object and its subindex: "
        "`params/0x6083`, `params/0x2000/4`; an SDO abort comes back as "
        '`{"error": "0x06090030 value range of parameter exceeded (...)", "code": 101253168}`). '
        "`value` is the raw word; `scaled` is it in `unit` (P0100 = 20 is 2.0 s), with the "
        "parameter's `code` as the manual writes it and its `name` (docs/devices.md lists the "
        "tables). Without a number, `<prefix>/drives/<id>/params` answers the drive's whole "
        'parameter backup document (docs/operations.md, "Parameter backup and restore"): '
        "every parameter of the drive's table, or those of the selector parameter "
        "`numbers` (`params?numbers=1-20,100`); `params?describe` answers the drive's "
        "identity, its table and its `writable_params` without reading them. A backup "
        "reads one parameter after the other: give the query a timeout of a minute.",
    ),
    KeySpec(
        KeyKind.EVENTS,
        "{prefix}/drives/{id}/events",
        (Role.PUBLISHES,),
        "event JSON: `drive`, `kind`, `text`, `ts` and kind-specific fields",
        "CongestionControl.BLOCK, in order",
        "Comm changes, faults and trips with the device's text, refused commands, "
        "safety actions, control changes, parameter writes. Published with Zenoh's advanced "
        "publisher: the last `zenoh.recovery_cache` events of each drive are kept, so an "
        'advanced subscriber that was away gets what it missed (below, "Recovery").',
    ),
    KeySpec(
        KeyKind.DIAG,
        "{prefix}/drives/{id}/diag",
        (Role.PUBLISHES,),
        "JSON: `id`, `bus`, `ts` and the adapter's bus figures for the drive",
        "CongestionControl.BLOCK, conflated per drive",
        "Published once per `zenoh.heartbeat`.",
    ),
    KeySpec(
        KeyKind.DRIVE_TOKEN,
        "{prefix}/drives/{id}",
        (Role.TOKEN,),
        "none",
        "liveliness",
        "Present while the drive is online (comm `online`); gone when it goes offline, "
        "when the gateway stops, or when the gateway's process dies.",
    ),
    KeySpec(
        KeyKind.GATEWAY_TOKEN,
        "{prefix}/gateway",
        (Role.TOKEN,),
        "none",
        "liveliness",
        "Present while the gateway's Zenoh front end is serving; declared after every "
        "subscriber and queryable, so a client that sees it can command at once.",
    ),
    KeySpec(
        KeyKind.HEALTH,
        "{prefix}/gateway/health",
        (Role.QUERYABLE,),
        "JSON: name, version, uptime_s, drives, online, faulted (online and faulted or "
        "tripped), per bus live list and cycle figures",
        "reply",
        "The gateway's health (`Runtime.health()`).",
    ),
    KeySpec(
        KeyKind.HISTORY,
        "{prefix}/drives/{id}/history",
        (Role.QUERYABLE,),
        "selector parameters `start`, `end`, `step`, `events` (below); no payload",
        'reply: `{"drive", "start", "end", "step", "t": [...], "values": {"speed_rpm": '
        '[...], ...}}`; error reply: `{"error": "..."}`',
        "The drive's readings kept in the gateway's history (`[history]` in the config): "
        "`{prefix}/drives/cfw11/history?start=now-1d;step=15m`. `start` and `end` are "
        "seconds since the epoch, ISO 8601 (`2026-01-01T00:00:00Z`; without an offset: "
        "UTC), `now` or `now-<duration>`; `step` a duration, seconds or with a unit "
        "(`60`, `15m`, `1h`, `1d`). Without `end` the range ends now, without `start` it "
        "is the hour before `end`, without `step` every sample is answered (at most "
        "100000; more is refused with the step that fits). With `step`, one row per "
        "bucket of `step` seconds of the epoch that holds samples: its start in `t` and "
        "each reading's average over the bucket. A reading no sample gives is left out; "
        "`null` where a bucket or sample has none. A bad parameter, an unknown drive, a "
        "key with wildcards or a gateway without history is answered with an error reply "
        "naming it. Readings are sampled every `history.period` seconds. With `events` "
        "(no value, no step) the answer is the drive's events of the range instead, each "
        'as the events key published it: `{"drive", "start", "end", "events": [...]}` '
        "(`history?events;start=now-1d`): what an advanced subscriber missed beyond the "
        'cache (below, "Recovery").',
    ),
    KeySpec(
        KeyKind.AUDIT,
        "{prefix}/gateway/audit",
        (Role.QUERYABLE,),
        'JSON: `{"records": [...]}`, the newest audit records (at most 1000), oldest first',
        "reply",
        'The audit trail (docs/operations.md, "Users, roles and the audit trail"): each '
        "record has `seq`, `timestamp` (UTC), `interface`, `peer`, `identity`, `role`, "
        "`category`, `type`, `event_id`, `result` and `detail`. `?since=N` answers the "
        "records after sequence number N. For engineers: the router's access control "
        "(config/zenoh-secure.json5) says which certificates may ask.",
    ),
)

SPECS: dict[KeyKind, KeySpec] = {spec.kind: spec for spec in KEYS}

COMMAND_FIELD_DOC: dict[str, str] = {
    "run": "bool: run (true) or stop (false); after a fault reset, a restart or a change of "
    "control source a drive runs only on a new `run: true`",
    "direction": '"forward" or "reverse"',
    "speed_rpm": "number: speed reference in rpm (not with speed_pct)",
    "speed_pct": "number: speed reference in % of the drive's scale base (not with speed_rpm)",
    "fault_reset": "true: one fault reset edge (never repeated; not with run)",
    "quick_stop": "bool: quick stop",
    "coast_stop": "bool: coast stop (disable the output)",
    "jog": "bool: jog",
    "remote": "bool: take (true) or leave (false) network control",
}
"""One line per command field; a test checks it names exactly COMMAND_FIELDS."""

STATE_FIELD_DOC: dict[str, str] = {
    "id": "drive id (the `<id>` of the keys)",
    "device": "device model: " + ", ".join(f'"{d.value}"' for d in published()),
    "bus": "bus name from the config",
    "address": "station address (Profibus) or MAC id (DeviceNet)",
    "comm": '"offline", "connecting", "online", "clear"',
    "status": '"not_ready", "ready", "starting", "running", "stopping", "faulted", "tripped"',
    "running": "bool",
    "direction": '"forward" or "reverse"',
    "at_reference": "bool",
    "remote": "bool: the network is in control",
    "alarm": "bool",
    "speed_rpm": "actual speed in rpm (null for a soft starter)",
    "speed_pct": "actual speed in % of the scale base (null for a soft starter)",
    "speed_ref_rpm": "speed reference in rpm",
    "speed_ref_pct": "speed reference in %",
    "current_a": "motor current in A",
    "current_pct_flc": "motor current in % of full-load current (soft starters)",
    "motor_temp_pct": "motor temperature in %",
    "power_kw": "output power in kW",
    "voltage_v": "output or line voltage in V",
    "fault_code": "the device's fault code, or null",
    "fault_text": "the device's text for the fault code, or null",
    "alarm_code": "the device's alarm code, or null",
    "seq": "monotonic sequence number (a heartbeat repeat keeps it)",
    "ts": "wall-clock time of the reading, seconds since the epoch",
    "control_source": '"none", "zenoh", "modbus", "gateway", "web", "opcua"',
    "speed_base": "what 100 % speed is, or null",
    "values": "named raw values the profile does not model",
    "control_client": "the client in control within `control_source` (a Modbus peer address, "
    'the label of a Zenoh session id or of a web page id, "anonymous"), or null; a label is '
    "the first 16 hex digits of the id's SHA-256, never the id itself, so no client can copy "
    "another's",
    "local_control": "true while the drive ignores the network's run commands (its own "
    "status or source parameters say so): run commands are refused, stops are still sent",
    "failsafe": "the drive's own reaction to a lost master: true when it stops or faults, "
    "false when it keeps running, null when unknown",
    "failsafe_text": "which parameter or setting gives `failsafe`, and its value, or null",
    "doubtful": "true while frames that contradict each other are heard for this drive "
    "(two answers to one request, a second producer): its readings may be forged; run "
    "commands are refused",
}
"""One line per DriveState JSON field; a test checks it names exactly the model's fields."""

EVENT_KIND_DOC: dict[EventKind, str] = {
    EventKind.COMM: "communication state changed",
    EventKind.FAULT: "fault (with code and the device's text), fault cleared, reset sent",
    EventKind.TRIP: "soft starter trip (with code and text)",
    EventKind.ALARM: "alarm raised",
    EventKind.COMMAND: "a command was accepted and changed the desired command (the audit "
    "trail: fields `source`, `client` and `changes`)",
    EventKind.COMMAND_REFUSED: "a command was refused (fields `source` and `client` say from "
    "where)",
    EventKind.SAFETY: "a safety action of the gateway (watchdog, shutdown, run cleared)",
    EventKind.CONTROL: "control passed from one client to another (rule 1: run needs a new "
    "run command)",
    EventKind.PARAMETER: "a parameter was written",
    EventKind.CONFIG: "configuration",
    EventKind.BUS: "bus-level event",
}


@dataclass(frozen=True, slots=True)
class ParsedKey:
    """A concrete key under ``<prefix>/drives/``: the drive id and what follows it."""

    drive_id: str
    kind: str
    rest: tuple[str, ...] = ()


class KeySpace:
    """The keys of one gateway (one prefix)."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self._drives = f"{prefix}/drives/"

    def key(self, kind: KeyKind, drive_id: str = "") -> str:
        template = SPECS[kind].template
        base = template.split("[", 1)[0] if kind is KeyKind.PARAM else template
        return base.format(prefix=self.prefix, id=drive_id, number="", subindex="").rstrip("/")

    def param(self, drive_id: str, number: int, subindex: int | None = None) -> str:
        key = f"{self._drives}{drive_id}/params/{number}"
        return key if subindex is None else f"{key}/{subindex}"

    def all_drives(self, kind: KeyKind) -> str:
        """The key expression covering ``kind`` for every drive (for declarations)."""
        if kind is KeyKind.PARAM:
            return f"{self._drives}*/params/**"
        return self.key(kind, "*")

    def parse(self, key: str) -> ParsedKey | None:
        """Split a key under ``<prefix>/drives/``; None if it is not one."""
        if not key.startswith(self._drives):
            return None
        parts = key[len(self._drives) :].split("/")
        if len(parts) < 2 or not parts[0]:
            return None
        return ParsedKey(parts[0], parts[1], tuple(parts[2:]))


def is_concrete(key: str) -> bool:
    """True when a key expression names one key (no ``*``, ``**`` or ``$*``)."""
    return "*" not in key


# ---------------------------------------------------------------- the document


def _display(template: str) -> str:
    """A key template as the document writes it: ``<prefix>/drives/<id>/...``."""
    for name in ("prefix", "id", "number", "subindex"):
        template = template.replace("{" + name + "}", f"<{name}>")
    return template


def _table(header: tuple[str, ...], rows: Sequence[tuple[str, ...]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    return lines


ZENOH_SERIES = "1.10"
"""The Zenoh release the gateway is built with (pyproject.toml pins eclipse-zenoh to it; a
test holds the two equal)."""

CLIENT_EXAMPLE_FILE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "zenoh_client.py"
"""A client in Python, as docs/zenoh-keys.md shows it (a test runs it against a gateway):
a file of the source tree, read when the page is generated, never by the daemon."""


def client_example() -> str:
    """The client example's code, without its module docstring (the page says as much)."""
    text = CLIENT_EXAMPLE_FILE.read_text()
    return text[text.index('"""', 3) + 3 :].lstrip("\n")


def _client_section() -> list[str]:
    return [
        "## Clients",
        "",
        f"The gateway is built with Zenoh {ZENOH_SERIES} (the Python binding eclipse-zenoh "
        f"{ZENOH_SERIES}.x, on the Zenoh {ZENOH_SERIES} protocol): give clients the same "
        "release; another release may not talk to it.",
        "",
        "**Every client sends its source info** with each put and query "
        "(`source_info=zenoh.SourceInfo(publisher.id, sequence_number)`: the id of a "
        "publisher the client declares, which carries its session's Zenoh id). The gateway "
        'tells clients apart by it (docs/operations.md, "Control belongs to a client"): '
        "only the client in control feeds a drive's command watchdog, with "
        '`control = "any"` a command from another client takes control and the drive '
        "stops until that client sends run, and the state names the client in "
        "`control_client`. A put or query without source info is the `anonymous` client: "
        "every client that sends none is that same one client, so one of them takes over "
        "another's drive without the stop, and its keep-alive feeds the watchdog of a motor "
        "another one started. "
        "`drive-gateway cmd`, `param` and `params` send it.",
        "",
        "A client in Python (read a state, send a command as a query and as a put, read a "
        "parameter):",
        "",
        "```python",
        *client_example().rstrip("\n").split("\n"),
        "```",
        "",
        "`drive-gateway watch`, `cmd`, `param` and `params` are such clients "
        "(gateway/cli/tools.py).",
        "",
    ]


def render_markdown() -> str:
    """docs/zenoh-keys.md, generated from the tables of this module."""
    out = [
        "# drive-gateway: Zenoh key space",
        "",
        "<!-- Generated by `python -m gateway.zenoh.keys > docs/zenoh-keys.md`; do not edit. -->",
        "",
        "`<prefix>` is `zenoh.prefix` from the config (the demo uses `demo`), `<id>` a drive id.",
        "Every payload is JSON (encoding `application/json`).",
        "",
        "## Keys",
        "",
    ]
    rows = [
        (
            f"`{_display(spec.template)}`",
            ", ".join(r.value for r in spec.roles),
            spec.payload,
            spec.qos,
        )
        for spec in KEYS
    ]
    out += _table(("key", "gateway", "payload", "delivery"), rows)
    out.append("")
    for spec in KEYS:
        out += [f"### `{_display(spec.template)}`", "", _display(spec.summary), ""]
    out += _client_section()
    out += ["## Command fields", ""]
    out += _table(("field", "meaning"), [(f"`{n}`", COMMAND_FIELD_DOC[n]) for n in COMMAND_FIELDS])
    out += [
        "",
        "Unknown fields, wrong types, out-of-range speeds, speed_rpm together with speed_pct, "
        "and fields the device cannot follow (a speed or direction for a soft starter) are "
        "refused with the reason; nothing of a refused command is applied, except its stop: "
        "a command that asks for less motion (run or jog false, quick_stop or coast_stop "
        "true) is never refused because of another field, and a stop kind the drive lacks "
        "becomes the nearest one it has (a `safety` event says so once). Invalid JSON and "
        "an object that names a key twice are refused the same way.",
        "",
        "## State fields",
        "",
    ]
    fields = JSON_FIELDS + EXTRA_JSON_FIELDS
    out += _table(("field", "meaning"), [(f"`{n}`", STATE_FIELD_DOC[n]) for n in fields])
    out += ["", "## Event kinds", ""]
    out += _table(("kind", "meaning"), [(f"`{k.value}`", EVENT_KIND_DOC[k]) for k in EventKind])
    out += [
        "",
        "A burst of identical events is one event with a count: an event with the same kind "
        "and text as the drive's event before it, within 1 s of the first (or of the last "
        "count), is held back and counted; when that second is over, or just before the "
        "drive's next different event, one event like the last one held back carries "
        "`repeats`: how many were held back since the drive's event before it "
        '(`{"drive": "cfw11", "kind": "fault", "text": "EMCY 0x2310 ...", "code": 8976, '
        '"repeats": 999, ...}`). The count is in time within a second (the hub\'s tick); an '
        "event that differs from the drive's event before it (a new fault, another code, a "
        "fault announced again after a comm change) is never held back, and each drive's "
        "events stay in order. Added up, the events and their `repeats` are every event "
        "that happened.",
        "",
        "## Session and delivery",
        "",
        "- Peer mode by default. The session listens and connects only on the endpoints of the "
        "config (`zenoh.listen`, `zenoh.connect`, or `--zenoh-endpoint`); multicast and gossip "
        "scouting are off unless `zenoh.multicast_scouting` is true. `zenoh.config_file` "
        "(JSON5) replaces all of this and is passed to Zenoh as it is (routers, TLS, access "
        "control).",
        "- The gateway's event loop never waits on the network. It puts each state change "
        "at once with CongestionControl.DROP (on a congested link Zenoh drops it: older "
        "states are overtaken by newer ones, nothing queues up). The newest state of a "
        "drive is put again with CongestionControl.BLOCK once the drive has been quiet for "
        "50 ms and at least once per heartbeat, so the last word always arrives.",
        "- One I/O thread makes every Zenoh call that can block: opening and closing the "
        "session, declarations, BLOCK puts of states (through a latest-per-drive slot: a "
        "newer state replaces one not yet sent), events and diagnostics, query replies and "
        "liveliness tokens. Events are put in order with CongestionControl.BLOCK.",
        "- Events wait for the I/O thread in a queue of 1000. When it is full (a flood of "
        "refused commands faster than the network takes them), a new event is dropped and "
        "counted, and the next event put carries `dropped`: how many were lost before it. "
        "A fault, a trip, a safety action and a comm change are never dropped. A burst of "
        "identical events reaches the queue as one event and one with `repeats` per second "
        '(above, "Event kinds"). The log writes one line per event that leaves the hub, and '
        "a refusal repeated by the same client for the same reason once per 10 s, with the "
        "count.",
        "- Zenoh callbacks only copy the key and payload and hand them to the event loop; "
        "every query gets exactly one reply (an error reply if the gateway stops first). "
        "At most 1024 puts and queries wait for the loop; more are dropped (a query "
        "dropped gets no reply) rather than queued without a bound.",
        "- A command or parameter payload over 4096 bytes is refused before it is copied "
        "or parsed (`payload of N bytes is over the limit of 4096 bytes`); JSON nested "
        "too deeply to parse is refused like any other bad command. At most 64 parameter "
        "requests are under way at once; one more is refused as busy.",
        "- Readings and events outlive a restart in the gateway's own history (SQLite on "
        "the box, `[history]`): `<prefix>/drives/<id>/history` above, `drive-gateway "
        "history` on the box (docs/operations.md).",
        "- Shared memory is off in the gateway's session (Zenoh turns it on by default, and "
        "then same-host clients' large payloads map 16 MB segments in the gateway that "
        "are never given back), unless `zenoh.config_file` sets `transport.shared_memory`.",
        "",
        "## Recovery",
        "",
        "Events, and the settled states (the BLOCK puts of each drive's newest state), are "
        "published with Zenoh's advanced publisher (`zenoh.ext`): each keeps the last "
        "`zenoh.recovery_cache` samples of its key (events; the newest state for states), "
        "puts a sequence number on each sample, announces itself with a liveliness token "
        "and sends its last sequence number once a second when it changed (a sporadic "
        "heartbeat: a subscriber that missed the last sample learns of it). An advanced "
        "subscriber that comes back after a cut (or starts late) asks for what it missed "
        "and gets it, in order, up to the cache's size; a plain subscriber gets the live "
        "samples as before. A client doing it (Python, eclipse-zenoh 1.10):",
        "",
        "```python",
        "import zenoh",
        "from zenoh.ext import HistoryConfig, RecoveryConfig, declare_advanced_subscriber",
        "",
        "session = zenoh.open(config)  # connected to the gateway or to the plant's router",
        "sub = declare_advanced_subscriber(",
        "    session,",
        '    "demo/drives/*/events",',
        "    lambda sample: print(sample.payload.to_string()),",
        "    history=HistoryConfig(detect_late_publishers=True, max_samples=100),",
        "    recovery=RecoveryConfig(heartbeat=True),",
        "    subscriber_detection=True,",
        ")",
        "misses = sub.sample_miss_listener(",
        '    lambda miss: print("missed", miss.nb, "samples: ask the history key for them")',
        ")",
        "```",
        "",
        "Closed and opened again (a new session), the subscriber first gets the events "
        "kept in the cache it had not seen, then the live ones. Events lost beyond the "
        "cache are told by the miss listener; `<prefix>/drives/<id>/history?events` answers "
        "them from the gateway's history. The key expressions are Zenoh's own, so a plant "
        "router with a storage on `<prefix>/**` in front of the gateway keeps and answers "
        "them the same way.",
        "",
        "The advanced publishers' own keys are under `@adv` (`<prefix>/drives/<id>/events/"
        "@adv/pub/...`: their liveliness tokens, heartbeats and caches), which `**` does "
        "not match: with access control, allow `<prefix>/drives/*/*/@adv/**` for "
        "subscribers, queries and liveliness, and replies on the events and state keys, "
        "as config/zenoh-secure.json5 does for both of its identities.",
        "",
    ]
    return "\n".join(out)


def main() -> int:
    sys.stdout.write(render_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
