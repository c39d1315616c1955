"""Operator tools: Zenoh clients for any running gateway (``--connect ENDPOINT``).

``watch`` (live table of drives; ``--once`` asks for the states and says which drive is
missing), ``cmd`` (a command as a query; prints the state that results; exit 0 only when
accepted and followed), ``param`` (read/write through the params queryable; device error
text and exit 1 on refusal) and ``health``; ``params`` (backup, diff, restore) is in
:mod:`gateway.cli.params`. Every tool takes ``--json``. The client session connects only to
the given endpoint, listens on nothing and does no multicast scouting. Every query carries
the session's source info (its Zenoh id and a sequence number), so the gateway can tell
this client from the others.

Exit status of every tool: 0 done; 1 refused, failed, or a drive missing or not following;
2 a usage error; 3 no gateway answers (docs/operations.md, "Command line").
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
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import zenoh

from gateway.config import parse_param_ref, read_zenoh_config_file
from gateway.devices import code_text
from gateway.errors import ConfigError, GatewayError

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
DEFAULT_PREFIX = "demo"
QUERY_TIMEOUT = 10.0
GATEWAY_TIMEOUT = 3.0  # s to wait for the gateway's liveliness token
CMD_WAIT = 5.0  # s ``cmd`` waits for the drive to follow

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_GATEWAY = 0, 1, 2, 3

ACTIONS: dict[str, dict[str, Any]] = {
    "run": {"run": True},
    "stop": {"run": False},
    "forward": {"direction": "forward"},
    "reverse": {"direction": "reverse"},
    "reset": {"fault_reset": True},
    "quick-stop": {"quick_stop": True},
    "quick-stop-release": {"quick_stop": False},
    "coast": {"coast_stop": True},
    "coast-release": {"coast_stop": False},
    "jog": {"jog": True},
    "jog-stop": {"jog": False},
    "remote": {"remote": True},
    "local": {"remote": False},
    "speed": {},
}
"""``drive-gateway cmd ID ACTION`` -> the JSON command it sends (every field of the
command model: a test checks it against ``gateway.model.COMMAND_FIELDS``)."""

ACTION_HELP: dict[str, str] = {
    "run": "run (a new run command: needed after every stop reason)",
    "stop": "stop (ramp)",
    "forward": "turn forward",
    "reverse": "turn in reverse",
    "reset": "one fault reset edge",
    "quick-stop": "quick stop (latched until released)",
    "quick-stop-release": "release the quick stop (the drive stays stopped until run)",
    "coast": "coast stop: the output off (latched until released)",
    "coast-release": "release the coast stop (the drive stays stopped until run)",
    "jog": "jog",
    "jog-stop": "end the jog",
    "remote": "take network control",
    "local": "leave network control",
    "speed": "a speed reference only (with --speed-rpm or --speed-pct)",
}

Predicate = Callable[[dict[str, Any]], bool]
_STOPPED = ("ready", "not_ready", "stopping", "faulted", "tripped")

FOLLOWS: dict[str, tuple[str, Predicate]] = {
    "run": ("running", lambda s: bool(s.get("running")) or s.get("status") == "starting"),
    "stop": ("stopping or stopped", lambda s: s.get("status") in _STOPPED),
    "reset": ("no fault", lambda s: s.get("status") not in ("faulted", "tripped")),
    "quick-stop": ("stopping or stopped", lambda s: s.get("status") in _STOPPED),
    "coast": ("stopping or stopped", lambda s: s.get("status") in _STOPPED),
    "jog": ("running", lambda s: bool(s.get("running"))),
    "jog-stop": ("stopping or stopped", lambda s: s.get("status") in _STOPPED),
    "remote": ("in remote", lambda s: s.get("remote") is True),
    "local": ("out of remote", lambda s: s.get("remote") is False),
}
"""Action -> what the drive's state shows once it followed (the others: the state as it is)."""


