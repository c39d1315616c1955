"""The audit trail: one record per access decision that refuses, per accepted command,
parameter write, backup and restore, config load and reload, user change and login.

A record has the fields IEC 62443-3-3/4-2 CR 2.8 lists: when (UTC), where (interface and
peer), who (identity and role), the category, the type and its event id, and the result;
a short detail says what. Records go to three places:

- a file of bounded size, JSON lines, rotated by ``logging.handlers.RotatingFileHandler``
  (``[audit] file``, ``max_kib``, ``backups``): never more than (backups + 1) x max_kib;
- the systemd journal, each field a journal field (``AUDIT_*``, ``MESSAGE``), over
  journald's datagram socket (:mod:`gateway.access.journal`); skipped where the socket is
  absent, never waited for (a full socket drops the datagram and counts it);
- the newest :data:`KEEP` in memory, for engineers on the page (``/api/audit``) and on
  Zenoh (``<prefix>/gateway/audit``).

The trail never raises into its caller: a sink that fails is counted, logged once, and
the decision it records stands.

A refusal a client can repeat at its own pace (by role, CSRF, wrong token, logins refused
unchecked, requests refused at the door, Zenoh links opened and closed) is written once per
:data:`FOLD_PERIOD` for each interface, type, peer and identity; the ones in between are
counted, and the next record of that key (or a summary when the period is over,
:meth:`AuditTrail.flush`) says how many. A flood of refusals so fills neither the file's
bound nor the journal's rate limit, and every refusal is still counted. So is a command
that only moves a drive's speed setpoint, per drive and client. Logins, other commands,
parameter writes and the rest are each written.
"""

from __future__ import annotations

import collections
import datetime
import enum
import itertools
import json
import logging
import logging.handlers
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from gateway.access import journal
from gateway.access.roles import Identity
from gateway.model import DriveCommand
from gateway.ratelimit import LogRateLimit
from gateway.schema import Table

log = logging.getLogger(__name__)

KEEP = 1000  # records kept in memory for the readers
FOLD_PERIOD = 10.0  # s: records of one key beyond the first are counted (module docstring)
FOLD_KEYS = 4096  # (interface, type, peer, identity, result[, what]) being counted
SETPOINT_FIELDS = frozenset({"speed_rpm", "speed_pct"})
FOLDED = frozenset(
    {"refused", "csrf", "token", "login_limited", "request_refused", "link_open", "link_close"}
)  # Kind.type of the records folded: what a client can repeat at its own pace
DETAIL_MAX = 300  # characters of a record's detail
FIELD_MAX = 120  # characters of a peer or identity


class Category(enum.Enum):
    ACCESS = "access"  # authentication and authorisation decisions
    CONTROL = "control"  # drive commands
    PARAMETER = "parameter"  # parameter writes, backups, restores
    CONFIG = "config"  # configuration loaded, reload asked
    USERS = "users"  # user changes


class Result(enum.Enum):
    SUCCESS = "success"
    FAILURE = "failure"


class Kind(enum.Enum):
    """A record's type: its category and its event id (ids are stable, documented)."""

    LOGIN = ("login", Category.ACCESS, 1001)
    LOGOUT = ("logout", Category.ACCESS, 1002)
    LOGIN_LIMITED = ("login_limited", Category.ACCESS, 1003)
    TOKEN = ("token", Category.ACCESS, 1004)
    LINK_OPEN = ("link_open", Category.ACCESS, 1005)  # a Zenoh link, its certificate's name
    LINK_CLOSE = ("link_close", Category.ACCESS, 1006)
    REFUSED = ("refused", Category.ACCESS, 1010)  # the role does not allow it
    CSRF = ("csrf", Category.ACCESS, 1011)
    REQUEST_REFUSED = ("request_refused", Category.ACCESS, 1012)  # at the door: allow, Host
    COMMAND = ("command", Category.CONTROL, 2001)
    PARAM_WRITE = ("param_write", Category.PARAMETER, 3001)
    BACKUP = ("backup", Category.PARAMETER, 3002)
    RESTORE = ("restore", Category.PARAMETER, 3003)
    CONFIG_LOAD = ("config_load", Category.CONFIG, 4001)
    CONFIG_RELOAD = ("config_reload", Category.CONFIG, 4002)
    USER_CHANGE = ("user_change", Category.USERS, 5001)

    @property
    def type(self) -> str:
        return str(self.value[0])

    @property
    def category(self) -> Category:
        category: Category = self.value[1]
        return category

    @property
    def event_id(self) -> int:
        event_id: int = self.value[2]
        return event_id


def command_text(cmd: DriveCommand) -> str:
    """A command as a record's detail shows it: its JSON, the fields it sets only."""
    return json.dumps(cmd.to_json(), separators=(",", ":"))


