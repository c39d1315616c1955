"""``drive-gateway history``: the file read directly, CSV and JSON, bad ranges refused."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from gateway.cli import main
from gateway.history.store import READINGS, HistoryDb, HistoryEvent, Sample

T0 = 1_767_225_600.0


@pytest.fixture
def history(tmp_path: Path) -> Path:
    path = tmp_path / "h.sqlite"
    db = HistoryDb.open_checked(path)
    rest = (None,) * (len(READINGS) - 2)
    db.write(
        [Sample("cfw11", T0 + i, (float(i), 50.0, *rest)) for i in range(120)],
        [HistoryEvent(T0 + 5, "cfw11", "fault", "F021 undervoltage", {"code": 21})],
    )
    db.close()
    return path


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(["history", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_csv_of_the_samples(history: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys, "cfw11", "--file", str(history), "--start", str(T0), "--end", str(T0 + 3)
    )
    assert code == 0
    rows = list(csv.reader(io.StringIO(out)))
    assert rows[0] == ["t", "time", "speed_rpm", "speed_pct"]
    assert rows[1] == [f"{T0:.3f}", "2026-01-01T00:00:00.000Z", "0.0", "50.0"]
    assert len(rows) == 4


def test_json_downsampled(history: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys,
        "cfw11",
        "--file",
        str(history),
        "--start",
        "2026-01-01T00:00:00Z",
        "--end",
        "2026-01-01T00:02:00Z",
        "--step",
        "1m",
        "--format",
        "json",
    )
    assert code == 0
    body = json.loads(out)
    assert body["t"] == [T0, T0 + 60]
    assert body["values"]["speed_rpm"] == [29.5, 89.5]


def test_events(history: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys, "*", "--events", "--file", str(history), "--start", str(T0), "--format", "json"
    )
    assert code == 0
    assert json.loads(out)["events"][0]["code"] == 21


def test_a_bad_range_is_refused_by_name(history: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "cfw11", "--file", str(history), "--start", "soon")
    assert code == 2
    assert "start='soon' is not a time" in err


def test_no_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "cfw11", "--file", str(tmp_path / "none.sqlite"))
    assert code == 1
    assert "no history file" in err