class NoGateway(GatewayError):
    """No gateway answered (exit 3)."""


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
        _PUBLISHERS.pop(id(s), None)
        s.close()


JSON_HELP = "print JSON instead of text (default: text)"


def add_common(p: argparse.ArgumentParser, json_help: str = JSON_HELP) -> None:
    """``--connect``, ``--prefix``, ``--zenoh-config`` and ``--json`` of every tool."""
    p.add_argument(
        "--connect",
        default=DEFAULT_CONNECT,
        metavar="ENDPOINT",
        help="the gateway's Zenoh endpoint (default: %(default)s)",
    )
    p.add_argument(
        "--prefix",
        default=DEFAULT_PREFIX,
        help="the gateway's zenoh.prefix (default: %(default)s)",
    )
    p.add_argument(
        "--zenoh-config",
        type=_use_config_file,
        metavar="FILE",
        help="a Zenoh JSON5 client config (TLS certificates for a secured gateway; default: none)",
    )
    p.add_argument("--json", action="store_true", help=json_help)


_common = add_common


def add_common_after(p: argparse.ArgumentParser) -> None:
    """The options of :func:`add_common` once more on a sub-subcommand (``param DRIVE read``),
    so they may come anywhere on the line; given there they win, absent they leave the
    values given before (or the defaults) as they are."""
    before = "default: as given before the drive, else"
    for flags, kwargs in (
        (
            ("--connect",),
            {
                "metavar": "ENDPOINT",
                "help": f"the gateway's Zenoh endpoint ({before} {DEFAULT_CONNECT})",
            },
        ),
        (("--prefix",), {"help": f"the gateway's zenoh.prefix ({before} {DEFAULT_PREFIX})"}),
        (
            ("--zenoh-config",),
            {
                "type": _use_config_file,
                "metavar": "FILE",
                "help": f"a Zenoh JSON5 client config ({before} none)",
            },
        ),
        (
            ("--json",),
            {"action": "store_true", "help": f"print JSON instead of text ({before} text)"},
        ),
    ):
        p.add_argument(*flags, default=argparse.SUPPRESS, **kwargs)


def _use_config_file(path: str) -> str:
    try:
        read_zenoh_config_file(Path(path))
    except ConfigError as exc:  # argparse: "error: argument --zenoh-config: ...", exit 2
        raise argparse.ArgumentTypeError(str(exc)) from None
    _CONFIG_FILE[0] = path
    return path


_SEQUENCE = itertools.count(1)


_PUBLISHERS: dict[int, tuple[zenoh.Session, Any]] = {}


def source_info(s: zenoh.Session, key: str) -> zenoh.SourceInfo:
    """This session's identity for a put or a query on ``key``: the id of a publisher it
    declares (the session's Zenoh id and an entity id; ``EntityGlobalId`` has no
    constructor; one per session, kept with the session so an id is never another
    session's) and the next sequence number."""
    cached = _PUBLISHERS.get(id(s))
    if cached is None or cached[0] is not s:
        cached = _PUBLISHERS[id(s)] = (s, s.declare_publisher(key.split("?", 1)[0]))
    return zenoh.SourceInfo(cached[1].id, next(_SEQUENCE))


def query_in(
    s: zenoh.Session, key: str, payload: Any | None = None, timeout: float = QUERY_TIMEOUT
) -> Any:
    """One query on an open session, its first reply as JSON (an error reply as
    ``{"error": text}``); raises RuntimeError when nothing answers."""
    kwargs: dict[str, Any] = {"timeout": timeout, "source_info": source_info(s, key)}
    if payload is not None:
        kwargs["payload"] = json.dumps(payload)
    for reply in s.get(key, **kwargs):
        if reply.ok is not None:
            return _json_or_text(reply.ok.payload.to_string())
        if reply.err is not None:
            return _error_body(reply.err.payload.to_string())
    raise RuntimeError(f"no answer on {key}")


