"""The command line as an operator uses it, against gateway processes (real Zenoh, loopback):
``cmd`` for every command field, ``watch --once`` naming what is missing, ``watch`` saying
the gateway is gone, ``--json``; and what the parser says of itself (help with defaults,
completion, man page)."""

from __future__ import annotations

import argparse
import json
import queue
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from gateway.cli.docs import bash_completion, man_page, zsh_completion
from gateway.cli.parser import DefaultsFormatter, build_parser, walk
from gateway.cli.tools import ACTIONS
from gateway.model import COMMAND_FIELDS
from tests.support.net import zenoh_endpoint
from tests.support.timing import scaled
from tests.zenoh.conftest import PREFIX, GatewayProcess, start_gateway

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def gw(tmp_path_factory: pytest.TempPathFactory) -> Iterator[GatewayProcess]:
    gateway = start_gateway(tmp_path_factory.mktemp("ops"))
    yield gateway
    assert gateway.stop() == 0, "".join(gateway.log)


def tool(gw_endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "gateway", args[0], "--connect", gw_endpoint, "--prefix", PREFIX]
    return subprocess.run(
        [*argv, *args[1:]], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )


# ------------------------------------------------------------------ cmd


def test_cmd_covers_every_field_of_the_command_model() -> None:
    sent: dict[str, set[object]] = {}
    for command in ACTIONS.values():
        for name, value in command.items():
            sent.setdefault(name, set()).add(value)
    given = set(sent) | {"speed_rpm", "speed_pct"}  # --speed-rpm / --speed-pct
    assert given == set(COMMAND_FIELDS)
    for name in ("run", "quick_stop", "coast_stop", "jog", "remote"):
        assert sent[name] == {True, False}, name  # given and released
    assert sent["direction"] == {"forward", "reverse"}


def test_cmd_prints_the_state_that_results(gw: GatewayProcess) -> None:
    run = tool(gw.endpoint, "cmd", "d1", "run", "--speed-rpm", "300")
    assert run.returncode == 0, run.stderr
    first, state = run.stdout.splitlines()
    assert first == 'd1: accepted {"run": true, "speed_rpm": 300.0}'
    assert state.startswith("d1: online ") and (" running " in state or " starting " in state)
    quick = tool(gw.endpoint, "cmd", "d1", "quick-stop", "--json")
    assert quick.returncode == 0, quick.stderr
    doc = json.loads(quick.stdout)
    assert doc["accepted"] and doc["followed"] and doc["command"] == {"quick_stop": True}
    assert doc["state"]["status"] in ("stopping", "ready")
    refused = tool(gw.endpoint, "cmd", "d1", "run")  # latched in quick stop: rule 1
    assert refused.returncode == 1 and "refused" in refused.stderr
    release = tool(gw.endpoint, "cmd", "d1", "quick-stop-release")
    assert release.returncode == 0, release.stderr
    for action in ("coast", "coast-release", "reset", "remote", "forward", "reverse"):
        done = tool(gw.endpoint, "cmd", "d1", action)
        assert done.returncode == 0, (action, done.stderr)


def test_cmd_says_why_nothing_happened(gw: GatewayProcess) -> None:
    """The fake drive stays in remote whatever it is told: accepted, not followed, exit 1."""
    local = tool(gw.endpoint, "cmd", "d2", "local", "--wait", str(scaled(1.0)))
    assert local.returncode == 1
    assert local.stdout.startswith('d2: accepted {"remote": false}')
    assert "accepted, but not out of remote: it did not within" in local.stderr
    assert tool(gw.endpoint, "cmd", "d2", "remote").returncode == 0
    jog = tool(gw.endpoint, "cmd", "soft", "jog")  # the soft starter has no jog
    assert jog.returncode == 1 and "refused: " in jog.stderr


# ------------------------------------------------------------------ watch


def test_watch_once_asks_for_every_drive_every_time(gw: GatewayProcess) -> None:
    for _ in range(3):  # it used to leave drives out in 2 of 3 runs
        out = tool(gw.endpoint, "watch", "--once", "--json")
        assert out.returncode == 0, out.stderr
        doc = json.loads(out.stdout)
        assert [d["id"] for d in doc["drives"]] == ["d1", "d2", "soft"]
        assert doc["problems"] == []


def test_watch_once_names_a_missing_drive(gw: GatewayProcess) -> None:
    out = tool(gw.endpoint, "watch", "--once", "d1", "nosuch")
    assert out.returncode == 1
    assert "error: drive nosuch: missing" in out.stderr
    assert "d1" in out.stdout


def test_watch_once_without_a_gateway_says_so() -> None:
    out = tool(zenoh_endpoint(), "watch", "--once")
    assert out.returncode == 3
    assert "no gateway answers at tcp/127.0.0.1:" in out.stderr


