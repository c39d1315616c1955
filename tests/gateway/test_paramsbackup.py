"""The parameter backup document and its rules (gateway/paramsbackup.py), without a bus."""

from __future__ import annotations

import io
import json
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway import paramsbackup as pb
from gateway.adapter import ParamInfo, ParamValue, param_table
from gateway.cli.params import ProgressOut
from gateway.errors import GatewayTimeout, ParameterError

TABLE = param_table(
    [
        ParamInfo(100, "Acceleration time", "s", 1, code="P0100"),
        ParamInfo(23, "Software version", "", 2, code="P0023"),
    ]
)
DRIVE = pb.Identity("cfw11", "CFW-11", "pb", 3, {}, "5.00", "P0023")


def test_parse_numbers() -> None:
    assert pb.parse_numbers("100-102, P0134,p313,964.2,100") == (
        (100, 0),
        (101, 0),
        (102, 0),
        (134, 0),
        (313, 0),
        (964, 2),
    )
    for bad, why in [
        ("", "no parameter"),
        ("x", "not a parameter number"),
        ("10-5", "ends below"),
        ("0-5000", "over 4096"),
        ("964.x", "subindex"),
        ("70000", "beyond 65535"),
    ]:
        with pytest.raises(pb.BackupError, match=why):
            pb.parse_numbers(bad)


entries = st.builds(
    pb.ParamEntry,
    number=st.integers(0, 65535),
    subindex=st.integers(0, 255),
    code=st.text(max_size=6),
    name=st.text(max_size=20),
    unit=st.text(max_size=4),
    raw=st.one_of(st.integers(-(2**31), 2**31), st.floats(allow_nan=False, allow_infinity=False)),
    scaled=st.none() | st.integers(-1000, 1000),
)
errors = st.builds(
    pb.ParamEntry,
    number=st.integers(0, 65535),
    error=st.text(min_size=1, max_size=30),
    error_code=st.none() | st.integers(0, 0xFFFF),
)


@given(st.lists(entries | errors, max_size=30, unique_by=lambda e: e.key))
def test_the_document_round_trips_through_json(params: list[pb.ParamEntry]) -> None:
    backup = pb.Backup(DRIVE, tuple(params), "2026-11-25T03:00:00+00:00", "line-3 0.1.0")
    again = pb.Backup.from_json(json.loads(json.dumps(backup.to_json())))
    assert again == backup


def good() -> dict[str, Any]:
    return pb.Backup(DRIVE, (pb.ParamEntry(100, raw=20, scaled=2.0),)).to_json()


@pytest.mark.parametrize(
    ("change", "why"),
    [
        (lambda d: d.pop("schema"), "not a parameter backup"),
        (lambda d: d.update(version=2), "version 2"),
        (lambda d: d["params"].append(dict(d["params"][0])), "listed twice"),
        (lambda d: d["params"][0].update(raw="20"), r"params\[0\]\.raw"),
        (lambda d: d["params"][0].update(number=-1), r"params\[0\]\.number"),
        (lambda d: d["drive"].pop("device"), "drive.device"),
    ],
)
def test_a_bad_file_is_refused_with_the_reason(change: Any, why: str) -> None:
    doc = good()
    change(doc)
    with pytest.raises(pb.BackupError, match=why):
        pb.Backup.from_json(doc)


async def test_a_backup_goes_on_after_refusals_and_timeouts() -> None:
    async def read(number: int, subindex: int) -> ParamValue:
        if number == 1:
            raise ParameterError("parameter does not exist", 0x0000)
        if number == 2:
            raise GatewayTimeout("no DP-V1 answer within 1 s")
        return 20

    seen: list[int] = []
    backup = await pb.take(
        DRIVE, TABLE, [(1, 0), (2, 0), (100, 0)], read, progress=lambda d, t, e: seen.append(d)
    )
    one, two, p100 = backup.params
    assert (one.error, one.error_code) == ("parameter does not exist", 0)
    assert two.error == "no answer (no DP-V1 answer within 1 s)"
    assert (p100.code, p100.raw, p100.scaled, p100.shown()) == ("P0100", 20, 2.0, "2.0 s")
    assert seen == [1, 2, 3]
    with pytest.raises(pb.BackupError, match="no parameter table"):
        await pb.take(DRIVE, param_table([]), None, read)


async def test_firmware_where_the_bus_gives_it() -> None:
    async def read(number: int, subindex: int) -> ParamValue:
        assert number == 23
        return 500

    assert await pb.firmware_of("CFW-11", {}, {}, TABLE, read) == ("5.00", "P0023")
    values = {"software_version_major": 1, "software_version_minor": 4}
    assert (await pb.firmware_of("MCD 600", values, {}, TABLE, read))[0] == "1.4"
    none, why = await pb.firmware_of("CFW320", {}, {}, TABLE, read)
    assert none is None and "not readable" in why


def entry(number: int, raw: int | None = None, error: str | None = None) -> pb.ParamEntry:
    return pb.ParamEntry(number, raw=raw, scaled=raw, error=error)


def test_compare() -> None:
    left = [entry(1, 5), entry(2, 6), entry(3, 7), entry(5, error="x")]
    right = [entry(1, 5), entry(2, 9), entry(4, 1), entry(5, 3)]
    assert [r.status for r in pb.compare(left, right)] == [
        "same",
        "differs",
        "only left",
        "only right",
        "error",
    ]


