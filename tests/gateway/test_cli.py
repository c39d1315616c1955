from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from gateway import __version__
from gateway.cli import main
from tests.support.net import zenoh_endpoint
from tests.zenoh.client import client_config

PREFIX = "clitest"

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


def test_run_defaults_to_the_demo_config_and_says_so_loudly(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """No --config: the simulated demo runs, with a banner on stderr and a WARNING in the
    log at start (a new user must not take it for a real line)."""
    import logging

    import gateway.runtime.daemon
    from gateway.cli import run as run_cli
    from gateway.config import shipped_file

    ran: list[str] = []

    def fake_run(config: object) -> int:
        ran.append(str(getattr(config, "path", "")))
        return 0

    def leave(status: int) -> None:
        raise SystemExit(status)

    monkeypatch.setattr(gateway.runtime.daemon, "run", fake_run)
    monkeypatch.setattr(run_cli, "_leave_process", leave)
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    try:
        with pytest.raises(SystemExit):
            main(["run"])
        err = capsys.readouterr().err
        with pytest.raises(SystemExit):
            main(["run", "--config", str(shipped_file("demo.toml"))])
        quiet = capsys.readouterr().err
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)
        run_cli.set_library_level("WARNING")
    assert len(ran) == 2
    banner, *rest = err.splitlines()
    assert banner.startswith("*** no --config given: running the SIMULATED demo (")
    assert "config/demo.toml" in banner
    assert any("WARNING gateway.cli: no --config given" in line for line in rest), err
    assert "SIMULATED" not in quiet  # a config given, even the demo's: no banner


# ------------------------------------------------------------------ cmd against a gateway


class FakeGateway:
    """A Zenoh peer listening on a loopback endpoint with a command queryable that answers
    as told and records each query's source info."""

    def __init__(self, answer: tuple[bool, dict[str, object]]) -> None:
        self.endpoint = zenoh_endpoint()
        self.answer = answer
        self.sources: list[tuple[str, int] | None] = []
        self.payloads: list[object] = []
        self.session = zenoh.open(client_config(self.endpoint, listen=True))
        self.queryable = self.session.declare_queryable(f"{PREFIX}/drives/d1/command", self._on)

    def _on(self, query: zenoh.Query) -> None:
        info = query.source_info
        if info is None:
            self.sources.append(None)
        else:
            self.sources.append((str(info.source_id.zid), int(info.source_sn)))
        self.payloads.append(json.loads(query.payload.to_string()) if query.payload else None)
        ok, body = self.answer
        if ok:
            query.reply(query.key_expr, json.dumps(body))
        else:
            query.reply_err(json.dumps(body))

    def close(self) -> None:
        self.queryable.undeclare()
        self.session.close()


@pytest.fixture
def fake_gateway() -> Iterator[Callable[[bool, dict[str, object]], FakeGateway]]:
    made: list[FakeGateway] = []

    def make(ok: bool, body: dict[str, object]) -> FakeGateway:
        made.append(FakeGateway((ok, body)))
        return made[-1]

    yield make
    for gw in made:
        gw.close()


REASON = "drive d1 is faulted (F071): a run needs the fault cleared first"


@pytest.mark.parametrize(
    ("ok", "body"),
    [
        (True, {"accepted": False, "error": REASON}),  # the hub's refusal
        (False, {"error": REASON}),  # an error reply (e.g. from the front end)
    ],
)
def test_cmd_prints_the_refusal_reason_and_fails(
    fake_gateway: Callable[[bool, dict[str, object]], FakeGateway],
    capsys: pytest.CaptureFixture[str],
    ok: bool,
    body: dict[str, object],
) -> None:
    gw = fake_gateway(ok, body)
    code = main(["cmd", "--connect", gw.endpoint, "--prefix", PREFIX, "d1", "run"])
    out = capsys.readouterr()
    assert code == 1
    assert out.err.strip() == f"d1: refused: {REASON}"
    assert out.out == ""
    assert gw.payloads == [{"run": True}]


def test_cmd_accepted_exits_0_and_carries_the_session_source_info(
    fake_gateway: Callable[[bool, dict[str, object]], FakeGateway],
    capsys: pytest.CaptureFixture[str],
) -> None:
    gw = fake_gateway(True, {"accepted": True})
    argv = [
        "cmd",
        "--connect",
        gw.endpoint,
        "--prefix",
        PREFIX,
        "d1",
        "speed",
        "--speed-rpm",
        "900",
    ]
    assert main(argv) == 0
    assert capsys.readouterr().out.strip() == 'd1: accepted {"speed_rpm": 900.0}'
    assert main(argv) == 0  # a second run: another session, another id
    assert len(gw.sources) == 2 and None not in gw.sources
    first, second = gw.sources
    assert first is not None and second is not None
    assert first[0] != second[0] != str(gw.session.zid())  # one id per client session


def test_check_config_lists_the_safety_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 32 item 5: a reaction to a lost master switched off is said by check-config."""
    site = tmp_path / "site.toml"
    site.write_text(
        """
[buses.pb]
adapter = "profibus"
simulate = true
watchdog = 0
[[buses.pb.drives]]
id = "pump"
device = "CFW-11"
address = 3
[[buses.pb.drives]]
id = "starter"
device = "MCD 600"
address = 6
comm_timeout = 0
"""
    )
    assert main(["check-config", str(site)]) == 0  # warnings do not fail the check
    out = capsys.readouterr().out
    assert "safety warnings (" in out
    assert "drive pump: watchdog = 0" in out
    assert "drive starter:" in out