def test_watch_says_when_the_gateway_is_gone(tmp_path: Path) -> None:
    gateway = start_gateway(tmp_path)
    argv = [sys.executable, "-m", "gateway", "watch", "--connect", gateway.endpoint]
    watch = subprocess.Popen(
        [*argv, "--prefix", PREFIX], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )
    lines = lines_of(watch)

    def until(text: str) -> None:
        while True:
            line = lines.get(timeout=scaled(30))
            if text in line:
                return

    try:
        until(": serving (seen at ")
        assert gateway.stop() == 0
        until(": GONE at ")
    finally:
        gateway.kill()
        watch.send_signal(signal.SIGINT)
        assert watch.wait(timeout=30) == 0


def test_watch_json_prints_one_json_line_per_state(gw: GatewayProcess) -> None:
    argv = [sys.executable, "-m", "gateway", "watch", "--json", "--connect", gw.endpoint]
    watch = subprocess.Popen(
        [*argv, "--prefix", PREFIX], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )
    lines = lines_of(watch)
    try:
        seen: set[str] = set()
        while seen != {"d1", "d2", "soft"}:
            doc = json.loads(lines.get(timeout=scaled(30)))
            if doc["type"] == "state":
                seen.add(doc["id"])
    finally:
        watch.send_signal(signal.SIGINT)
        assert watch.wait(timeout=30) == 0


def lines_of(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    """The process's stdout lines, read by a thread (a test waits on them with a bound)."""
    lines: queue.Queue[str] = queue.Queue()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)

    threading.Thread(target=read, daemon=True).start()
    return lines


# ------------------------------------------------------------------ what the parser says


class _Declares:
    """A session whose second subscriber's declaration is where Ctrl-C lands."""

    def __init__(self) -> None:
        self.declared: list[_Declares] = []
        self.undeclared = 0

    def declare_subscriber(self, *_: object, **__: object) -> _Declares:
        if self.declared:
            raise KeyboardInterrupt
        self.declared.append(self)
        return self

    def undeclare(self) -> None:
        self.undeclared += 1


def test_watch_ends_well_on_ctrl_c_while_it_declares(monkeypatch: pytest.MonkeyPatch) -> None:
    """The first states print from the first subscriber while the others are declared: a
    Ctrl-C then (a loaded machine's run of the test above) ends the watch as any other,
    with what was declared undeclared."""
    import contextlib

    from gateway.cli import tools

    fake = _Declares()
    monkeypatch.setattr(tools, "session", lambda _endpoint: contextlib.nullcontext(fake))
    args = argparse.Namespace(prefix=PREFIX, json=True, connect="tcp/127.0.0.1:1")
    try:
        code = tools._watch_live(args)
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C while declaring escaped the watch (drive-gateway exits 130)")
    assert code == tools.EXIT_OK
    assert fake.undeclared == 1


def test_every_argument_has_help_and_shows_its_default() -> None:
    formatter = DefaultsFormatter("drive-gateway")
    for path, parser in walk(build_parser()):
        for action in parser._actions:
            if action.dest in ("help", "version"):
                continue
            if isinstance(action, argparse._SubParsersAction):
                for choice in action._choices_actions:  # each subcommand's one-line help
                    assert choice.help, (path, choice.dest)
                continue
            assert action.help, (path, action.option_strings or action.dest)
            if action.option_strings and action.default not in (None, False, []):
                shown = formatter._get_help_string(action) or ""
                assert "default" in shown, (path, action.option_strings)


def test_help_shows_defaults() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "gateway", "params", "backup", "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout
    out = " ".join(out.split())
    assert "(default: tcp/127.0.0.1:7447)" in out and "(default: demo)" in out


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_bash_completion_completes_commands_options_and_choices(tmp_path: Path) -> None:
    script = tmp_path / "drive-gateway.bash"
    script.write_text(bash_completion(build_parser()))

    def complete(*words: str) -> list[str]:
        cmd = (
            f"source {script}; COMP_WORDS=(drive-gateway {' '.join(words)}); "
            f"COMP_CWORD={len(words)}; _drive_gateway; printf '%s\\n' \"${{COMPREPLY[@]}}\""
        )
        out = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, check=True)
        return out.stdout.split()

    assert complete("par") == ["param", "params"]
    assert complete("params", "re") == ["restore"]
    assert complete("params", "restore", "--dr") == ["--dry-run"]
    assert complete("cmd", "--prefix", "x", "d1", "coast") == ["coast", "coast-release"]
    assert complete("run", "--log-level", "W") == ["WARNING"]


def test_zsh_completion_is_a_compdef_function() -> None:
    text = zsh_completion(build_parser())
    assert text.startswith("#compdef drive-gateway\n")
    if shutil.which("zsh"):
        subprocess.run(["zsh", "-n"], input=text, text=True, check=True)


@pytest.mark.skipif(shutil.which("groff") is None, reason="no groff")
def test_the_man_page_renders_every_command() -> None:
    page = man_page(build_parser())
    out = subprocess.run(
        ["groff", "-man", "-Tutf8", "-P", "-cbou"],
        input=page,
        capture_output=True,
        text=True,
        check=True,
    )
    assert "error" not in out.stderr.lower()
    for command in ("params backup", "params restore", "cmd", "watch", "check-config"):
        assert f"drive-gateway {command}" in out.stdout, command
    assert "--dry-run" in out.stdout.replace("\u2010", "-")