def _cut(text: str, size: int) -> str:
    text = text.replace("\n", " ").replace("\r", " ")
    return text if len(text) <= size else text[: size - 3] + "..."


@dataclass(frozen=True, slots=True)
class Record:
    seq: int
    timestamp: str  # ISO 8601, UTC, milliseconds
    interface: str  # web, modbus, zenoh, config, cli
    peer: str  # a client's address, a certificate's name, "-" for the gateway itself
    identity: str  # a user's name, "anonymous", an address
    role: str  # the role the identity was given ("-": none)
    kind: Kind
    result: Result
    detail: str

    def to_json(self) -> dict[str, Any]:
        return {
            "seq": self.seq,
            "timestamp": self.timestamp,
            "interface": self.interface,
            "peer": self.peer,
            "identity": self.identity,
            "role": self.role,
            "category": self.kind.category.value,
            "type": self.kind.type,
            "event_id": self.kind.event_id,
            "result": self.result.value,
            "detail": self.detail,
        }

    def journal_fields(self) -> dict[str, str]:
        fields = {f"AUDIT_{k.upper()}": str(v) for k, v in self.to_json().items()}
        message = (
            f"audit {self.kind.type} {self.result.value}: {self.interface} {self.peer} "
            f"{self.identity}: {self.detail}"
        )
        return {
            "MESSAGE": message,
            "PRIORITY": "5" if self.result is Result.SUCCESS else "4",
            "SYSLOG_IDENTIFIER": "drive-gateway",
            "MESSAGE_ID": "8e0b5a6c3f1d4e2a9b7c6d5e4f3a2b1c",
            **fields,
        }


@dataclass(frozen=True, slots=True)
class AuditSection:
    """The ``[audit]`` table."""

    file: Path | None = None  # absent: no file (the journal and memory only)
    max_kib: int = 10240
    backups: int = 5
    journal: bool = True


def read_audit_section(t: Table, base: Path) -> AuditSection:
    d = AuditSection()
    text: str | None = t.string("file", None)
    if text is not None and ("\x00" in text or not text.strip()):
        t.errors.append(t.error("file", f"{text!r} is not a file path"))
        text = None
    path = None if text is None else (base / text if not Path(text).is_absolute() else Path(text))
    return AuditSection(
        file=path,
        max_kib=t.integer("max_kib", d.max_kib, minimum=16, maximum=1 << 20),
        backups=t.integer("backups", d.backups, minimum=1, maximum=100),
        journal=t.boolean("journal", d.journal),
    )


def _utc(now: float) -> str:
    moment = datetime.datetime.fromtimestamp(now, datetime.UTC)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


class JournalSocket:
    """journald's socket, connected once; a datagram it cannot take now is dropped."""

    def __init__(self, path: str = journal.SOCKET_PATH) -> None:
        self.path = path
        self.dropped = 0
        self._sock: socket.socket | None = None
        if not os.path.exists(path):
            return
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            sock.connect(path)
        except OSError:
            sock.close()
            return
        sock.setblocking(False)
        self._sock = sock

    @property
    def open(self) -> bool:
        return self._sock is not None

    def send(self, datagram: bytes) -> None:
        if self._sock is None:
            return
        try:
            self._sock.send(datagram)
        except OSError:
            self.dropped += 1

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


