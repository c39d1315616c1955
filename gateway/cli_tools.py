"""Operator tools: Zenoh clients for any running gateway (``--connect ENDPOINT``).

``watch`` (live table of drives, ``--once`` for scripts), ``cmd`` (a command as a
query; exit 0 only when accepted, the gateway's reason and exit 1 when refused), ``param``
(read/write through the params queryable; device error text and exit 1 on refusal) and
``health``. The client session connects only to the given endpoint, listens on nothing and
does no multicast scouting. Every query carries the session's source info (its Zenoh id and
a sequence number), so the gateway can tell this client from the others.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import zenoh

from gateway.config import read_zenoh_config_file
from gateway.errors import ConfigError

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
DEFAULT_PREFIX = "demo"
QUERY_TIMEOUT = 10.0

ACTIONS: dict[str, dict[str, Any]] = {
    "run": {"run": True},
    "stop": {"run": False},
    "forward": {"direction": "forward"},
    "reverse": {"direction": "reverse"},
    "reset": {"fault_reset": True},
    "quick-stop": {"quick_stop": True},
    "coast": {"coast_stop": True},
    "speed": {},
}
"""``drive-gateway cmd ID ACTION`` -> the JSON command it sends."""


def client_config(endpoint: str, config_file: str | None = None) -> zenoh.Config:
    """A client session: only ``endpoint``, no listening, no scouting.

    With ``config_file`` (JSON5, e.g. with TLS certificates for a secured
    gateway) that file is the base and ``endpoint`` is added to connect to.
    """
    if config_file is not None:  # bounded and checked first (gateway.config)
        conf = zenoh.Config.from_json5(read_zenoh_config_file(Path(config_file)))
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        return conf
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("listen/endpoints", json.dumps([]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return conf


_CONFIG_FILE: list[str | None] = [None]


@contextmanager
def session(endpoint: str) -> Iterator[zenoh.Session]:
    s = zenoh.open(client_config(endpoint, _CONFIG_FILE[0]))
    try:
        yield s
    finally:
        s.close()


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--connect", default=DEFAULT_CONNECT, help="gateway endpoint")
    p.add_argument("--prefix", default=DEFAULT_PREFIX, help="the gateway's zenoh.prefix")
    p.add_argument(
        "--zenoh-config",
        type=_use_config_file,
        help="a Zenoh JSON5 client config (TLS certificates for a secured gateway)",
    )


def _use_config_file(path: str) -> str:
    try:
        read_zenoh_config_file(Path(path))
    except ConfigError as exc:  # argparse: "error: argument --zenoh-config: ...", exit 2
        raise argparse.ArgumentTypeError(str(exc)) from None
    _CONFIG_FILE[0] = path
    return path


_SEQUENCE = itertools.count(1)


def source_info(s: zenoh.Session, key: str) -> zenoh.SourceInfo:
    """This session's identity for a put or a query on ``key``: the id of a publisher it
    declares there (the session's Zenoh id and an entity id; ``EntityGlobalId`` has no
    constructor) and the next sequence number."""
    publisher = s.declare_publisher(key)
    return zenoh.SourceInfo(publisher.id, next(_SEQUENCE))


def query(endpoint: str, key: str, payload: Any | None = None) -> Any:
    """One query, its first reply as JSON (an error reply as ``{"error": text}``); raises
    RuntimeError when nothing answers."""
    with session(endpoint) as s:
        kwargs: dict[str, Any] = {"timeout": QUERY_TIMEOUT, "source_info": source_info(s, key)}
        if payload is not None:
            kwargs["payload"] = json.dumps(payload)
        for reply in s.get(key, **kwargs):
            if reply.ok is not None:
                return _json_or_text(reply.ok.payload.to_string())
            if reply.err is not None:
                return _error_body(reply.err.payload.to_string())
    raise RuntimeError(f"no answer on {key} from {endpoint}")


def _json_or_text(text: str) -> Any:
    try:
        return json.loads(text)
    except ValueError:
        return {"error": f"not JSON: {text!r}"}


def _error_body(text: str) -> dict[str, Any]:
    """An error reply: the gateway's own ``{"error": ...}`` body, or its text as the error."""
    body = _json_or_text(text)
    if isinstance(body, dict) and "error" in body:
        return body
    return {"error": text}


def _print_json(doc: Any, out: TextIO = sys.stdout) -> None:
    print(json.dumps(doc, indent=2, sort_keys=True), file=out)


# ------------------------------------------------------------------ health


def add_health(sub: Any) -> None:
    p = sub.add_parser("health", help="the gateway's health: live lists and cycle figures")
    _common(p)
    p.set_defaults(handler=cmd_health)


