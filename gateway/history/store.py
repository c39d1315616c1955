"""The history database: its schema, the writer's connection and the readers' queries.

One SQLite file (the standard library's sqlite3), in WAL mode with ``synchronous=NORMAL``:
a transaction is one batch of the writer (gateway/history/writer.py); a power cut loses at
most the batch being written, never the file. Two tables:

- ``readings``: one row per drive and sample: ``drive`` (the drive's number in
  ``drives``), ``t`` (seconds since the epoch) and one column per reading of the drive
  model (:data:`READINGS`), NULL where the drive gives none. ``(drive, t)`` is the primary
  key of a table without row ids: a drive's day is one range of the B-tree.
- ``events``: one row per event the hub delivered: ``t``, ``drive``, ``kind``, ``text``
  and the event's other fields as JSON (``data``).

Readers (:class:`HistoryStore`) open a connection of their own for each query, so any
thread may query while the writer writes (WAL: readers never wait for it).
Downsampling (``step``): the samples of each bucket of ``step`` seconds of the epoch
(``floor(t / step) * step``) that fall in the range are one row, at the bucket's start,
with each reading's average over them (NULLs left out: a bucket where a reading was never
given has None; a bucket without samples has no row). A third table, ``minutes``, keeps per
drive and minute each reading's sum and count, so a step of whole minutes reads one row a
minute (docs/decisions/0083-history-store.md).
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway.errors import HistoryError

READINGS: tuple[str, ...] = (
    "speed_rpm",
    "speed_pct",
    "speed_ref_rpm",
    "speed_ref_pct",
    "current_a",
    "current_pct_flc",
    "motor_temp_pct",
    "power_kw",
    "voltage_v",
)
"""The drive model's readings kept in the history (the numeric fields of DriveState)."""

SCHEMA_VERSION = 1
MAX_ROWS = 100_000
"""Rows one query may answer; beyond it the query is refused with the step that fits."""
WAL_LIMIT = 8 << 20  # bytes the WAL file is cut back to after a checkpoint
BUSY_TIMEOUT = 5.0  # s a connection waits for a lock (a checkpoint) before it fails

_COLUMNS = ", ".join(f"{name} REAL" for name in READINGS)
_SCHEMA: tuple[str, ...] = (
    "CREATE TABLE IF NOT EXISTS drives (id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE)",
    f"CREATE TABLE IF NOT EXISTS readings (drive INTEGER NOT NULL, t REAL NOT NULL, {_COLUMNS},"
    " PRIMARY KEY (drive, t)) WITHOUT ROWID",
    "CREATE TABLE IF NOT EXISTS events (id INTEGER PRIMARY KEY, t REAL NOT NULL,"
    " drive TEXT NOT NULL, kind TEXT NOT NULL, text TEXT NOT NULL, data TEXT NOT NULL)",
    "CREATE INDEX IF NOT EXISTS events_t ON events (t)",
)
_ROLLUP_COLUMNS = ", ".join(f"s_{n} REAL NOT NULL, n_{n} INTEGER NOT NULL" for n in READINGS)
_SCHEMA += (
    f"CREATE TABLE IF NOT EXISTS minutes (drive INTEGER NOT NULL, m INTEGER NOT NULL,"
    f" {_ROLLUP_COLUMNS}, PRIMARY KEY (drive, m)) WITHOUT ROWID",
)
_ROLLUP_NAMES = ", ".join(f"s_{n}, n_{n}" for n in READINGS)
_UPSERT_MINUTE = (
    f"INSERT INTO minutes (drive, m, {_ROLLUP_NAMES}) VALUES (?, ?, "
    + ", ".join("?" for _ in range(2 * len(READINGS)))
    + ") ON CONFLICT (drive, m) DO UPDATE SET "
    + ", ".join(f"s_{n} = s_{n} + excluded.s_{n}, n_{n} = n_{n} + excluded.n_{n}" for n in READINGS)
)
MINUTE = 60
"""s of one row of the ``minutes`` table: per drive, each reading's sum and count over a
minute of the epoch, kept with the samples, so a downsampled query whose step is a whole
number of minutes reads a row a minute instead of every sample."""
_INSERT_READING = (
    f"INSERT OR REPLACE INTO readings (drive, t, {', '.join(READINGS)}) "
    f"VALUES (?, ?, {', '.join('?' for _ in READINGS)})"
)
_INSERT_EVENT = "INSERT INTO events (t, drive, kind, text, data) VALUES (?, ?, ?, ?, ?)"