class AuditTrail:
    """Where every front end records its decisions (:meth:`record`)."""

    def __init__(
        self,
        section: AuditSection | None = None,
        clock: Callable[[], float] | None = None,
        journal_path: str = journal.SOCKET_PATH,
        monotonic: Callable[[], float] | None = None,
    ) -> None:
        self.section = section or AuditSection(journal=False)
        self.clock = clock or time.time
        self.records: collections.deque[Record] = collections.deque(maxlen=KEEP)
        self.counts: dict[str, int] = collections.Counter()
        self.failures = 0
        self._seq = itertools.count(1)
        self._listeners: list[Callable[[Record], None]] = []
        self._file: logging.Logger | None = None
        self._handler: logging.Handler | None = None
        self._journal: JournalSocket | None = None
        self._monotonic = monotonic or time.monotonic
        self._folds = LogRateLimit(FOLD_PERIOD, FOLD_KEYS)
        self._flushed = self._monotonic()
        if self.section.file is not None:
            self._open_file(self.section.file)
        if self.section.journal:
            self._journal = JournalSocket(journal_path)

    def _open_file(self, path: Path) -> None:
        handler = logging.handlers.RotatingFileHandler(
            path,
            maxBytes=self.section.max_kib * 1024,
            backupCount=self.section.backups,
            encoding="utf-8",
            delay=False,
        )
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger = logging.getLogger(f"{__name__}.file.{id(self)}")
        logger.propagate = False
        logger.setLevel(logging.INFO)
        logger.addHandler(handler)
        self._file, self._handler = logger, handler

    @property
    def journal_open(self) -> bool:
        return self._journal is not None and self._journal.open

    def listen(self, listener: Callable[[Record], None]) -> None:
        """Call ``listener`` with each new record (on the caller's thread)."""
        self._listeners.append(listener)

    def record(
        self,
        kind: Kind,
        result: Result,
        *,
        interface: str,
        peer: str = "-",
        identity: Identity | str | None = None,
        detail: str = "",
        fold: str | None = None,
    ) -> Record | None:
        """The record of one decision (None: folded into the next, module docstring);
        ``fold``: fold this one too, under this key (a drive's speed setpoints)."""
        self.counts[f"{kind.type}:{result.value}"] += 1
        if kind.type in FOLDED or fold is not None:
            who = identity.name if isinstance(identity, Identity) else identity or ""
            key: tuple[str, ...] = (interface, kind.type, peer, who, result.value)
            key += (fold,) if fold is not None else ()
            held = self._folds.admit(key, self._monotonic())
            if held is None:
                return None
            if held:
                detail = f"{detail} ({held} more since the last record)"
        return self._new(
            kind, result, interface=interface, peer=peer, identity=identity, detail=detail
        )

    def _new(
        self,
        kind: Kind,
        result: Result,
        *,
        interface: str,
        peer: str,
        identity: Identity | str | None,
        detail: str,
    ) -> Record:
        if isinstance(identity, Identity):
            who, role = identity.name, identity.role.label
        else:
            who, role = identity or "anonymous", "-"
        rec = Record(
            seq=next(self._seq),
            timestamp=_utc(self.clock()),
            interface=interface,
            peer=_cut(peer or "-", FIELD_MAX),
            identity=_cut(who, FIELD_MAX),
            role=role,
            kind=kind,
            result=result,
            detail=_cut(detail, DETAIL_MAX),
        )
        self.records.append(rec)
        self._write(rec)
        return rec

    def command(
        self,
        cmd: DriveCommand,
        result: Result,
        *,
        interface: str,
        peer: str,
        identity: Identity | str,
        drive: str,
        why: str = "",
    ) -> None:
        """A drive command, accepted or refused. One that only moves the speed setpoint
        (a SCADA ramping it sends one per cycle) is folded per drive and client like a
        refusal; a run, stop, reset, direction or any other change is always written."""
        setpoint_only = set(cmd.to_json()) <= SETPOINT_FIELDS
        self.record(
            Kind.COMMAND,
            result,
            interface=interface,
            peer=peer,
            identity=identity,
            detail=f"drive {drive}: {command_text(cmd)}" + (f": {why}" if why else ""),
            fold=f"setpoint {drive}" if setpoint_only else None,
        )

    def refused_request(self, interface: str, reason: str, peer: str, detail: str) -> None:
        """A request or connection refused before anyone is identified (an address
        outside the allow-list, a Host not in web.names, a limit): folded like any refusal."""
        self.record(
            Kind.REQUEST_REFUSED,
            Result.FAILURE,
            interface=interface,
            peer=peer,
            detail=f"{reason}: {detail}",
        )

    def flush(self) -> None:
        """A summary record for each folded key whose period is over with refusals held
        back (at most once a second; the daemon calls it on every tick)."""
        now = self._monotonic()
        if now - self._flushed < 1.0:
            return
        self._flushed = now
        for key, held in self._folds.flush(now):
            interface, kind_type, peer, who, result, *fold = cast(tuple[str, ...], key)
            kind = next(k for k in Kind if k.type == kind_type)
            what = f"{fold[0]}: {held} more" if fold else f"{held} more refused"
            detail = f"{what} since the last record"
            self._new(
                kind, Result(result), interface=interface, peer=peer, identity=who, detail=detail
            )

    def _write(self, rec: Record) -> None:
        try:
            if self._file is not None:
                self._file.info(json.dumps(rec.to_json(), ensure_ascii=False))
            if self._journal is not None:
                self._journal.send(journal.encode(rec.journal_fields()))
            for listener in self._listeners:
                listener(rec)
        except Exception:
            self.failures += 1
            if self.failures == 1:
                log.exception("audit: a record could not be written (logged once)")

    def newest(self, limit: int = KEEP, since: int = 0) -> list[dict[str, Any]]:
        """The newest records (at most ``limit``, after sequence ``since``), oldest first."""
        out = [r.to_json() for r in self.records if r.seq > since]
        return out[-limit:] if limit > 0 else []

    def close(self) -> None:
        if self._handler is not None and self._file is not None:
            self._file.removeHandler(self._handler)
            self._handler.close()
            self._handler = None
        if self._journal is not None:
            self._journal.close()