def query(endpoint: str, key: str, payload: Any | None = None) -> Any:
    """:func:`query_in` on a session of its own."""
    with session(endpoint) as s:
        try:
            return query_in(s, key, payload)
        except RuntimeError:
            raise RuntimeError(f"no answer on {key} from {endpoint}") from None


def query_or_no_gateway(args: argparse.Namespace, key: str, payload: Any | None = None) -> Any:
    """:func:`query_in` on a session of its own; when nothing answers, :class:`NoGateway`
    (exit 3) if the gateway's liveliness token is not there either, else RuntimeError (a
    gateway that does not answer this key: exit 1)."""
    with session(args.connect) as s:
        try:
            return query_in(s, key, payload)
        except RuntimeError:
            if not gateway_alive(s, args.prefix):
                raise NoGateway(no_gateway_text(args)) from None
            raise RuntimeError(f"no answer on {key} from {args.connect}") from None


def query_all(s: zenoh.Session, key: str, timeout: float = QUERY_TIMEOUT) -> list[Any]:
    """Every good reply of a query (a wildcard key), as JSON."""
    kwargs: dict[str, Any] = {"timeout": timeout, "source_info": source_info(s, key)}
    out = []
    for reply in s.get(key, **kwargs):
        if reply.ok is not None:
            out.append(_json_or_text(reply.ok.payload.to_string()))
    return out


def gateway_alive(s: zenoh.Session, prefix: str, timeout: float = GATEWAY_TIMEOUT) -> bool:
    """True when the gateway's liveliness token ``<prefix>/gateway`` is there."""
    return any(r.ok is not None for r in s.liveliness().get(f"{prefix}/gateway", timeout=timeout))


def no_gateway_text(args: argparse.Namespace) -> str:
    return (
        f"no gateway answers at {args.connect} under prefix {args.prefix!r} "
        "(is it running? is --connect or --prefix wrong?)"
    )


def require_gateway(s: zenoh.Session, args: argparse.Namespace) -> None:
    if not gateway_alive(s, args.prefix):
        raise NoGateway(no_gateway_text(args))


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


def fail(text: str, code: int = EXIT_FAILED) -> int:
    print(f"error: {text}", file=sys.stderr)
    return code


# ------------------------------------------------------------------ health


def add_health(sub: Any) -> None:
    p = sub.add_parser(
        "health",
        help="the gateway's health: live lists and cycle figures",
        description="Ask the gateway for its health: name, version, uptime, drives, per "
        "bus the live list and cycle figures. The answer is printed as JSON, with or "
        "without --json.",
        epilog="exit status: 0 answered; 1 the gateway did not answer the health query; "
        "3 no gateway answers.",
    )
    _common(
        p,
        json_help="accepted for scripts that give it to every tool; the health is "
        "always printed as JSON",
    )
    p.set_defaults(handler=cmd_health)


def cmd_health(args: argparse.Namespace) -> int:
    try:
        doc = query_or_no_gateway(args, f"{args.prefix}/gateway/health")
    except NoGateway as exc:
        return fail(str(exc), EXIT_NO_GATEWAY)
    except RuntimeError as exc:
        return fail(str(exc))
    _print_json(doc)
    return 0


# ------------------------------------------------------------------ cmd


