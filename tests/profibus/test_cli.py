"""``drive-gateway profibus scan`` and ``drive-gateway sim profibus``."""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from adapters.profibus.cli import SlaveSpec, build_line, parse_spec, run_sim, scan
from adapters.profibus.codec.fdl import StationType
from adapters.profibus.master.timing import BusParams
from adapters.profibus.sim.echo import EchoSim
from gateway.cli import main
from tests.profibus.support import line_config

ROOT = Path(__file__).resolve().parents[2]
BUS = BusParams.for_baudrate(500000, latency=0.003)


def test_slave_specs() -> None:
    assert parse_spec("5:cfw11") == [SlaveSpec(5, "cfw11")]
    assert parse_spec("3-5:echo:8") == [SlaveSpec(a, "echo", 8) for a in (3, 4, 5)]
    for bad, why in [
        ("5", "is not ADDRESS[-ADDRESS]:KIND[:SIZE]"),
        ("5:cfw08", "is not ADDRESS[-ADDRESS]:KIND[:SIZE]"),
        ("126:echo", "126 is not a station address (0-125)"),
        ("x:echo", "invalid literal"),
        ("5:cfw11:4", "SIZE (1-64) is for echo slaves only"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=re.escape(why)):
            parse_spec(bad)


def test_a_line_from_specs_and_from_a_gateway_config() -> None:
    line = build_line(parse_spec("7:echo:6"), line_config([5, 6], drive={"size": 8}))
    assert sorted(line.slaves) == [5, 6, 7]
    assert line[7].device.expected_cfg() == EchoSim(6).expected_cfg()
    assert line[5].device.expected_cfg() == EchoSim(8).expected_cfg()  # as configured


async def test_scan_finds_the_simulated_slaves() -> None:
    line = build_line(parse_spec("3-4:echo") + parse_spec("40:echo"))
    stop = asyncio.Event()
    announced: asyncio.Future[str] = asyncio.get_running_loop().create_future()
    sim = asyncio.create_task(run_sim("pty", 500000, line, stop, announced.set_result))
    try:
        path = (await announced).split(" on ")[1].split(":")[0]
        found = await scan(path, BUS, range(0, 45))
        assert found == {3: StationType.SLAVE, 4: StationType.SLAVE, 40: StationType.SLAVE}
    finally:
        stop.set()
        await sim


def test_scan_of_a_missing_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profibus", "scan", "--port", "/dev/ttyNOSUCH7"]) == 1
    assert capsys.readouterr().err.startswith("error: /dev/ttyNOSUCH7: ")
    assert main(["profibus", "scan", "--port", "/dev/null", "--from", "9", "--to", "3"]) == 2
    assert "--from 9 is above --to 3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["profibus", "scan", "--port", "/dev/null", "--baud", "250000"])


def test_sim_needs_slaves(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "profibus", "--port", "pty"]) == 2
    assert "no slaves to simulate" in capsys.readouterr().err


def test_the_standalone_simulator_and_the_scan_tool_end_to_end(
    capsys: pytest.CaptureFixture[str],
) -> None:
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "gateway",
            "sim",
            "profibus",
            "--port",
            "pty",
            "--slaves",
            "5:echo",
            "9-10:echo:8",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("simulating 3 slave(s) on /dev/pts/"), first
        path = first.split(" on ")[1].split(":")[0]
        # --rs485 on: kernel RS-485 mode insisted on, which a pty is excused from
        scan_json = ["profibus", "scan", "--port", path, "--to", "12", "--json", "--rs485", "on"]
        assert main(scan_json) == 0
        echo = {"station": "slave", "ident_number": 0xEC00, "master_address": 255}
        assert json.loads(capsys.readouterr().out) == {
            "5": {**echo, "cfg": "B3"},
            "9": {**echo, "cfg": "B7"},
            "10": {**echo, "cfg": "B7"},
        }
        assert main(["profibus", "scan", "--port", path, "--from", "4", "--to", "6"]) == 0
        captured = capsys.readouterr()
        assert captured.out.splitlines() == [
            f"{path}: 1 station(s) answered, addresses 4-6",
            "    5  slave, Ident_Number 0xEC00, configuration B3 (4 bytes in, 4 bytes out)",
        ]
        # progress: plain lines when stderr is not a terminal
        assert captured.err.splitlines() == [
            "scanned 0/3 addresses, 0 station(s) answered",
            "scanned 3/3 addresses, 1 station(s) answered",
        ]
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        if proc.stdout:
            proc.stdout.close()
        if proc.stderr:
            proc.stderr.close()
