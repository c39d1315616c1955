"""History: the write cost per reading and the query of a day of one drive.

A day of synthetic 1 Hz samples of one drive (every reading given) is written as the
writer thread writes it (gateway/history/store.py ``HistoryDb.write`` and a checkpoint,
batches of one second of 220 drives), then queried: every sample, and downsampled with a step of 60 s
(the page's trend over a day). The references, in the same run: the same rows inserted
with a bare ``executemany`` into a table of the same shape in memory (SQLite's floor, no
file, no minute sums), and the day's rows read with bare SQL.
"""

from __future__ import annotations

import sqlite3
import tempfile
import time
from pathlib import Path

from bench.common import Figure, add_number, arg_parser, print_figures
from gateway.history.store import READINGS, HistoryDb, HistoryStore, Sample

DAY = 86400
DRIVES_PER_BATCH = 220  # a plant's drives: one batch is one second of them
T0 = 1_767_225_600.0


def _samples(seconds: int) -> list[Sample]:
    return [
        Sample("d1", T0 + i, tuple(float(i % 1500) + k for k in range(len(READINGS))))
        for i in range(seconds)
    ]


def _write(db: HistoryDb, samples: list[Sample]) -> float:
    started = time.perf_counter()
    for at in range(0, len(samples), DRIVES_PER_BATCH):
        db.write(samples[at : at + DRIVES_PER_BATCH], [])
        db.checkpoint()  # as the writer thread does after each batch
    return time.perf_counter() - started


def _bare_write(samples: list[Sample]) -> float:
    conn = sqlite3.connect(":memory:")
    conn.execute(f"CREATE TABLE r (drive INTEGER, t REAL, {', '.join(READINGS)})")
    started = time.perf_counter()
    for at in range(0, len(samples), DRIVES_PER_BATCH):
        with conn:
            conn.executemany(
                f"INSERT INTO r VALUES (1, ?, {', '.join('?' for _ in READINGS)})",
                [(s.t, *s.values) for s in samples[at : at + DRIVES_PER_BATCH]],
            )
    elapsed = time.perf_counter() - started
    conn.close()
    return elapsed


def _best(fn: object, rounds: int) -> float:
    times = []
    for _ in range(rounds):
        started = time.perf_counter()
        fn()  # type: ignore[operator]
        times.append(time.perf_counter() - started)
    return min(times)


def run(seconds: int = DAY, rounds: int = 5) -> list[Figure]:
    samples = _samples(seconds)
    readings = len(samples) * len(READINGS)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "history.sqlite"
        db = HistoryDb.open_checked(path)
        written = _write(db, samples)
        size = db.used_bytes()
        db.close()
        bare = _bare_write(samples)
        store = HistoryStore(path, max_rows=seconds + 1)
        end = T0 + seconds
        step60 = _best(lambda: store.readings("d1", T0, end, 60.0), rounds)
        raw = _best(lambda: store.readings("d1", T0, end), rounds)
        conn = sqlite3.connect(path)
        sql = _best(
            lambda: conn.execute(
                f"SELECT t, {', '.join(READINGS)} FROM readings WHERE drive = 1 AND t >= ? "
                "AND t < ?",
                (T0, end),
            ).fetchall(),
            rounds,
        )
        conn.close()
    return [
        Figure(
            "history_write_us_per_reading",
            written / readings * 1e6,
            "us",
            bare / readings * 1e6,
            note=f"{seconds} samples of {len(READINGS)} readings, batches of "
            f"{DRIVES_PER_BATCH}; reference: bare executemany in memory",
        ),
        Figure(
            "history_bytes_per_sample", size / len(samples), "bytes", None, note="file pages in use"
        ),
        Figure(
            "history_query_day_step60_ms",
            step60 * 1e3,
            "ms",
            sql * 1e3,
            "< 100 ms",
            note="one drive, a day at 1 Hz, 1440 buckets; reference: the day's rows by bare SQL",
        ),
        Figure(
            "history_query_day_raw_ms",
            raw * 1e3,
            "ms",
            sql * 1e3,
            note="every sample of the day as HistoryRow objects",
        ),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_history", __doc__)
    add_number(parser, "--seconds", DAY, "seconds of 1 Hz samples (a day)")
    add_number(parser, "--rounds", 5, "queries timed (the best counts)")
    args = parser.parse_args(argv)
    print_figures(run(args.seconds, args.rounds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