def add_cmd(sub: Any) -> None:
    actions = "\n".join(f"  {name:<19} {ACTION_HELP[name]}" for name in ACTIONS)
    p = sub.add_parser(
        "cmd",
        help="send a command to a drive and print the state that results",
        description="Send one command to a drive as a query and print the gateway's answer, "
        "then the drive's state once it followed (or why it did not).",
        epilog=f"actions:\n{actions}\n\nexit status: 0 accepted and followed; 1 refused, "
        "or the drive did not follow within --wait; 2 usage; 3 no gateway answers.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _common(p)
    p.add_argument("drive", help="the drive's id")
    p.add_argument("action", choices=list(ACTIONS), help="what to do (the list below)")
    speed = p.add_mutually_exclusive_group()
    speed.add_argument(
        "--speed-rpm", type=float, metavar="RPM", help="speed reference in rpm (default: none)"
    )
    speed.add_argument(
        "--speed-pct",
        type=float,
        metavar="PCT",
        help="speed reference in %% of the drive's scale base (default: none)",
    )
    p.add_argument(
        "--wait",
        type=float,
        default=CMD_WAIT,
        metavar="S",
        help="s to wait for the drive to follow; 0: print the answer only (default: %(default)s)",
    )
    p.set_defaults(handler=cmd_cmd)


def build_command(args: argparse.Namespace) -> dict[str, Any]:
    command = dict(ACTIONS[args.action])
    if args.speed_rpm is not None:
        command["speed_rpm"] = args.speed_rpm
    if args.speed_pct is not None:
        command["speed_pct"] = args.speed_pct
    return command


def _code(state: dict[str, Any], name: str) -> str:
    """A code of a state JSON as the drive's documents write it (``0x8130`` for CANopen)."""
    code = state.get(name)
    if isinstance(code, bool) or not isinstance(code, int):
        return str(code)
    device = state.get("device")
    return code_text(device if isinstance(device, str) else None, code)


def state_line(s: dict[str, Any]) -> str:
    """``cfw11: online running forward 900 rpm (ref 900 rpm) remote`` and the fault."""
    parts = [str(s.get("comm")), str(s.get("status")), str(s.get("direction"))]
    if s.get("speed_rpm") is not None:
        parts.append(f"{s['speed_rpm']:.0f} rpm")
    if s.get("speed_ref_rpm") is not None:
        parts.append(f"(ref {s['speed_ref_rpm']:.0f} rpm)")
    parts.append("remote" if s.get("remote") else "local")
    if s.get("fault_code") is not None:
        parts.append(f"fault {_code(s, 'fault_code')} {s.get('fault_text') or ''}".rstrip())
    return f"{s.get('id')}: " + " ".join(parts)


def why_not(s: dict[str, Any], action: str, wait: float) -> str:
    """Why a drive did not follow an accepted command, from its state."""
    if s.get("comm") != "online":
        return f"the drive is not online (comm {s.get('comm')})"
    if s.get("status") in ("faulted", "tripped") and action != "reset":
        return f"the drive is {s.get('status')} ({_code(s, 'fault_code')} {s.get('fault_text')})"
    if not s.get("remote") and action not in ("remote", "local"):
        return "the drive is not in remote: the network is not in control of it"
    return f"it did not within {wait:g} s"


class StateWatch:
    """The newest state of one drive, from a subscription opened before the command."""

    def __init__(self, s: zenoh.Session, key: str) -> None:
        self.latest: dict[str, Any] | None = None
        self.changed = threading.Condition()
        self.sub = s.declare_subscriber(key, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        with suppress(ValueError):
            doc = json.loads(sample.payload.to_string())
            with self.changed:
                self.latest = doc
                self.changed.notify_all()

    def until(self, predicate: Predicate, wait: float) -> dict[str, Any] | None:
        deadline = time.monotonic() + wait
        with self.changed:
            while self.latest is None or not predicate(self.latest):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.changed.wait(left)
            return self.latest

    def close(self) -> None:
        self.sub.undeclare()


def cmd_cmd(args: argparse.Namespace) -> int:
    command = build_command(args)
    if not command:
        return fail("give --speed-rpm or --speed-pct with 'speed'", EXIT_USAGE)
    prefix, drive = args.prefix, args.drive
    with session(args.connect) as s:
        watch = StateWatch(s, f"{prefix}/drives/{drive}/state") if args.wait > 0 else None
        try:
            try:
                answer = query_in(s, f"{prefix}/drives/{drive}/command", command)
            except RuntimeError:
                return fail(no_gateway_text(args), EXIT_NO_GATEWAY)
            accepted = isinstance(answer, dict) and answer.get("accepted") is True
            result: dict[str, Any] = {"drive": drive, "command": command, "accepted": accepted}
            if not accepted:
                result["error"] = refusal_reason(answer)
                return _cmd_report(args, result, EXIT_FAILED)
            if watch is None:
                return _cmd_report(args, result, EXIT_OK)
            return _cmd_followed(args, s, watch, result)
        finally:
            if watch is not None:
                watch.close()


def _cmd_followed(
    args: argparse.Namespace, s: zenoh.Session, watch: StateWatch, result: dict[str, Any]
) -> int:
    expected = FOLLOWS.get(args.action)
    if watch.latest is None:  # nothing published yet since the command: ask for it
        with suppress(RuntimeError):
            state = query_in(s, f"{args.prefix}/drives/{args.drive}/state", timeout=args.wait)
            if isinstance(state, dict) and "id" in state:
                with watch.changed:
                    watch.latest = watch.latest or state
    if expected is None:
        state = watch.until(lambda _s: True, 0.0)
        result.update(state=state, followed=None)
        return _cmd_report(args, result, EXIT_OK)
    what, predicate = expected
    state = watch.until(predicate, args.wait)
    followed = state is not None and predicate(state)
    result.update(state=state, followed=followed, expected=what)
    if not followed:
        result["why"] = (
            f"no state of the drive within {args.wait:g} s"
            if state is None
            else why_not(state, args.action, args.wait)
        )
    return _cmd_report(args, result, EXIT_OK if followed else EXIT_FAILED)


def _cmd_report(args: argparse.Namespace, result: dict[str, Any], code: int) -> int:
    if args.json:
        _print_json(result)
        return code
    drive = args.drive
    if not result["accepted"]:
        print(f"{drive}: refused: {result['error']}", file=sys.stderr)
        return code
    print(f"{drive}: accepted {json.dumps(result['command'])}")
    state = result.get("state")
    if state is not None:
        print(state_line(state))
    if result.get("followed") is False:
        print(f"{drive}: accepted, but not {result['expected']}: {result['why']}", file=sys.stderr)
    return code


def refusal_reason(answer: Any) -> str:
    """The gateway's reason for a refused command (``{"accepted": false, "error": ...}`` or
    an error reply), else the answer as it came."""
    if isinstance(answer, dict) and isinstance(answer.get("error"), str):
        return str(answer["error"])
    return json.dumps(answer)


# ------------------------------------------------------------------ param


def add_param(sub: Any) -> None:
    p = sub.add_parser(
        "param",
        help="read or write one drive parameter",
        description="Read or write one parameter through the gateway's params service "
        "(writes only to the drive's writable_params). --connect, --prefix, --zenoh-config "
        "and --json may come before or after the drive.",
        epilog="exit status: 0 done; 1 refused by the gateway or the drive, or no answer "
        "for this drive; 2 usage; 3 no gateway answers.",
    )
    _common(p)
    p.add_argument("drive", help="the drive's id")
    ops = p.add_subparsers(dest="op", required=True, metavar="OP")
    r = ops.add_parser("read", help="read a parameter", description="Read a parameter.")
    r.add_argument("number", type=param_ref, help="the parameter: 100, P0100, 0x6083 or 0x2000:1")
    r.add_argument("--subindex", type=int, default=0, help="subindex (default: %(default)s)")
    add_common_after(r)
    w = ops.add_parser(
        "write", help="write a parameter (raw value)", description="Write a parameter."
    )
    w.add_argument("number", type=param_ref, help="the parameter: 100, P0100, 0x6083 or 0x2000:1")
    w.add_argument("value", type=float, help="the raw value (P0100 = 2.0 s is 20)")
    w.add_argument("--subindex", type=int, default=0, help="subindex (default: %(default)s)")
    add_common_after(w)
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


def param_ref(text: str) -> tuple[int, int | None]:
    """A parameter as the manuals write it ("P0100", "100") or a CANopen object ("0x6083",
    "0x2000:1" with its subindex)."""
    try:
        return parse_param_ref(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def cmd_param(args: argparse.Namespace) -> int:
    number, subindex = args.number
    if subindex is not None and args.subindex and args.subindex != subindex:
        return fail(f"{number:#06x}:{subindex} and --subindex {args.subindex} disagree")
    subindex = args.subindex if subindex is None else subindex
    args.number = number
    key = f"{args.prefix}/drives/{args.drive}/params/{number}"
    if subindex:
        key += f"/{subindex}"
    payload = None
    if args.op == "write":
        value: float | int = int(args.value) if args.value.is_integer() else args.value
        payload = {"value": value}
    try:
        answer = query_or_no_gateway(args, key, payload)
    except NoGateway as exc:
        return fail(str(exc), EXIT_NO_GATEWAY)
    except RuntimeError as exc:
        return fail(str(exc))
    if args.json:
        _print_json(answer)
        return EXIT_FAILED if "error" in answer else EXIT_OK
    if "error" in answer:
        print(f"{args.drive} P{args.number}: {answer['error']}", file=sys.stderr)
        return EXIT_FAILED
    print(param_line(answer, args.number))
    return EXIT_OK


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
    gateway: bool | None = None  # its liveliness token: None before the first word
    gateway_since: float = 0.0  # wall clock of the last change of ``gateway``
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

    def on_gateway(self, alive: bool) -> None:
        with self.lock:
            if self.gateway is not alive:
                self.gateway = alive
                self.gateway_since = time.time()
        self.changed.set()

    def header(self, where: str) -> str:
        with self.lock:
            alive, since = self.gateway, self.gateway_since
        if alive is None:
            return f"gateway {where}: no answer yet"
        at = time.strftime("%H:%M:%S", time.localtime(since))
        if alive:
            return f"gateway {where}: serving (seen at {at})"
        return (
            f"gateway {where}: GONE at {at}: its liveliness token was withdrawn (stopped, or "
            "its process died or lost the network); the rows are its last words"
        )

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
            fault = f"{_code(d, 'fault_code')} {d.get('fault_text') or ''}".strip()
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
    p = sub.add_parser(
        "watch",
        help="live table of every drive the gateway publishes",
        description="A live table of every drive: state, speed, current, fault and the last "
        "comm event that says why a drive left; a line says when the gateway is gone. "
        "--once asks the gateway for every state instead and exits.",
        epilog="exit status (--once): 0 every drive answered and is online; 1 a drive is "
        "missing or not online (named on stderr); 3 no gateway answers.",
    )
    _common(p)
    p.add_argument(
        "--once",
        action="store_true",
        help="ask for every drive's state, print it and exit (default: live)",
    )
    p.add_argument(
        "drives",
        nargs="*",
        metavar="DRIVE",
        help="with --once: the drives that must be there (default: every drive of the "
        "gateway's config)",
    )
    p.set_defaults(handler=cmd_watch)


def _key_drive(key: str, prefix: str) -> str | None:
    parts = key[len(prefix) + 1 :].split("/") if key.startswith(prefix + "/") else []
    return parts[1] if len(parts) >= 2 and parts[0] == "drives" else None


def cmd_watch(args: argparse.Namespace) -> int:
    if args.once:
        return _watch_once(args)
    if args.drives:
        return fail("DRIVE arguments go with --once", EXIT_USAGE)
    return _watch_live(args)


def once_problems(states: list[dict[str, Any]], expected: list[str]) -> list[tuple[str, str]]:
    """(drive, what is wrong) for every expected drive not answered or not online."""
    by_id = {str(s.get("id")): s for s in states}
    problems = []
    for drive in expected:
        state = by_id.get(drive)
        if state is None:
            problems.append((drive, "missing: the gateway did not answer its state"))
        elif state.get("comm") != "online":
            problems.append((drive, f"not online (comm {state.get('comm')})"))
    return problems


def _watch_once(args: argparse.Namespace) -> int:
    prefix = args.prefix
    with session(args.connect) as s:
        if not gateway_alive(s, prefix):
            return fail(no_gateway_text(args), EXIT_NO_GATEWAY)
        states = [d for d in query_all(s, f"{prefix}/drives/*/state") if "id" in d]
        expected = list(args.drives)
        if not expected:
            try:
                health = query_in(s, f"{prefix}/gateway/health")
            except RuntimeError:
                return fail(no_gateway_text(args), EXIT_NO_GATEWAY)
            expected = list(health.get("drive_ids", [])) or [str(d["id"]) for d in states]
    problems = once_problems(states, expected)
    states.sort(key=lambda d: str(d["id"]))
    if args.json:
        _print_json(
            {
                "gateway": {"connect": args.connect, "prefix": prefix, "alive": True},
                "drives": states,
                "problems": [{"drive": d, "problem": p} for d, p in problems],
            }
        )
    else:
        board = Board()
        for state in states:
            board.on_state(state)
            if state.get("comm") == "online":
                board.on_alive(str(state["id"]), True)
        print(render(board.rows(time.monotonic())))
    for drive, problem in problems:
        print(f"error: drive {drive}: {problem}", file=sys.stderr)
    return EXIT_FAILED if problems else EXIT_OK


def _watch_live(args: argparse.Namespace) -> int:
    board = Board()
    prefix = args.prefix
    emit = _json_line if args.json else None

    def on_sample(sample: zenoh.Sample) -> None:
        with suppress(ValueError, KeyError):
            doc = json.loads(sample.payload.to_string())
            board.on_state(doc)
            if emit:
                emit({"type": "state", **doc})

    def on_event(sample: zenoh.Sample) -> None:
        with suppress(ValueError, KeyError):
            doc = json.loads(sample.payload.to_string())
            board.on_event(doc)
            if emit:
                emit({"type": "event", **doc})

    def on_token(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        alive = sample.kind == zenoh.SampleKind.PUT
        if key == f"{prefix}/gateway":
            board.on_gateway(alive)
            if emit:
                emit({"type": "gateway", "alive": alive, "ts": time.time()})
            return
        drive = _key_drive(key, prefix)
        if drive is not None:
            board.on_alive(drive, alive)
            if emit:
                emit({"type": "live", "drive": drive, "alive": alive, "ts": time.time()})

    with session(args.connect) as s:
        subs: list[zenoh.Subscriber[None]] = []
        try:  # Ctrl-C ends the watch from here on: the first states print while it declares
            subs.append(s.declare_subscriber(f"{prefix}/drives/*/state", on_sample))
            subs.append(s.declare_subscriber(f"{prefix}/drives/*/events", on_event))
            live = s.liveliness()
            subs.append(live.declare_subscriber(f"{prefix}/drives/*", on_token, history=True))
            subs.append(live.declare_subscriber(f"{prefix}/gateway", on_token, history=True))
            if not gateway_alive(s, prefix):
                board.on_gateway(False)
                print(f"error: {no_gateway_text(args)}; waiting for it", file=sys.stderr)
            if emit:
                threading.Event().wait()  # the callbacks print; Ctrl-C ends it
            return _live(board, f"{prefix} at {args.connect}")
        except KeyboardInterrupt:
            return EXIT_OK
        finally:
            for sub in subs:
                sub.undeclare()


_PRINT_LOCK = threading.Lock()


def _json_line(doc: dict[str, Any]) -> None:
    with _PRINT_LOCK:
        sys.stdout.write(json.dumps(doc, sort_keys=True) + "\n")
        sys.stdout.flush()


def _live(board: Board, where: str) -> int:
    tty = sys.stdout.isatty() and os.environ.get("TERM") != "dumb"
    while True:
        board.changed.wait(1.0)
        board.changed.clear()
        text = board.header(where) + "\n" + render(board.rows(time.monotonic()))
        if tty:
            sys.stdout.write("\x1b[H\x1b[2J" + text + "\n")
        else:
            sys.stdout.write(text + "\n\n")
        sys.stdout.flush()