Values = tuple[float | None, ...]
"""One sample's readings, in the order of :data:`READINGS`."""


@dataclass(frozen=True)
class HistoryRow:
    """One sample of one drive (or, downsampled, one bucket's average)."""

    t: float
    """Seconds since the epoch (a bucket's start when downsampled)."""
    values: Mapping[str, float | None]
    """Reading name (:data:`READINGS`) -> value, None where there was none."""


@dataclass(frozen=True)
class HistoryEvent:
    """One event as the history keeps it."""

    t: float
    drive_id: str
    kind: str
    text: str
    data: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The event's JSON, as the hub's events key publishes it."""
        return {
            "drive": self.drive_id,
            "kind": self.kind,
            "text": self.text,
            "ts": self.t,
            **dict(self.data),
        }


@dataclass(frozen=True, slots=True)
class Sample:
    """One drive's readings at ``t``, as the recorder hands them to the writer."""

    drive_id: str
    t: float
    values: Values


@dataclass
class WriterCounters:
    """What the writer thread (gateway/history/writer.py) has counted since it started."""

    batches: int = 0
    samples: int = 0
    events: int = 0
    samples_dropped: int = 0  # refused by the full queue
    events_dropped: int = 0
    samples_failed: int = 0  # in batches that could not be written
    events_failed: int = 0
    moved_aside: int = 0
    pruned: int = 0  # rows deleted by retention


# ---------------------------------------------------------------- the writer's connection


def _connect(path: Path) -> sqlite3.Connection:
    conn = sqlite3.connect(
        path, timeout=BUSY_TIMEOUT, isolation_level=None, check_same_thread=False
    )
    return conn


