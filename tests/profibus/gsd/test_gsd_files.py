"""A ``gsd =`` file is read only if it is a regular file of at most 4 MiB: ``check-config``
and ``run`` refuse /dev/zero, a named pipe, a link to /dev/zero and a 400 MB file with the
same lines, at once (each command runs bounded: tests/support/vendorfiles.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from adapters.profibus.codec.gsd import GsdError
from adapters.profibus.options import find_in_dir, load_gsd
from tests.support.vendorfiles import check_and_run, refusal, special_files

GSD_DIR = Path(__file__).resolve().parents[2] / "data" / "gsd"


def site(tmp_path: Path, files: dict[str, Path]) -> Path:
    text = "[buses.pb]\nadapter = 'profibus'\nsimulate = true\n"
    for address, (kind, path) in enumerate(files.items(), start=4):
        text += (
            f"[[buses.pb.drives]]\nid = '{kind}'\ndevice = 'CFW700'\naddress = {address}\n"
            f"gsd = '{path}'\nmodule = '3 words I/O'\n"
        )
    config = tmp_path / "site.toml"
    config.write_text(text)
    return config


def test_check_config_and_run_refuse_what_is_not_a_gsd_file_alike(tmp_path: Path) -> None:
    files = special_files(tmp_path, ".gsd")
    config = site(tmp_path, files)
    check, run = check_and_run(config)
    expected = [
        f"error: {config}: buses.pb.drives[{kind}].gsd: {refusal(kind, path, 'a GSD file')}"
        for kind, path in files.items()
    ]
    assert (check.status, check.errors) == (2, expected), check.stderr
    assert (run.status, run.errors) == (2, expected), run.stderr
    assert "Traceback" not in check.stderr + run.stderr


@pytest.mark.parametrize("kind", ["device", "fifo", "link", "big"])
def test_load_gsd_refuses_it_with_a_gsd_error(tmp_path: Path, kind: str) -> None:
    path = special_files(tmp_path, ".gsd")[kind]
    with pytest.raises(GsdError) as info:
        load_gsd(path)
    assert str(info.value) == refusal(kind, path, "a GSD file")


def test_the_scan_passes_over_what_is_not_a_gsd_file(tmp_path: Path) -> None:
    """``profibus scan --gsd-dir``: the special files are passed over, the real one found."""
    special_files(tmp_path, ".gsd")
    (tmp_path / "TEST_CFW700.gsd").write_bytes((GSD_DIR / "TEST_CFW700.gsd").read_bytes())
    found = find_in_dir(tmp_path, 0x0C70)
    assert [Path(g.path).name for g in found] == ["TEST_CFW700.gsd"]
