"""The GSD corpus read by pyprofibus's GSD parser, compared with ours.

pyprofibus is GPL: it is never imported here nor a dependency of the project. As the
pyprofibus bench does (bench/bench_pyprofibus.py, whose installer this uses), it is
installed from PyPI into a venv of its own, kept in pytest's cache directory, and a small
script of ours (:data:`SCRIPT`, its public API: ``GsdInterp``) runs with that venv's Python
as a separate process. Without network or PyPI the comparison is skipped, saying why.

Where pyprofibus reads a file otherwise, :data:`PYPROFIBUS_READS_OTHERWISE` gives its
bytes, worked out by hand from what it does, and why they differ from the
specification's; every other file must give the same Chk_Cfg and user parameter bytes.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Final

import pytest

from bench import bench_pyprofibus as bench
from tests.profibus.gsd.corpus import CASES

SCRIPT: Final = r"""
import json
import sys

from pyprofibus.gsd.interp import GsdInterp

results = {}
for case in json.load(sys.stdin):
    try:
        gsd = GsdInterp.fromFile(case["path"])
        gsd.clearConfiguredModules()
        for name in case["modules"]:
            gsd.setConfiguredModule(name)
        cfg = b"".join(bytes([e.identifier]) + bytes(e.lengthBytes)
                       for e in gsd.getCfgDataElements())
        results[case["file"]] = {"cfg": cfg.hex(), "user_prm": bytes(gsd.getUserPrmData()).hex()}
    except Exception as exc:
        results[case["file"]] = {"error": "%s: %s" % (type(exc).__name__, exc)}
print("RESULT " + json.dumps(results), flush=True)
"""

NO_REFS: Final = (
    "pyprofibus 1.13 does not place the defaults of Ext_User_Prm_Data_Ref parameters: "
    "it sends the constant bytes only"
)
PYPROFIBUS_READS_OTHERWISE: Final[dict[str, tuple[dict[str, str], str]]] = {
    "compact_ext.gsd": ({"cfg": "f1", "user_prm": "0000000000"}, NO_REFS),
    "dpv1_drive.gsd": ({"cfg": "f371", "user_prm": "8000000000"}, NO_REFS),
    "ref_before_const.gsd": (
        {"cfg": "1727", "user_prm": "0000"},
        NO_REFS + "; a module block without Ext_Module_Prm_Data_Len ends at its last constant",
    ),
    "mixed_legacy_ext.gsd": (
        {"cfg": "31", "user_prm": "001002dd"},
        "pyprofibus lays the Ext constants over User_Prm_Data (User_Prm_Data_Len bytes) "
        "where the specification leaves User_Prm_Data out",
    ),
    "odd_layout.gsd": (
        {"error": "not found in GSD"},
        "pyprofibus reads keywords only as the specification spells them and names only in "
        "ASCII: it reads no module of the file",
    ),
}


@pytest.fixture(scope="module")
def pyprofibus_python(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """The Python of a venv with pyprofibus (made once, kept in pytest's cache)."""
    cache = getattr(request.config, "cache", None)
    where = cache.mkdir("pyprofibus-venv") if cache is not None else tmp_path_factory.mktemp("pp")
    return venv_python(where)


def venv_python(where: Path) -> Path:
    """The venv under ``where`` if pyprofibus imports there, else a new one; a skip saying
    why when it cannot be installed."""
    python = where / "venv" / "bin" / "python"
    if python.exists() and _imports_pyprofibus(python):
        return python
    try:
        return bench.install_pyprofibus(where)
    except bench.Skipped as exc:
        pytest.skip(f"pyprofibus could not be installed in its own venv (needs PyPI): {exc}")


def _imports_pyprofibus(python: Path) -> bool:
    done = subprocess.run(
        [str(python), "-c", "import pyprofibus.gsd"], capture_output=True, check=False, timeout=60
    )
    return done.returncode == 0


def _their_readings(python: Path, tmp_path: Path) -> dict[str, dict[str, str]]:
    script = tmp_path / "pyprofibus_gsd.py"
    script.write_text(SCRIPT)
    cases = [{"file": c.file, "path": str(c.path), "modules": list(c.modules)} for c in CASES]
    done = subprocess.run(
        [str(python), str(script)],
        input=json.dumps(cases),
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    lines = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")]
    assert done.returncode == 0 and lines, f"pyprofibus script failed: {done.stderr[-2000:]}"
    result: dict[str, dict[str, str]] = json.loads(lines[-1][len("RESULT ") :])
    return result


def test_the_corpus_against_pyprofibus(pyprofibus_python: Path, tmp_path: Path) -> None:
    theirs = _their_readings(pyprofibus_python, tmp_path)
    assert sorted(theirs) == sorted(c.file for c in CASES)
    for case in CASES:
        got = theirs[case.file]
        if case.file not in PYPROFIBUS_READS_OTHERWISE:
            ours = {"cfg": case.cfg.hex(), "user_prm": case.user_prm.hex()}
            assert got == ours, f"{case.file}: pyprofibus {got}, ours {ours}"
            continue
        expected, why = PYPROFIBUS_READS_OTHERWISE[case.file]
        if "error" in expected:
            assert expected["error"] in got.get("error", ""), f"{case.file} ({why}): {got}"
            continue
        assert got == expected, f"{case.file} ({why}): pyprofibus {got}"
        assert got["cfg"] == case.cfg.hex()  # the configuration bytes agree all the same
        assert got["user_prm"] != case.user_prm.hex()


def test_the_differences_are_explained_for_files_of_the_corpus() -> None:
    files = {c.file for c in CASES}
    assert set(PYPROFIBUS_READS_OTHERWISE) <= files
    assert all(why for _, why in PYPROFIBUS_READS_OTHERWISE.values())


def test_without_pypi_the_comparison_is_skipped_saying_why(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    def fail(where: Path) -> Path:
        raise bench.Skipped("pip install --quiet pyprofibus==1.13 failed (1): no network")

    monkeypatch.setattr(bench, "install_pyprofibus", fail)
    with pytest.raises(pytest.skip.Exception, match=r"needs PyPI.*no network"):
        venv_python(tmp_path)
