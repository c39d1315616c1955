from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gateway import __version__
from gateway.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"drive-gateway {__version__}"


def test_python_dash_m_gateway_and_console_script_agree() -> None:
    exe = Path(sys.executable).parent / "drive-gateway"
    for argv in ([sys.executable, "-m", "gateway", "--version"], [str(exe), "--version"]):
        out = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, check=True, timeout=60)
        assert out.stdout.strip() == f"drive-gateway {__version__}"


def test_no_command_prints_help_and_fails(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert "run" in capsys.readouterr().err


def test_run_defaults_to_the_demo_config() -> None:
    from gateway.cli import build_parser

    args = build_parser().parse_args(["run"])
    assert args.config.endswith("config/demo.toml")