def cmd_health(args: argparse.Namespace) -> int:
    try:
        doc = query(args.connect, f"{args.prefix}/gateway/health")
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    _print_json(doc)
    return 0


# ------------------------------------------------------------------ cmd


def add_cmd(sub: Any) -> None:
    p = sub.add_parser("cmd", help="send a command to a drive and print the gateway's answer")
    _common(p)
    p.add_argument("drive")
    p.add_argument("action", choices=sorted(ACTIONS))
    speed = p.add_mutually_exclusive_group()
    speed.add_argument("--speed-rpm", type=float)
    speed.add_argument("--speed-pct", type=float)
    p.set_defaults(handler=cmd_cmd)


def build_command(args: argparse.Namespace) -> dict[str, Any]:
    command = dict(ACTIONS[args.action])
    if args.speed_rpm is not None:
        command["speed_rpm"] = args.speed_rpm
    if args.speed_pct is not None:
        command["speed_pct"] = args.speed_pct
    return command


def cmd_cmd(args: argparse.Namespace) -> int:
    command = build_command(args)
    if not command:
        print("error: give --speed-rpm or --speed-pct with 'speed'", file=sys.stderr)
        return 2
    try:
        answer = query(args.connect, f"{args.prefix}/drives/{args.drive}/command", command)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if isinstance(answer, dict) and answer.get("accepted") is True:
        print(f"{args.drive}: accepted {json.dumps(command)}")
        return 0
    print(f"{args.drive}: refused: {refusal_reason(answer)}", file=sys.stderr)
    return 1


def refusal_reason(answer: Any) -> str:
    """The gateway's reason for a refused command (``{"accepted": false, "error": ...}`` or
    an error reply), else the answer as it came."""
    if isinstance(answer, dict) and isinstance(answer.get("error"), str):
        return str(answer["error"])
    return json.dumps(answer)


# ------------------------------------------------------------------ param


def add_param(sub: Any) -> None:
    p = sub.add_parser("param", help="read or write a drive parameter")
    _common(p)
    p.add_argument("drive")
    ops = p.add_subparsers(dest="op", required=True)
    r = ops.add_parser("read")
    r.add_argument("number", type=param_number, help="100 or P0100")
    r.add_argument("--subindex", type=int, default=0)
    w = ops.add_parser("write")
    w.add_argument("number", type=param_number, help="100 or P0100")
    w.add_argument("value", type=float)
    w.add_argument("--subindex", type=int, default=0)
    p.set_defaults(handler=cmd_param)


def param_number(text: str) -> int:
    """A parameter number as the manuals write it ("P0100", "p100") or bare ("100")."""
    digits = text[1:] if text[:1] in ("P", "p") else text
    if not digits.isascii() or not digits.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r} is not a parameter number (100 or P0100)")
    return int(digits)


def param_line(answer: dict[str, Any], number: int) -> str:
    """``P0100 Acceleration time = 2.0 s`` where the drive's table knows the parameter,
    else ``P100 = 20`` (the raw value)."""
    sub = answer.get("subindex", 0)
    code = answer.get("code") or f"P{answer.get('number', number)}"
    if sub:
        code += f".{sub}"
    if "name" not in answer:
        return f"{code} = {answer.get('value')}"
    unit = f" {answer['unit']}" if answer.get("unit") else ""
    return f"{code} {answer['name']} = {answer.get('scaled', answer.get('value'))}{unit}"


def cmd_param(args: argparse.Namespace) -> int:
    key = f"{args.prefix}/drives/{args.drive}/params/{args.number}"
    if args.subindex:
        key += f"/{args.subindex}"
    payload = None
    if args.op == "write":
        value: float | int = int(args.value) if args.value.is_integer() else args.value
        payload = {"value": value}
    try:
        answer = query(args.connect, key, payload)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if "error" in answer:
        print(f"{args.drive} P{args.number}: {answer['error']}", file=sys.stderr)
        return 1
    print(param_line(answer, args.number))
    return 0


# ------------------------------------------------------------------ watch

COLUMNS = ("id", "device", "comm", "status", "speed", "current", "fault", "age", "last comm event")
_TRANSITION = re.compile(r"comm \w+ -> \w+")  # the hub's own comm events: no reason in them


