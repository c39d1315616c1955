"""``drive-gateway history DRIVE``: a drive's readings (or events) from the history file,
as CSV or JSON.

It reads the file directly, read-only, so it works on the box while the gateway runs (WAL:
it never waits for the writer) and after it died; the file is the config's
``history.path`` or ``--file``. ``--start``, ``--end`` and ``--step`` take the forms of
the Zenoh history key (gateway/history/query.py): ``--start now-1d --step 15m``.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from gateway.cli.check import load_or_report
from gateway.config import DEFAULT_CONFIG
from gateway.errors import HistoryError
from gateway.history.query import columns_json, parse_range
from gateway.history.store import READINGS, HistoryRow, HistoryStore


def add_history(sub: Any) -> None:
    p = sub.add_parser("history", help="a drive's readings or events from the history file")
    p.add_argument("drive", metavar="DRIVE", help="drive id, or * with --events for every drive")
    p.add_argument("--config", default=str(DEFAULT_CONFIG), help="config file (its [history] path)")
    p.add_argument("--file", help="the history file (instead of the config's history.path)")
    p.add_argument("--start", default="", help="from (default: an hour before --end)")
    p.add_argument("--end", default="", help="until (default: now)")
    p.add_argument("--step", default="", help="average per bucket of this duration (15m, 60)")
    p.add_argument("--events", action="store_true", help="the events instead of the readings")
    p.add_argument("--format", choices=("csv", "json"), default="csv", help="output format")
    p.set_defaults(handler=cmd_history)


def _path(args: argparse.Namespace) -> Path | None:
    if args.file:
        return Path(args.file)
    config = load_or_report(args.config)
    return None if config is None else config.history.path


def cmd_history(args: argparse.Namespace) -> int:
    path = _path(args)
    if path is None:
        return 2
    if not path.is_file():
        print(f"drive-gateway history: no history file at {path}", file=sys.stderr)
        return 1
    store = HistoryStore(path)
    params = {k: getattr(args, k) for k in ("start", "end", "step") if getattr(args, k)}
    try:
        asked = parse_range(params, time.time())
        if args.events:
            drive = None if args.drive == "*" else args.drive
            events = [e.to_json() for e in store.events(drive, asked.start, asked.end)]
            _write_events(sys.stdout, events, args.format)
            return 0
        rows = store.readings(args.drive, asked.start, asked.end, asked.step)
    except HistoryError as exc:
        print(f"drive-gateway history: {exc}", file=sys.stderr)
        return 2
    if args.format == "json":
        json.dump(columns_json(args.drive, asked, rows), sys.stdout)
        sys.stdout.write("\n")
    else:
        _write_csv(sys.stdout, rows)
    return 0


def _write_csv(out: TextIO, rows: list[HistoryRow]) -> None:
    names = [n for n in READINGS if any(r.values.get(n) is not None for r in rows)]
    writer = csv.writer(out)
    writer.writerow(["t", "time", *names])
    for r in rows:
        iso = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(r.t)) + f".{int(r.t % 1 * 1000):03d}Z"
        writer.writerow(
            [f"{r.t:.3f}", iso, *("" if r.values[n] is None else r.values[n] for n in names)]
        )


def _write_events(out: TextIO, events: list[dict[str, Any]], fmt: str) -> None:
    if fmt == "json":
        json.dump({"events": events}, out, default=str)
        out.write("\n")
        return
    writer = csv.writer(out)
    writer.writerow(["ts", "drive", "kind", "text", "data"])
    for e in events:
        data = {k: v for k, v in e.items() if k not in ("ts", "drive", "kind", "text")}
        writer.writerow(
            [f"{e['ts']:.3f}", e["drive"], e["kind"], e["text"], json.dumps(data, default=str)]
        )