class HistoryDb:
    """The writer's connection: schema, batches, retention. Used by one thread at a time."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.conn = _connect(path)
        self._drive_ids: dict[str, int] = {}
        self._prepare()

    @classmethod
    def open_checked(cls, path: Path) -> HistoryDb:
        """Open (or create) the database and check it (``PRAGMA quick_check``); raises
        sqlite3.DatabaseError when the file is not a sound history database."""
        path.parent.mkdir(parents=True, exist_ok=True)
        db = cls(path)
        try:
            row = db.conn.execute("PRAGMA quick_check").fetchone()
            if row is None or row[0] != "ok":
                raise sqlite3.DatabaseError(f"quick_check: {row[0] if row else 'no answer'}")
        except BaseException:
            db.close()
            raise
        return db

    def _prepare(self) -> None:
        conn = self.conn
        conn.execute("PRAGMA auto_vacuum = INCREMENTAL")  # takes effect on a new file only
        mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()
        if mode is None or str(mode[0]).lower() != "wal":
            raise sqlite3.DatabaseError(f"journal mode {mode!r}, not WAL")
        conn.execute("PRAGMA synchronous = NORMAL")
        conn.execute(f"PRAGMA journal_size_limit = {WAL_LIMIT}")  # the WAL shrinks back to it
        version = conn.execute("PRAGMA user_version").fetchone()[0]
        if version not in (0, SCHEMA_VERSION):
            raise sqlite3.DatabaseError(
                f"schema version {version}, this gateway knows {SCHEMA_VERSION}"
            )
        with _transaction(conn):
            for statement in _SCHEMA:
                conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        self._drive_ids = {name: i for i, name in conn.execute("SELECT id, name FROM drives")}

    def close(self) -> None:
        self.conn.close()

    def _drive_number(self, drive_id: str) -> int:
        number = self._drive_ids.get(drive_id)
        if number is None:
            cur = self.conn.execute("INSERT INTO drives (name) VALUES (?)", (drive_id,))
            number = self._drive_ids[drive_id] = int(cur.lastrowid or 0)
        return number

    def write(self, samples: Sequence[Sample], events: Sequence[HistoryEvent]) -> None:
        """One batch, in one transaction (all of it or, after a power cut, none)."""
        if not samples and not events:
            return
        conn = self.conn
        known = dict(self._drive_ids)
        try:
            with _transaction(conn):
                conn.executemany(
                    _INSERT_READING,
                    [(self._drive_number(s.drive_id), s.t, *s.values) for s in samples],
                )
                conn.executemany(_UPSERT_MINUTE, _minute_sums(self._drive_ids, samples))
                conn.executemany(
                    _INSERT_EVENT,
                    [
                        (e.t, e.drive_id, e.kind, e.text, json.dumps(dict(e.data), default=str))
                        for e in events
                    ],
                )
        except BaseException:
            self._drive_ids = known  # the drives added in the batch were rolled back with it
            raise

    def used_bytes(self) -> int:
        """The bytes of the file in use (its pages less the free ones)."""
        conn = self.conn
        pages = conn.execute("PRAGMA page_count").fetchone()[0]
        free = conn.execute("PRAGMA freelist_count").fetchone()[0]
        size = conn.execute("PRAGMA page_size").fetchone()[0]
        return int((pages - free) * size)

    def prune(self, now: float, max_age: float, max_bytes: int) -> int:
        """Rows older than ``max_age`` deleted; then, while the database uses more than
        ``max_bytes``, the oldest tenth of what is left; the freed pages given back to the
        file system. Returns the rows deleted."""
        conn = self.conn
        deleted = self._delete_before(now - max_age)
        for _ in range(20):  # each pass deletes a tenth of the span: bounded work
            oldest = self._oldest()
            if oldest is None or self.used_bytes() <= max_bytes:
                break
            removed = self._delete_before(oldest + max((now - oldest) / 10, 1.0))
            deleted += removed
            if not removed:
                break
        conn.execute("PRAGMA incremental_vacuum")
        return deleted

    def _oldest(self) -> float | None:
        """The time of the oldest row (each drive's first sample, the first event)."""
        conn = self.conn
        firsts = [
            conn.execute("SELECT MIN(t) FROM readings WHERE drive = ?", (drive,)).fetchone()[0]
            for (drive,) in conn.execute("SELECT id FROM drives").fetchall()
        ]
        firsts.append(conn.execute("SELECT MIN(t) FROM events").fetchone()[0])
        known = [t for t in firsts if t is not None]
        return min(known) if known else None

    def _delete_before(self, t: float) -> int:
        conn = self.conn
        deleted = 0
        with _transaction(conn):
            for (drive,) in conn.execute("SELECT id FROM drives").fetchall():  # the key's order
                cur = conn.execute("DELETE FROM readings WHERE drive = ? AND t < ?", (drive, t))
                deleted += max(cur.rowcount, 0)
                conn.execute(
                    "DELETE FROM minutes WHERE drive = ? AND m < ?", (drive, math.floor(t / MINUTE))
                )
            deleted += max(conn.execute("DELETE FROM events WHERE t < ?", (t,)).rowcount, 0)
        return deleted

    def checkpoint(self) -> None:
        self.conn.execute("PRAGMA wal_checkpoint(PASSIVE)")


def _minute_sums(drive_ids: Mapping[str, int], samples: Sequence[Sample]) -> list[tuple[Any, ...]]:
    """Each (drive, minute) of the samples: per reading, its sum and its count."""
    width = len(READINGS)
    sums: dict[tuple[int, int], list[float]] = {}
    for s in samples:
        key = (drive_ids[s.drive_id], math.floor(s.t / MINUTE))
        acc = sums.get(key)
        if acc is None:
            acc = sums[key] = [0.0] * (2 * width)
        for i, v in enumerate(s.values):
            if v is not None:
                acc[2 * i] += v
                acc[2 * i + 1] += 1
    return [(drive, m, *acc) for (drive, m), acc in sums.items()]


class _transaction:
    """BEGIN IMMEDIATE ... COMMIT, ROLLBACK on an error (autocommit connections)."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def __enter__(self) -> None:
        self.conn.execute("BEGIN IMMEDIATE")

    def __exit__(self, kind: object, exc: object, tb: object) -> None:
        if kind is None:
            self.conn.execute("COMMIT")
        elif self.conn.in_transaction:
            self.conn.execute("ROLLBACK")


def move_aside(path: Path, now: float | None = None) -> Path:
    """Rename a database that cannot be used (and its WAL and shared-memory files) to
    ``<name>.corrupt-<UTC time>``; returns the new path of the database."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(time.time() if now is None else now))
    target = path.with_name(f"{path.name}.corrupt-{stamp}")
    n = 1
    while target.exists():
        n += 1
        target = path.with_name(f"{path.name}.corrupt-{stamp}-{n}")
    for suffix in ("", "-wal", "-shm"):
        src = Path(f"{path}{suffix}")
        if src.exists():
            os.replace(src, Path(f"{target}{suffix}"))
    return target


# ---------------------------------------------------------------- readers


def check_range(start: float, end: float, step: float | None) -> None:
    """HistoryError naming what is wrong with a time range and step."""
    for name, value in (("start", start), ("end", end)):
        if not math.isfinite(value):
            raise HistoryError(f"{name} must be a finite time, not {value!r}")
    if end < start:
        raise HistoryError(f"end ({end:g}) is before start ({start:g})")
    if step is not None and (not math.isfinite(step) or step <= 0):
        raise HistoryError(f"step must be a number of seconds above 0, not {step!r}")


class HistoryStore:
    """Queries of the history file at ``path``; any thread, any number at once.

    A file not there yet has no rows. Each query opens the file read-only for itself.
    """

    def __init__(
        self, path: Path | str, max_rows: int = MAX_ROWS, counters: WriterCounters | None = None
    ) -> None:
        self.path = Path(path)
        self.max_rows = max_rows
        self.counters = counters
        """The writer's counters in a running gateway (``/metrics``), else None."""

    def _reader(self) -> sqlite3.Connection | None:
        """A read-only connection, or None while there is no file or no schema yet (the
        writer creates both when it starts)."""
        if not self.path.exists():
            return None
        conn = self._connect()
        if conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'events'").fetchone() is None:
            conn.close()
            return None
        return conn

    def _connect(self) -> sqlite3.Connection:
        conn = sqlite3.connect(
            f"{self.path.resolve().as_uri()}?mode=ro",
            uri=True,
            timeout=BUSY_TIMEOUT,
            check_same_thread=False,
        )
        return conn

    def drives(self) -> list[str]:
        """The drives the history has rows of."""
        conn = self._reader()
        if conn is None:
            return []
        with _closing(conn):
            return [name for (name,) in conn.execute("SELECT name FROM drives ORDER BY name")]

    def readings(
        self, drive_id: str, start: float, end: float, step: float | None = None
    ) -> list[HistoryRow]:
        """The drive's samples with ``start <= t < end``, in time order; with ``step``,
        one row per bucket of ``step`` seconds of the epoch holding a sample (the bucket's
        start, each reading's average).
        HistoryError for a bad range or more than ``max_rows`` rows."""
        check_range(start, end, step)
        if step is not None and (end - start) / step > self.max_rows:
            raise HistoryError(
                f"{(end - start) / step:.0f} buckets of {step:g} s: at most {self.max_rows} "
                f"per query (a step of at least {_fitting_step(start, end, self.max_rows):g} s)"
            )
        conn = self._reader()
        if conn is None:
            return []
        with _closing(conn):
            found = conn.execute("SELECT id FROM drives WHERE name = ?", (drive_id,)).fetchone()
            if found is None:
                return []
            rows = self._select(conn, found[0], start, end, step)
        return [HistoryRow(t, dict(zip(READINGS, values, strict=True))) for t, *values in rows]

    def _select(
        self, conn: sqlite3.Connection, drive: int, start: float, end: float, step: float | None
    ) -> list[tuple[Any, ...]]:
        cols = ", ".join(READINGS)
        limit = self.max_rows + 1
        if step is None:
            rows = conn.execute(
                f"SELECT t, {cols} FROM readings WHERE drive = ? AND t >= ? AND t < ? "
                "ORDER BY t LIMIT ?",
                (drive, start, end, limit),
            ).fetchall()
            if len(rows) > self.max_rows:
                raise HistoryError(
                    f"more than {self.max_rows} samples from {start:g} to {end:g}: give a step "
                    f"(at least {_fitting_step(start, end, self.max_rows):g} s) or a shorter range"
                )
            return rows
        if step % MINUTE == 0 and end - start >= 2 * MINUTE:
            return _by_minutes(conn, drive, start, end, step)
        return _buckets(_raw_sums(conn, drive, start, end, step), step)

    def events(
        self,
        drive_id: str | None,
        start: float,
        end: float,
        limit: int | None = None,
        newest: bool = False,
    ) -> list[HistoryEvent]:
        """The events (of one drive, or of all with None) with ``start <= t < end``, in
        order (``newest``: the newest first); HistoryError beyond ``max_rows``. With
        ``limit``: at most ``limit + 1`` (the one after the last is where the next read
        goes on), never an error."""
        check_range(start, end, None)
        cap = self.max_rows if limit is None else min(limit, self.max_rows)
        conn = self._reader()
        if conn is None:
            return []
        where = "t >= ? AND t < ?"
        args: list[Any] = [start, end]
        if drive_id is not None:
            where += " AND drive = ?"
            args.append(drive_id)
        with _closing(conn):
            rows = conn.execute(
                f"SELECT t, drive, kind, text, data FROM events WHERE {where} "
                f"ORDER BY {'t DESC, id DESC' if newest else 't, id'} LIMIT ?",
                (*args, cap + 1),
            ).fetchall()
        if limit is None and len(rows) > self.max_rows:
            raise HistoryError(f"more than {self.max_rows} events: ask for a shorter range")
        return [HistoryEvent(t, d, k, text, _data(raw)) for t, d, k, text, raw in rows]


Sums = dict[int, list[float]]
"""Bucket number -> per reading, its sum and its count (as in ``minutes``)."""


def _raw_sums(conn: sqlite3.Connection, drive: int, start: float, end: float, step: float) -> Sums:
    """The samples' sums and counts per bucket of ``step`` seconds of the epoch."""
    sums = ", ".join(f"TOTAL({n}), COUNT({n})" for n in READINGS)
    out: Sums = {}
    for bucket, *acc in conn.execute(
        f"SELECT CAST(t / ? AS INTEGER) - (t < 0) AS b, {sums} FROM readings "
        "WHERE drive = ? AND t >= ? AND t < ? GROUP BY b",
        (step, drive, start, end),
    ):
        out[bucket] = [float(x) for x in acc]
    return out


def _by_minutes(
    conn: sqlite3.Connection, drive: int, start: float, end: float, step: float
) -> list[tuple[Any, ...]]:
    """Buckets of whole minutes: the minutes wholly in the range from ``minutes``, the
    partial minutes at its edges from the samples."""
    first = math.ceil(start / MINUTE)
    last = math.floor(end / MINUTE)  # minutes [first, last) are wholly inside
    per = int(step // MINUTE)
    out: Sums = {}
    for minute, *acc in conn.execute(
        f"SELECT m, {_ROLLUP_NAMES} FROM minutes WHERE drive = ? AND m >= ? AND m < ?",
        (drive, first, last),
    ):
        _add(out, minute // per, acc)
    for lo, hi in ((start, first * MINUTE), (last * MINUTE, end)):
        if hi > lo:
            for bucket, acc in _raw_sums(conn, drive, lo, hi, step).items():
                _add(out, bucket, acc)
    return _buckets(out, step)


def _add(out: Sums, bucket: int, acc: Sequence[float]) -> None:
    mine = out.get(bucket)
    if mine is None:
        out[bucket] = [float(x) for x in acc]
    else:
        for i, x in enumerate(acc):
            mine[i] += x


def _buckets(sums: Sums, step: float) -> list[tuple[Any, ...]]:
    """One row per bucket holding a sample: its start and each reading's average."""
    rows = []
    for bucket in sorted(sums):
        acc = sums[bucket]
        if not any(acc[1::2]):
            continue
        averages = [acc[i] / acc[i + 1] if acc[i + 1] else None for i in range(0, len(acc), 2)]
        rows.append((float(bucket * step), *averages))
    return rows


def _data(raw: str) -> dict[str, Any]:
    try:
        value = json.loads(raw)
    except ValueError:
        return {}
    return value if isinstance(value, dict) else {}


def _fitting_step(start: float, end: float, max_rows: int) -> float:
    """The smallest whole number of seconds that makes at most ``max_rows`` buckets."""
    return float(max(1, math.ceil((end - start) / max_rows)))


class _closing:
    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def __enter__(self) -> sqlite3.Connection:
        return self.conn

    def __exit__(self, *exc: object) -> None:
        self.conn.close()


def samples_of(t: float, states: Iterable[Any]) -> list[Sample]:
    """One sample per drive that gives at least one reading (an offline drive gives none:
    its readings are unknown, never its last values)."""
    out = []
    for state in states:
        values = tuple(getattr(state, name) for name in READINGS)
        if any(v is not None for v in values):
            out.append(Sample(state.id, t, values))
    return out
