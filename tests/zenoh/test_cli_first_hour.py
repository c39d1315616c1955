"""The operator tools as a new user types them: ``param``'s options anywhere on the line,
and exit 3 (docs/operations.md, "Command line") when no gateway answers."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gateway.cli.parser import build_parser
from tests.support.net import zenoh_endpoint
from tests.support.timing import scaled

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "argv",
    [
        [
            "param",
            "--json",
            "--connect",
            "tcp/127.0.0.1:7999",
            "--prefix",
            "p",
            "d1",
            "read",
            "100",
        ],
        [
            "param",
            "d1",
            "read",
            "100",
            "--json",
            "--connect",
            "tcp/127.0.0.1:7999",
            "--prefix",
            "p",
        ],
        [
            "param",
            "d1",
            "--json",
            "read",
            "--prefix",
            "p",
            "100",
            "--connect",
            "tcp/127.0.0.1:7999",
        ],
    ],
)
def test_param_takes_its_options_before_or_after_the_drive(argv: list[str]) -> None:
    args = build_parser().parse_args(argv)
    assert (args.drive, args.op, args.number) == ("d1", "read", (100, None))
    assert (args.json, args.connect, args.prefix) == (True, "tcp/127.0.0.1:7999", "p")


def test_param_options_absent_after_the_drive_keep_their_defaults() -> None:
    args = build_parser().parse_args(["param", "--prefix", "p", "d1", "write", "100", "20"])
    assert (args.json, args.connect, args.prefix) == (False, "tcp/127.0.0.1:7447", "p")
    assert args.value == 20.0


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "gateway", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=scaled(60),
        check=False,
    )


@pytest.mark.parametrize(
    "args",
    [("param", "d1", "read", "100"), ("param", "d1", "write", "100", "20"), ("health",)],
)
def test_no_gateway_is_exit_3(args: tuple[str, ...]) -> None:
    out = run(*args, "--connect", zenoh_endpoint(), "--prefix", "nobody")
    assert out.returncode == 3, out.stderr
    assert "no gateway answers at tcp/127.0.0.1:" in out.stderr


def test_health_help_says_one_thing_of_json() -> None:
    out = run("health", "--help")
    text = " ".join(out.stdout.split())
    assert "print JSON instead of text" not in text
    assert "always printed as JSON" in text and "3 no gateway answers" in text