@dataclass
class Board:
    """What ``watch`` knows: the newest state per drive and who is alive."""

    states: dict[str, dict[str, Any]] = field(default_factory=dict)
    received: dict[str, float] = field(default_factory=dict)
    alive: set[str] = field(default_factory=set)
    comm_events: dict[str, tuple[str, float]] = field(default_factory=dict)  # text, received
    lock: threading.Lock = field(default_factory=threading.Lock)
    changed: threading.Event = field(default_factory=threading.Event)

    def on_state(self, doc: dict[str, Any]) -> None:
        with self.lock:
            self.states[doc["id"]] = doc
            self.received[doc["id"]] = time.monotonic()
        self.changed.set()

    def on_event(self, doc: dict[str, Any]) -> None:
        """Keep a drive's last comm event that says why (left data exchange: the reason)."""
        text = doc.get("text")
        if doc.get("kind") != "comm" or not isinstance(text, str) or _TRANSITION.fullmatch(text):
            return
        with self.lock:
            self.comm_events[str(doc.get("drive"))] = (text, time.monotonic())
        self.changed.set()

    def on_alive(self, drive_id: str, alive: bool) -> None:
        with self.lock:
            (self.alive.add if alive else self.alive.discard)(drive_id)
        self.changed.set()

    def rows(self, now: float) -> list[tuple[str, ...]]:
        with self.lock:
            return [self._row(d, now) for d in sorted(self.states.values(), key=lambda d: d["id"])]

    def _row(self, d: dict[str, Any], now: float) -> tuple[str, ...]:
        speed = "-" if d.get("speed_rpm") is None else f"{d['speed_rpm']:.0f} rpm"
        if d.get("current_a") is not None:
            current = f"{d['current_a']:.1f} A"
        elif d.get("current_pct_flc") is not None:
            current = f"{d['current_pct_flc']:.0f} %FLC"
        else:
            current = "-"
        fault = "-"
        if d.get("fault_code") is not None:
            fault = f"{d['fault_code']} {d.get('fault_text') or ''}".strip()
        comm = d.get("comm", "?")
        if d["id"] not in self.alive and comm == "online":
            comm = "gone"
        age = f"{now - self.received.get(d['id'], now):.1f}s"
        why = "-"
        if d["id"] in self.comm_events:
            text, at = self.comm_events[d["id"]]
            why = f"{text} ({now - at:.0f}s ago)"
        return (
            d["id"],
            str(d.get("device")),
            comm,
            str(d.get("status")),
            speed,
            current,
            fault,
            age,
            why,
        )


def render(rows: list[tuple[str, ...]]) -> str:
    table = [COLUMNS, *rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in table)


def add_watch(sub: Any) -> None:
    p = sub.add_parser("watch", help="live table of every drive the gateway publishes")
    _common(p)
    p.add_argument("--once", action="store_true", help="print one snapshot and exit")
    p.add_argument("--wait", type=float, default=1.5, help="s to collect states for --once")
    p.set_defaults(handler=cmd_watch)


def _key_drive(key: str, prefix: str) -> str | None:
    parts = key[len(prefix) + 1 :].split("/") if key.startswith(prefix + "/") else []
    return parts[1] if len(parts) >= 2 and parts[0] == "drives" else None


def cmd_watch(args: argparse.Namespace) -> int:
    board = Board()
    prefix = args.prefix

    def on_sample(sample: zenoh.Sample) -> None:
        with suppress(ValueError, KeyError):
            board.on_state(json.loads(sample.payload.to_string()))

    def on_event(sample: zenoh.Sample) -> None:
        with suppress(ValueError, KeyError):
            board.on_event(json.loads(sample.payload.to_string()))

    def on_token(sample: zenoh.Sample) -> None:
        drive = _key_drive(str(sample.key_expr), prefix)
        if drive is not None:
            board.on_alive(drive, sample.kind == zenoh.SampleKind.PUT)

    with session(args.connect) as s:
        sub_states = s.declare_subscriber(f"{prefix}/drives/*/state", on_sample)
        sub_events = s.declare_subscriber(f"{prefix}/drives/*/events", on_event)
        sub_alive = s.liveliness().declare_subscriber(f"{prefix}/drives/*", on_token, history=True)
        try:
            if args.once:
                board.changed.wait(args.wait)
                deadline = time.monotonic() + args.wait
                while time.monotonic() < deadline:
                    board.changed.wait(max(0.0, deadline - time.monotonic()))
                    board.changed.clear()
                print(render(board.rows(time.monotonic())))
                return 0 if board.states else 1
            return _live(board)
        except KeyboardInterrupt:
            return 0
        finally:
            sub_states.undeclare()
            sub_events.undeclare()
            sub_alive.undeclare()


def _live(board: Board) -> int:
    tty = sys.stdout.isatty() and os.environ.get("TERM") != "dumb"
    while True:
        board.changed.wait(1.0)
        board.changed.clear()
        text = render(board.rows(time.monotonic()))
        if tty:
            sys.stdout.write("\x1b[H\x1b[2J" + text + "\n")
        else:
            sys.stdout.write(text + "\n\n")
        sys.stdout.flush()
