"""A DeviceNet ``eds =`` file is read only if it is a regular file of at most 4 MiB:
``check-config`` and ``run`` refuse /dev/zero, a named pipe, a link to /dev/zero and a
400 MB file with the same lines, at once (each command runs bounded:
tests/support/vendorfiles.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from adapters.devicenet.errors import EdsError
from adapters.devicenet.options import load_eds
from tests.support.vendorfiles import check_and_run, refusal, special_files


def site(tmp_path: Path, files: dict[str, Path]) -> Path:
    text = "[buses.dn]\nadapter = 'devicenet'\ninterface = 'virtual'\nsimulate = true\n"
    for address, (kind, path) in enumerate(files.items(), start=5):
        text += (
            f"[[buses.dn.drives]]\nid = '{kind}'\ndevice = 'CFW-08'\naddress = {address}\n"
            f"max_rpm = 1800\neds = '{path}'\n"
        )
    config = tmp_path / "site.toml"
    config.write_text(text)
    return config


def test_check_config_and_run_refuse_what_is_not_an_eds_file_alike(tmp_path: Path) -> None:
    files = special_files(tmp_path, ".eds")
    config = site(tmp_path, files)
    check, run = check_and_run(config)
    expected = [
        f"error: {config}: buses.dn.drives[{kind}].eds: {refusal(kind, path, 'an EDS file')}"
        for kind, path in files.items()
    ]
    assert (check.status, check.errors) == (2, expected), check.stderr
    assert (run.status, run.errors) == (2, expected), run.stderr
    assert "Traceback" not in check.stderr + run.stderr


@pytest.mark.parametrize("kind", ["device", "fifo", "link", "big"])
def test_load_eds_refuses_it_with_an_eds_error(tmp_path: Path, kind: str) -> None:
    path = special_files(tmp_path, ".eds")[kind]
    with pytest.raises(EdsError) as info:
        load_eds(path)
    assert str(info.value) == refusal(kind, path, "an EDS file")
