"""The operator tools against a running gateway process (real Zenoh, loopback)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.zenoh.conftest import PREFIX, GatewayProcess, start_gateway

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def gw(tmp_path_factory: pytest.TempPathFactory) -> Iterator[GatewayProcess]:
    gateway = start_gateway(tmp_path_factory.mktemp("tools"))
    yield gateway
    assert gateway.stop() == 0, "".join(gateway.log)


def tool(gw: GatewayProcess, *args: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "gateway", args[0], "--connect", gw.endpoint, "--prefix", PREFIX]
    return subprocess.run(
        [*argv, *args[1:]], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )


def test_health(gw: GatewayProcess) -> None:
    out = tool(gw, "health")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["drives"] == 3
    assert sorted(doc["buses"]["line1"]["live"]) == ["d1", "d2", "soft"]


def test_watch_once_lists_every_drive(gw: GatewayProcess) -> None:
    out = tool(gw, "watch", "--once")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].split()[:4] == ["id", "device", "comm", "status"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert set(rows) == {"d1", "d2", "soft"}
    assert "online" in rows["d1"] and "MCD 600" in rows["soft"]


def test_cmd_accepted_and_refused(gw: GatewayProcess) -> None:
    ok = tool(gw, "cmd", "d2", "run", "--speed-rpm", "300")
    assert ok.returncode == 0, ok.stderr
    assert "accepted" in ok.stdout
    stop = tool(gw, "cmd", "d2", "stop")
    assert stop.returncode == 0, stop.stderr
    refused = tool(gw, "cmd", "soft", "speed", "--speed-rpm", "100")
    assert refused.returncode == 1
    assert "refused" in refused.stderr and "no speed" in refused.stderr


def test_param_read_write_and_refusal(gw: GatewayProcess) -> None:
    wrote = tool(gw, "param", "d1", "write", "100", "85")
    assert wrote.returncode == 0, wrote.stderr
    read = tool(gw, "param", "d1", "read", "100")
    assert read.returncode == 0, read.stderr
    assert read.stdout.strip() == "P0100 Acceleration time = 8.5 s"  # the drive's table
    named = tool(gw, "param", "d1", "read", "P0100")  # as the manuals write it
    assert named.returncode == 0, named.stderr
    assert named.stdout.strip() == "P0100 Acceleration time = 8.5 s"
    unnamed = tool(gw, "param", "d1", "read", "p134")  # not in the table: the raw value
    assert unnamed.returncode == 0, unnamed.stderr
    assert unnamed.stdout.strip() == "P134 = 1800"
    bad = tool(gw, "param", "d1", "read", "X100")
    assert (
        bad.returncode == 2 and "is not a parameter: 100, P0100, 0x6083 or 0x2000:1" in bad.stderr
    )
    out_of_range = tool(gw, "param", "d1", "write", "101", "99999")
    assert out_of_range.returncode == 1
    assert "parameter value out of limits" in out_of_range.stderr
    not_allowed = tool(gw, "param", "d1", "write", "134", "1000")
    assert not_allowed.returncode == 1
    assert "writable_params" in not_allowed.stderr


def test_no_gateway_is_a_clear_error(tmp_path: Path) -> None:
    from tests.support.net import zenoh_endpoint

    argv = [sys.executable, "-m", "gateway", "health", "--connect", zenoh_endpoint()]
    out = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 3  # no gateway answers (docs/operations.md: exit 3)
    assert "no gateway answers" in out.stderr


def test_watch_says_why_a_drive_left() -> None:
    """The last comm event with a reason (not the hub's bare transitions) is in the row."""
    from gateway.cli.tools import COLUMNS, Board

    board = Board()
    board.on_state({"id": "cfw11", "device": "CFW-11", "comm": "online", "status": "ready"})
    reason = "left data exchange: no reply to Data_Exchange after 3 tries (waited 60.4 ms for each)"
    board.on_event({"drive": "cfw11", "kind": "comm", "text": reason, "reason": "..."})
    board.on_event({"drive": "cfw11", "kind": "comm", "text": "comm offline -> connecting"})
    board.on_event({"drive": "cfw11", "kind": "fault", "text": "F070 overcurrent"})
    (row,) = board.rows(1e9)
    assert COLUMNS[-1] == "last comm event"
    assert row[-1].startswith(reason + " (")
