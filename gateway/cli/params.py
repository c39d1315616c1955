"""``drive-gateway params``: backup, diff and restore of a drive's parameters through a
running gateway (the document and the rules: :mod:`gateway.paramsbackup`).

The tool asks the gateway for the drive's identity, parameter table and
``writable_params`` (``<prefix>/drives/<id>/params?describe``), then reads or writes one
parameter per query on the existing params keys, so it can show its progress: a bar on a
terminal, one line per parameter otherwise (on stderr; stdout carries the result).
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import zenoh

from gateway import paramsbackup as pb
from gateway.adapter import ParamValue
from gateway.cli.tools import (
    EXIT_FAILED,
    EXIT_NO_GATEWAY,
    EXIT_OK,
    NoGateway,
    _print_json,
    add_common,
    fail,
    query_in,
    require_gateway,
    session,
)
from gateway.errors import ParameterError

BACKUP_QUERY_TIMEOUT = 15.0  # s for one parameter (the gateway answers within 8 s)


def add_params(sub: Any) -> None:
    p = sub.add_parser(
        "params",
        help="back up, compare and restore a drive's parameters",
        description="Back up a drive's parameters to a JSON file, compare a drive or a file "
        'with a file, restore a file to a stopped drive (docs/operations.md, "Parameter '
        'backup and restore").',
    )
    ops = p.add_subparsers(dest="params_op", required=True, metavar="OP")

    b = ops.add_parser(
        "backup",
        help="read every parameter of the drive's table (or those given) into a file",
        description="Read every parameter the drive's table knows, or those given with "
        "--params, into a JSON file with the drive's identity, firmware where readable and "
        "a timestamp. A parameter that cannot be read is kept with the device's error.",
        epilog="exit status: 0 written (even with unreadable parameters); 1 nothing could be "
        "read; 3 no gateway answers.",
    )
    add_common(b)
    b.add_argument("drive", help="the drive's id")
    b.add_argument(
        "-o",
        "--output",
        metavar="FILE",
        help="the backup file; - for stdout (default: DRIVE-<UTC time>.json here)",
    )
    b.add_argument(
        "--params",
        type=_numbers,
        metavar="LIST",
        help="parameters to read, e.g. 100-103,134,P0313,964.2 (default: the drive's table)",
    )
    b.set_defaults(handler=cmd_backup)

    d = ops.add_parser(
        "diff",
        help="compare a file with a drive, or two files, as a table",
        description="Compare the parameters of a backup file with a drive (read now) or with "
        "another file; raw values are compared.",
        epilog="exit status: 0 no difference; 1 differences (or unreadable parameters); "
        "3 no gateway answers.",
    )
    add_common(d)
    d.add_argument("file", help="a backup file")
    d.add_argument("other", metavar="DRIVE|FILE", help="a drive id, or a second backup file")
    d.add_argument(
        "--all", action="store_true", help="list equal parameters too (default: differences)"
    )
    d.set_defaults(handler=cmd_diff)

    r = ops.add_parser(
        "restore",
        help="write what differs from a file to a stopped drive, and read it back",
        description="Write the parameters of a backup file that differ from the drive, only "
        "those in the drive's writable_params, in number order, each read back; refused "
        "while the drive runs or is not online, or for a file of another device model.",
        epilog="exit status: 0 every write read back as written; 1 refused, a write failed "
        "or the drive started; 3 no gateway answers.",
    )
    add_common(r)
    r.add_argument("file", help="a backup file")
    r.add_argument("drive", help="the drive's id")
    r.add_argument(
        "--dry-run", action="store_true", help="show what would be written, write nothing"
    )
    r.set_defaults(handler=cmd_restore)


def _numbers(text: str) -> tuple[tuple[int, int], ...]:
    try:
        return pb.parse_numbers(text)
    except pb.BackupError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# ------------------------------------------------------------------ progress


class ProgressOut:
    """A bar on a terminal, one line per parameter otherwise."""

    WIDTH = 30

    def __init__(self, what: str, out: TextIO = sys.stderr) -> None:
        self.what = what
        self.out = out
        self.tty = out.isatty() and os.environ.get("TERM") != "dumb"

    def __call__(self, done: int, total: int, entry: pb.ParamEntry) -> None:
        if self.tty:
            filled = self.WIDTH * done // max(total, 1)
            bar = "#" * filled + "." * (self.WIDTH - filled)
            label = f"{entry.label} {entry.name}"[:40]
            self.out.write(f"\r{self.what} [{bar}] {done}/{total} {label:<40}")
            if done == total:
                self.out.write("\n")
        else:
            name = f" {entry.name}" if entry.name else ""
            self.out.write(f"{self.what} {done}/{total} {entry.label}{name} = {entry.shown()}\n")
        self.out.flush()


# ------------------------------------------------------------------ the gateway side


class Remote:
    """One drive through the gateway, on an open session."""

    def __init__(self, s: zenoh.Session, prefix: str, drive: str) -> None:
        self.s = s
        self.base = f"{prefix}/drives/{drive}"
        self.drive = drive

    def describe(self) -> dict[str, Any]:
        answer = query_in(self.s, f"{self.base}/params?describe", timeout=BACKUP_QUERY_TIMEOUT)
        if not isinstance(answer, dict) or "error" in answer:
            raise pb.BackupError(_error_text(answer))
        return answer

    def state(self) -> dict[str, Any]:
        answer = query_in(self.s, f"{self.base}/state")
        if not isinstance(answer, dict) or "id" not in answer:
            raise pb.BackupError(f"no state of drive {self.drive}: {_error_text(answer)}")
        return answer

    def _key(self, number: int, subindex: int) -> str:
        key = f"{self.base}/params/{number}"
        return f"{key}/{subindex}" if subindex else key

    async def read(self, number: int, subindex: int) -> ParamValue:
        return self._answer(
            query_in(self.s, self._key(number, subindex), None, BACKUP_QUERY_TIMEOUT)
        )

    def write(self, number: int, subindex: int, value: ParamValue) -> None:
        self._answer(query_in(self.s, self._key(number, subindex), {"value": value}))

    @staticmethod
    def _answer(answer: Any) -> ParamValue:
        if not isinstance(answer, dict) or "error" in answer:
            code = answer.get("code") if isinstance(answer, dict) else None
            raise ParameterError(_error_text(answer), code if isinstance(code, int) else None)
        value = answer.get("value")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterError(f"not a value: {answer!r}")
        return value


def _error_text(answer: Any) -> str:
    if isinstance(answer, dict) and isinstance(answer.get("error"), str):
        return str(answer["error"])
    return json.dumps(answer)


def _run(args: argparse.Namespace, body: Any) -> int:
    """Open the session, check the gateway, run ``body(session)``; the errors as exit codes."""
    try:
        with session(args.connect) as s:
            require_gateway(s, args)
            result: int = body(s)
            return result
    except NoGateway as exc:
        return fail(str(exc), EXIT_NO_GATEWAY)
    except pb.BackupError as exc:
        return fail(str(exc))
    except RuntimeError as exc:  # a query nobody answered
        return fail(str(exc))


def _require_online(state: dict[str, Any]) -> None:
    if state.get("comm") != "online":
        raise pb.BackupError(f"drive {state.get('id')} is not online (comm {state.get('comm')})")


def _load(path: str) -> pb.Backup:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise pb.BackupError(f"{path}: {exc.strerror or exc}") from None
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise pb.BackupError(f"{path}: not JSON ({exc})") from None
    try:
        return pb.Backup.from_json(doc)
    except pb.BackupError as exc:
        raise pb.BackupError(f"{path}: {exc}") from None


# ------------------------------------------------------------------ backup


def cmd_backup(args: argparse.Namespace) -> int:
    def body(s: zenoh.Session) -> int:
        remote = Remote(s, args.prefix, args.drive)
        described = remote.describe()
        _require_online(described.get("state") or remote.state())
        drive = pb.Identity.from_json(described["drive"])
        table = pb.table_from_json(described.get("table", []))
        progress = ProgressOut(f"backup {args.drive}")
        backup = asyncio.run(
            pb.take(
                drive,
                table,
                args.params,
                remote.read,
                gateway=str(described.get("gateway", "")),
                progress=progress,
                entries=pb.entries_from_json(described.get("writable_entries")),
            )
        )
        return _write_backup(args, backup)

    return _run(args, body)


def default_name(drive: str) -> str:
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%SZ")
    return f"{drive}-{stamp}.json"


def _write_backup(args: argparse.Namespace, backup: pb.Backup) -> int:
    text = json.dumps(backup.to_json(), indent=2) + "\n"
    target = args.output or default_name(args.drive)
    if target == "-":
        sys.stdout.write(text)
    else:
        try:
            Path(target).write_text(text, encoding="utf-8")
        except OSError as exc:
            return fail(f"{target}: {exc.strerror or exc}")
    errors = [p for p in backup.params if p.error is not None]
    summary = {
        "file": target,
        "drive": backup.drive.id,
        "device": backup.drive.device,
        "firmware": backup.drive.firmware,
        "parameters": len(backup.params),
        "errors": len(errors),
    }
    if args.json and target != "-":
        _print_json(summary)
    else:
        firmware = backup.drive.firmware or "not readable"
        print(
            f"backup of {backup.drive.id} ({backup.drive.device}, firmware {firmware}): "
            f"{len(backup.params)} parameter(s), {len(errors)} not readable -> {target}",
            file=sys.stderr if target == "-" else sys.stdout,
        )
    return EXIT_FAILED if backup.params and len(errors) == len(backup.params) else EXIT_OK


# ------------------------------------------------------------------ diff


def cmd_diff(args: argparse.Namespace) -> int:
    try:
        left = _load(args.file)
    except pb.BackupError as exc:
        return fail(str(exc))
    if Path(args.other).is_file():
        try:
            right = _load(args.other)
        except pb.BackupError as exc:
            return fail(str(exc))
        return _report_diff(args, pb.compare(left.params, right.params), args.other)

    def body(s: zenoh.Session) -> int:
        remote = Remote(s, args.prefix, args.other)
        described = remote.describe()
        _require_online(described.get("state") or remote.state())
        table = pb.reading_table(pb.table_from_json(described.get("table", [])), left)
        progress = ProgressOut(f"read {args.other}")
        entries = asyncio.run(
            pb.read_all([p.key for p in left.params], table, remote.read, progress)
        )
        return _report_diff(args, pb.compare(left.params, entries), f"drive {args.other}")

    return _run(args, body)


def _report_diff(args: argparse.Namespace, rows: list[pb.DiffRow], right: str) -> int:
    differing = [r for r in rows if r.status != "same"]
    if args.json:
        _print_json(
            {
                "left": args.file,
                "right": right,
                "rows": [r.to_json() for r in (rows if args.all else differing)],
                "differences": len(differing),
                "parameters": len(rows),
            }
        )
    else:
        shown = rows if args.all else differing
        table = [("parameter", "name", args.file, right, "")]
        table += [(r.label, r.name, r.left, r.right, r.status) for r in shown]
        print(_table(table))
        print(f"{len(differing)} of {len(rows)} parameter(s) differ")
    return EXIT_FAILED if differing else EXIT_OK


def _table(rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


# ------------------------------------------------------------------ restore


def cmd_restore(args: argparse.Namespace) -> int:
    try:
        backup = _load(args.file)
    except pb.BackupError as exc:
        return fail(str(exc))

    def body(s: zenoh.Session) -> int:
        remote = Remote(s, args.prefix, args.drive)
        described = remote.describe()
        state = described.get("state") or remote.state()
        pb.check_target(backup, state)
        why = pb.not_stopped(state)
        if why is not None:
            return fail(f"restore refused: {why}")
        table = pb.reading_table(pb.table_from_json(described.get("table", [])), backup)
        progress = ProgressOut(f"read {args.drive}")
        entries = asyncio.run(
            pb.read_all([p.key for p in backup.params], table, remote.read, progress)
        )
        current = {e.key: e for e in entries}
        steps = pb.plan(
            backup,
            current,
            described.get("writable", []),
            args.drive,
            pb.entries_from_json(described.get("writable_entries")),
        )
        if args.dry_run:
            return _report_restore(args, [_planned(step) for step in steps], dry_run=True)
        return _report_restore(args, _execute(remote, steps))

    return _run(args, body)


def _planned(step: pb.Step) -> dict[str, Any]:
    action = {"write": "would write", "same": "same", "skip": "skipped"}[step.action]
    return _result(step, action, step.reason)


def _result(step: pb.Step, result: str, reason: str = "") -> dict[str, Any]:
    return {
        "parameter": step.entry.label,
        "name": step.entry.name,
        "file": step.entry.shown(),
        "drive": "-" if step.current is None else step.current.shown(),
        "result": result,
        "reason": reason,
    }


def _execute(remote: Remote, steps: list[pb.Step]) -> list[dict[str, Any]]:
    results: list[dict[str, Any]] = []
    stopped_by: str | None = None
    for step in steps:
        if step.action != "write":
            results.append(_planned(step))
            continue
        if stopped_by is None:
            stopped_by = pb.not_stopped(remote.state())
        if stopped_by is not None:
            results.append(_result(step, "not written", stopped_by))
            continue
        results.append(_write_one(remote, step))
    return results


def _write_one(remote: Remote, step: pb.Step) -> dict[str, Any]:
    entry = step.entry
    if entry.raw is None:  # a plan writes only values read into the file
        return _result(step, "not written", "the file holds no value for it")
    try:
        remote.write(entry.number, entry.subindex, entry.raw)
    except ParameterError as exc:
        return _result(step, "refused", exc.text)
    try:
        back = asyncio.run(remote.read(entry.number, entry.subindex))
    except ParameterError as exc:
        return _result(step, "written, not read back", exc.text)
    if back != entry.raw:
        return _result(step, "read back differs", f"read back {back}, wrote {entry.raw}")
    return _result(step, "written")


GOOD = frozenset({"written", "same", "skipped", "would write"})


def _report_restore(
    args: argparse.Namespace, results: list[dict[str, Any]], *, dry_run: bool = False
) -> int:
    failed = [r for r in results if r["result"] not in GOOD]
    counts: dict[str, int] = {}
    for r in results:
        counts[r["result"]] = counts.get(r["result"], 0) + 1
    if args.json:
        _print_json(
            {
                "file": args.file,
                "drive": args.drive,
                "dry_run": dry_run,
                "results": results,
                "counts": counts,
            }
        )
    else:
        rows = [("parameter", "name", "file", "drive", "result")]
        rows += [
            (
                r["parameter"],
                r["name"],
                r["file"],
                r["drive"],
                f"{r['result']}: {r['reason']}" if r["reason"] else r["result"],
            )
            for r in results
            if r["result"] != "same"
        ]
        print(_table(rows))
        summary = ", ".join(f"{n} {what}" for what, n in sorted(counts.items()))
        print(f"{'dry run: ' if dry_run else ''}{args.drive}: {summary or 'nothing to do'}")
    return EXIT_FAILED if failed else EXIT_OK
