"""``params diff FILE DRIVE``: the drive's side is read with the drive's own table, so both
sides are in the same unit ("2.5 s" beside "2.5 s", never "25 s" for a raw 25)."""

from __future__ import annotations

from gateway import paramsbackup as pb
from gateway.adapter import ParamInfo, ParamTable, ParamValue, param_table

DRIVE_TABLE = param_table(
    [
        ParamInfo(100, "Acceleration time", "s", decimals=1, code="P0100"),
        ParamInfo(401, "Motor rated current", "A", decimals=1, code="P0401"),
        ParamInfo(220, "Local/remote source", "", code="P0220"),
    ]
)


def a_file(raws: dict[int, int]) -> pb.Backup:
    entries = tuple(pb.entry_of(n, 0, DRIVE_TABLE.get(n), raw) for n, raw in raws.items())
    return pb.Backup(pb.Identity("cfw11", "CFW-11"), entries)


async def read_back(table: ParamTable, file: pb.Backup, drive: dict[int, int]) -> list[pb.DiffRow]:
    async def read(number: int, subindex: int) -> ParamValue:
        return drive[number]

    entries = await pb.read_all([p.key for p in file.params], table, read)
    return pb.compare(file.params, entries)


async def test_the_drive_side_is_in_the_unit_of_the_file_side() -> None:
    file = a_file({100: 25, 401: 41, 220: 1})
    table = pb.reading_table(DRIVE_TABLE, file)
    rows = {r.label: r for r in await read_back(table, file, {100: 25, 401: 43, 220: 1})}
    assert (rows["P0100"].left, rows["P0100"].right, rows["P0100"].status) == (
        "2.5 s",
        "2.5 s",
        "same",
    )
    assert (rows["P0401"].left, rows["P0401"].right, rows["P0401"].status) == (
        "4.1 A",
        "4.3 A",
        "differs",
    )
    assert rows["P0220"].right == "1"


async def test_a_number_the_drive_table_lacks_is_shown_raw_not_with_a_wrong_unit() -> None:
    file = a_file({100: 25, 220: 1})
    table = pb.reading_table(param_table([]), file)  # a drive that gives no table
    rows = {r.label: r for r in await read_back(table, file, {100: 25, 220: 2})}
    assert rows["P0100"].right == "25"  # raw: the file keeps no scale; never "25 s"
    assert rows["P0100"].name == "Acceleration time"
    assert rows["P0220"].right == "2" and rows["P0220"].status == "differs"
