"""A CANopen ``eds =`` file is read only if it is a regular file of at most 4 MiB, and its
values must be in their ranges (a DefaultValue within LowLimit..HighLimit and within its
DataType): ``check-config`` and ``run`` refuse the same files with the same lines. A
DefaultValue beyond its DataType used to pass ``check-config``; ``run`` with simulated
drives then crashed the line on every bring-up (6 restarts in 30 s)."""

from __future__ import annotations

import re
from pathlib import Path

import canopen
import pytest

from adapters.canopen.codec.od import parse, value_problems
from adapters.canopen.errors import EdsError
from adapters.canopen.options import read_eds
from adapters.canopen.sim.node import EdsUnreadable, load_od
from gateway.config import shipped_file
from tests.support.vendorfiles import check_and_run, refusal, special_files

EDS = shipped_file("eds/cia402-drive.eds")
ABORT = "Abort connection option code"  # 0x6007, INTEGER16, LowLimit 0, HighLimit 3


def edited(tmp_path: Path, name: str, *changes: tuple[str, str, str]) -> Path:
    """The shipped EDS with ``(section, key, value)`` set in each section named."""
    text = EDS.read_text()
    for section, key, value in changes:
        start = text.index(f"\n[{section}]\n")
        end = text.find("\n[", start + 1)
        body = text[start:end]
        line = f"{key}={value}"
        pattern = rf"^{key}=.*$"
        if re.search(pattern, body, flags=re.MULTILINE):
            body = re.sub(pattern, line, body, flags=re.MULTILINE)
        else:
            body = body.rstrip("\n") + f"\n{line}\n"
        text = text[:start] + body + text[end:]
    path = tmp_path / name
    path.write_text(text)
    return path


def problems_of(path: Path) -> list[tuple[str, str]]:
    return value_problems(canopen.import_od(str(path), 5))


def test_the_shipped_eds_has_every_value_in_range() -> None:
    assert problems_of(EDS) == []


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        (
            ("6007", "DefaultValue", "7"),
            ("0x6007", f"DefaultValue 7 is above its HighLimit 3 ({ABORT})"),
        ),
        (
            ("6007", "DefaultValue", "-1"),
            ("0x6007", f"DefaultValue -1 is below its LowLimit 0 ({ABORT})"),
        ),
        (
            ("6007", "DefaultValue", "40000"),
            (
                "0x6007",
                f"DefaultValue 40000 is beyond its DataType INTEGER16 (-32768..32767) ({ABORT})",
            ),
        ),
        (
            ("1017", "DefaultValue", "0x10000"),
            (
                "0x1017",
                "DefaultValue 65536 is beyond its DataType UNSIGNED16 (0..65535) (Producer heartbeat time)",
            ),
        ),
        (
            ("2000sub4", "DefaultValue", "50"),
            ("0x2000:4", "DefaultValue 50 is below its LowLimit 100 (Rated speed (rpm))"),
        ),
        (
            ("6007", "ParameterValue", "9"),
            ("0x6007", f"ParameterValue 9 is above its HighLimit 3 ({ABORT})"),
        ),
    ],
)
def test_a_value_out_of_its_range_is_named(
    tmp_path: Path, change: tuple[str, str, str], problem: tuple[str, str]
) -> None:
    assert problems_of(edited(tmp_path, "bad.eds", change)) == [problem]


def test_the_first_problem_is_named_with_how_many_more(tmp_path: Path) -> None:
    bad = edited(
        tmp_path, "bad.eds", ("1017", "DefaultValue", "70000"), ("6007", "DefaultValue", "7")
    )
    with pytest.raises(EdsError) as info:
        parse(str(bad), bad.read_bytes(), 5)
    assert str(info.value) == (
        f"{bad}: 0x1017: DefaultValue 70000 is beyond its DataType UNSIGNED16 (0..65535) "
        "(Producer heartbeat time) (and 1 more value(s) out of range)"
    )


def test_check_config_and_run_refuse_the_same_eds_files_alike(tmp_path: Path) -> None:
    files = special_files(tmp_path, ".eds")
    files["above"] = edited(tmp_path, "above.eds", ("6007", "DefaultValue", "7"))
    files["beyond"] = edited(tmp_path, "beyond.eds", ("6007", "DefaultValue", "40000"))
    text = (
        "[buses.co]\nadapter = 'canopen'\ninterface = 'virtual'\nchannel = 'x'\nsimulate = true\n"
    )
    for node, (kind, path) in enumerate(files.items(), start=5):
        text += (
            f"[[buses.co.drives]]\nid = '{kind}'\ndevice = 'CiA 402'\naddress = {node}\n"
            f"eds = '{path}'\nmax_rpm = 1800\n"
        )
    config = tmp_path / "site.toml"
    config.write_text(text)
    check, run = check_and_run(config)
    key = "error: {config}: buses.co.drives[{kind}].eds: "
    expected = [
        key.format(config=config, kind=kind) + refusal(kind, path, "an EDS file")
        for kind, path in files.items()
        if kind not in ("above", "beyond")
    ] + [
        key.format(config=config, kind="above")
        + f"{files['above']}: 0x6007: DefaultValue 7 is above its HighLimit 3 ({ABORT})",
        key.format(config=config, kind="beyond")
        + f"{files['beyond']}: 0x6007: DefaultValue 40000 is beyond its DataType INTEGER16 "
        f"(-32768..32767) ({ABORT})",
    ]
    assert (check.status, check.errors) == (2, expected), check.stderr
    assert (run.status, run.errors) == (2, expected), run.stderr
    assert "Traceback" not in check.stderr + run.stderr


@pytest.mark.parametrize("kind", ["device", "fifo", "link", "big"])
def test_read_eds_refuses_what_is_not_an_eds_file(tmp_path: Path, kind: str) -> None:
    path = special_files(tmp_path, ".eds")[kind]
    with pytest.raises(EdsError) as info:
        read_eds(path)
    assert str(info.value) == refusal(kind, path, "an EDS file")


def test_the_simulator_reads_and_checks_its_eds_alike(tmp_path: Path) -> None:
    """``drive-gateway sim canopen --eds`` and a simulated drive read the file as the
    options do: the same refusals."""
    bad = edited(tmp_path, "bad.eds", ("6007", "DefaultValue", "40000"))
    with pytest.raises(EdsUnreadable, match=r"0x6007: DefaultValue 40000 is beyond its DataType"):
        load_od(bad, 5)
    fifo = special_files(tmp_path, ".eds")["fifo"]
    with pytest.raises(EdsUnreadable, match="is a named pipe, not a regular file"):
        load_od(fifo)
    assert len(load_od(EDS, 5).indices) > 0