def test_a_restore_writes_only_what_differs_and_may_be_written() -> None:
    backup = pb.Backup(
        DRIVE, (entry(100, 20), entry(101, 30), entry(134, 1800), entry(2, error="refused"))
    )
    current = {e.key: e for e in (entry(100, 25), entry(101, 30), entry(134, 1500), entry(2, 0))}
    steps = {s.entry.number: s for s in pb.plan(backup, current, [100, 101], "cfw11")}
    assert (steps[100].action, steps[101].action) == ("write", "same")
    assert steps[134].action == "skip" and "writable_params of drive cfw11" in steps[134].reason
    assert steps[2].action == "skip" and "when taken: refused" in steps[2].reason


def test_a_restore_needs_a_stopped_drive_of_the_same_model() -> None:
    backup = pb.Backup(DRIVE, ())
    with pytest.raises(pb.BackupError, match="drive x is a CFW700"):
        pb.check_target(backup, {"id": "x", "device": "CFW700"})
    stopped = {"id": "x", "comm": "online", "status": "ready", "running": False}
    assert pb.not_stopped(stopped) is None
    assert "running" in str(pb.not_stopped({**stopped, "status": "stopping"}))
    assert "not online" in str(pb.not_stopped({**stopped, "comm": "offline"}))


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_a_bar_on_a_terminal_and_lines_otherwise(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("TERM", "xterm")
    p100 = pb.ParamEntry(100, code="P0100", name="Acceleration time", unit="s", raw=20, scaled=2.0)
    tty = Tty()
    bar = ProgressOut("backup cfw11", tty)
    bar(1, 2, p100)
    bar(2, 2, p100)
    assert tty.getvalue().startswith("\rbackup cfw11 [" + "#" * 15 + "." * 15 + "] 1/2 P0100")
    assert tty.getvalue().endswith("\n") and tty.getvalue().count("\n") == 1
    plain = io.StringIO()
    ProgressOut("backup cfw11", plain)(1, 2, p100)
    assert plain.getvalue() == "backup cfw11 1/2 P0100 Acceleration time = 2.0 s\n"


async def test_subindex_entries_of_writable_params_are_backed_up_and_restored() -> None:
    """``writable_params = ["0x6083", "0x2000:4"]``: 0x2000:4 is read beside the table's
    numbers (subindex 0) and restored; 0x2000:1, not listed, is only compared."""
    table = param_table([ParamInfo(0x2000, "Manufacturer record"), ParamInfo(0x6083, "Accel")])
    entries = pb.entries_from_json(pb.entries_to_json([(0x2000, 4)]))
    assert entries == {(0x2000, 4)}
    assert pb.choose(table, None, entries) == [(0x2000, 0), (0x2000, 4), (0x6083, 0)]
    assert pb.choose(param_table([]), None, entries) == [(0x2000, 4)]
    assert pb.choose(table, [(0x2000, 1)], entries) == [(0x2000, 1)]  # asked: only that

    values = {(0x2000, 0): 4, (0x2000, 4): 1800, (0x6083, 0): 500}

    async def read(number: int, subindex: int) -> ParamValue:
        return values[(number, subindex)]

    backup = await pb.take(DRIVE, table, None, read, entries=entries)
    assert [(e.key, e.raw, e.label) for e in backup.params] == [
        ((0x2000, 0), 4, "P8192"),
        ((0x2000, 4), 1800, "P8192.4"),
        ((0x6083, 0), 500, "P24707"),
    ]
    again = pb.Backup.from_json(json.loads(json.dumps(backup.to_json())))
    now = {
        (0x2000, 0): pb.ParamEntry(0x2000, 0, raw=4),
        (0x2000, 1): pb.ParamEntry(0x2000, 1, raw=7),
        (0x2000, 4): pb.ParamEntry(0x2000, 4, raw=1500),
        (0x6083, 0): pb.ParamEntry(0x6083, 0, raw=400),
    }
    stale = pb.Backup(DRIVE, (*again.params, pb.ParamEntry(0x2000, 1, raw=9)))
    steps = {s.entry.key: s for s in pb.plan(stale, now, [0x6083], "co", entries)}
    assert steps[(0x2000, 4)].action == "write"
    assert steps[(0x6083, 0)].action == "write"
    assert steps[(0x2000, 0)].action == "same"
    assert steps[(0x2000, 1)].action == "skip"
    assert "writable_params of drive co" in steps[(0x2000, 1)].reason
    # without the entries (an older gateway's describe) 0x2000:4 is skipped, as before
    old = {s.entry.key: s for s in pb.plan(stale, now, [0x6083], "co")}
    assert old[(0x2000, 4)].action == "skip"


def test_writable_entries_from_a_describe_answer() -> None:
    assert pb.entries_from_json(None) == frozenset()
    assert pb.entries_from_json([[8192, 4], [24707, 0]]) == {(8192, 4), (24707, 0)}
    for bad, why in [
        ("x", "not a list"),
        ([[1]], r"writable_entries\[0\]: not a \[number, subindex\] pair"),
        ([[1, 2], [70000, 1]], r"writable_entries\[1\]"),
    ]:
        with pytest.raises(pb.BackupError, match=why):
            pb.entries_from_json(bad)
