"""The wheel and the sdist (``python -m build``), and ``make install`` into a temporary prefix
from that wheel: a clean venv with the runtime dependencies only (from pip's cache or the
index), where ``drive-gateway --version`` and the shipped demo config work; the unit, the
site config, completions and man page; the interpreter the unit's sandbox can read.

``python -m build`` builds the sdist, then the wheel from the sdist: the wheel installed
here is the proof that the sdist holds what a build needs."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from gateway import __version__

ROOT = Path(__file__).resolve().parents[2]
INSTALLER = ROOT / "packaging" / "install.py"


def load_installer() -> ModuleType:
    spec = importlib.util.spec_from_file_location("drive_gateway_install", INSTALLER)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Path]]:
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    (wheel,) = out.glob("*.whl")
    (sdist,) = out.glob("*.tar.gz")
    yield {"wheel": wheel, "sdist": sdist}


DATA = (
    "demo.toml",
    "site.example.toml",
    "drive-gateway.service",
    "zenoh-secure.json5",
    "eds/cfw08-test.eds",
    "eds/cia402-drive.eds",
)


def test_the_wheel_carries_the_run_time_data(dist: dict[str, Path]) -> None:
    names = zipfile.ZipFile(dist["wheel"]).namelist()
    for name in DATA:
        assert any(n.endswith(f".data/data/share/drive-gateway/{name}") for n in names), name
    assert "gateway/py.typed" in names and "adapters/py.typed" in names
    assert not any(n.startswith("tests/") for n in names)
    # the steady ring compiled (decision 0103) where a C compiler is; else Python's alone
    compiled = [n for n in names if n.startswith("adapters/link/_ring.") and n.endswith(".so")]
    assert len(compiled) == (1 if shutil.which("cc") else 0), names


def test_the_sdist_carries_what_a_build_and_an_install_need(dist: dict[str, Path]) -> None:
    with tarfile.open(dist["sdist"]) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    for name in (
        "pyproject.toml",
        "README.md",
        "Makefile",
        "packaging/install.py",
        "docs/operations.md",
        "gateway/cli/__init__.py",
        "adapters/profibus/weg/paramtable.py",
        "setup.py",
        "adapters/link/_ring.c",
        *(f"config/{n}" for n in DATA),
    ):
        assert name in names, name


def test_make_install_into_a_temporary_prefix(dist: dict[str, Path], tmp_path: Path) -> None:
    paths = {
        "PREFIX": tmp_path / "opt" / "drive-gateway",
        "SYSCONFDIR": tmp_path / "etc" / "drive-gateway",
        "UNITDIR": tmp_path / "etc" / "systemd" / "system",
        "BINDIR": tmp_path / "bin",
        "BASHCOMPDIR": tmp_path / "bash-completion",
        "ZSHCOMPDIR": tmp_path / "zsh",
        "MANDIR": tmp_path / "man",
    }
    argv = ["make", "-s", "-C", str(ROOT), "install", f"PYTHON={sys.executable}"]
    argv += [f"{k}={v}" for k, v in paths.items()]
    argv += ["CREATE_USER=no", f"WHEEL={dist['wheel']}"]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=900, check=False)
    out = proc.stdout
    assert proc.returncode == 0, out + proc.stderr

    steps = re.findall(r"^(\d)\. ", out, flags=re.M)
    assert steps == ["1", "2", "3", "4", "5", "6"], out
    nexts = out.split("Next steps", 1)[1]
    order = ["sudoedit", "check-config", "can0", "enable --now", "journalctl", "watch --once"]
    at = [nexts.index(word) for word in order]
    assert at == sorted(at), nexts  # docs/operations.md walks them in this order

    prefix = paths["PREFIX"]
    exe = prefix / "venv" / "bin" / "drive-gateway"
    version = subprocess.run([str(exe), "--version"], capture_output=True, text=True, check=True)
    assert version.stdout.strip() == f"drive-gateway {__version__}"
    assert (paths["BINDIR"] / "drive-gateway").resolve() == exe.resolve()

    # runtime only: none of the dev tools
    py = str(prefix / "venv" / "bin" / "python")
    for module in ("pytest", "mypy", "ruff", "hypothesis"):
        missing = subprocess.run([py, "-c", f"import {module}"], capture_output=True, check=False)
        assert missing.returncode != 0, module
    # the demo config shipped in the wheel is `run`'s default, and checks
    default = subprocess.run(
        [py, "-c", "from gateway.config import DEFAULT_CONFIG as d; print(d, d.is_file())"],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
    ).stdout.split()
    assert default == [str((prefix / "venv/share/drive-gateway/demo.toml").resolve()), "True"]
    check = subprocess.run(
        [str(exe), "check-config", default[0]], capture_output=True, text=True, check=False
    )
    assert check.returncode == 0 and ": ok, 7 drive(s)" in check.stdout, check.stdout

    # the interpreter: one the unit's sandbox (ProtectHome=yes, PrivateTmp=yes) can read
    home = (prefix / "venv" / "pyvenv.cfg").read_text()
    base = re.search(r"^home = (.*)$", home, flags=re.M)
    assert base is not None
    assert not base.group(1).startswith(("/root", "/home", "/run/user")), home
    if os.path.realpath(sys.base_prefix).startswith(("/root", "/home")):
        assert "which the unit's ProtectHome=yes hides from the service" in out
        assert "instead (the unit's sandbox can read it)" in out

    unit = (paths["UNITDIR"] / "drive-gateway.service").read_text()
    assert f"ExecStart={exe} run --config {paths['SYSCONFDIR']}/site.toml" in unit
    assert f"ExecReload={exe} check-config --errors-only {paths['SYSCONFDIR']}/site.toml" in unit
    assert "AmbientCapabilities=CAP_NET_BIND_SERVICE" in unit
    assert (prefix / "doc" / "operations.md").is_file()
    site = paths["SYSCONFDIR"] / "site.toml"
    assert site.is_file() and (site.stat().st_mode & 0o777) == 0o640
    assert (paths["BASHCOMPDIR"] / "drive-gateway").read_text().startswith("# bash completion")
    assert (paths["ZSHCOMPDIR"] / "_drive-gateway").read_text().startswith("#compdef")
    assert (paths["MANDIR"] / "man1" / "drive-gateway.1").read_text().startswith(".TH")
    if shutil.which("systemd-analyze"):
        assert "systemd-analyze verify" in out and ": ok" in out, out
        verify = subprocess.run(
            ["systemd-analyze", "verify", str(paths["UNITDIR"] / "drive-gateway.service")],
            capture_output=True,
            text=True,
            check=False,
        )
        problems = [
            line
            for line in (verify.stdout + verify.stderr).splitlines()
            if "drive-gateway.service" in line
        ]
        assert problems == [], problems


def test_an_interpreter_the_sandbox_hides_is_replaced_or_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    installer = load_installer()
    roots = installer.hidden_roots((ROOT / "config" / "drive-gateway.service").read_text())
    assert roots["/root"] == "ProtectHome=yes" and roots["/tmp"] == "PrivateTmp=yes"
    assert installer.hidden_by("/root/.pyenv/versions/3.11.7/bin/python3.11", roots)
    assert installer.hidden_by("/usr/bin/python3.11", roots) is None
    assert installer.hidden_roots("ProtectHome=read-only\nPrivateTmp=no\n") == {}

    fake = {
        "/root/.pyenv/shims/python3": ((3, 12), ["/root/.pyenv/versions/3.12.1/bin/python3.12"]),
        "/usr/bin/python3.11": ((3, 11), ["/usr/bin/python3.11", "/usr"]),
        "/usr/bin/python3": ((3, 9), ["/usr/bin/python3.9", "/usr"]),
    }
    monkeypatch.setattr(installer, "probe", fake.get)
    monkeypatch.setattr(installer.os.path, "exists", lambda p: p in fake)
    assert installer.choose_python("/root/.pyenv/shims/python3", roots) == "/usr/bin/python3.11"
    del fake["/usr/bin/python3.11"]
    with pytest.raises(installer.InstallError, match="apt install python3 python3-venv"):
        installer.choose_python("/root/.pyenv/shims/python3", roots)
