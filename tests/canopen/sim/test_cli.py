"""``drive-gateway sim canopen``."""

from __future__ import annotations

import logging
import socket
from pathlib import Path

import pytest

from adapters.canopen.cli import node_configs
from adapters.canopen.sim import BootState
from gateway.cli import main
from gateway.cli.parser import build_parser


def test_arguments_become_node_configs() -> None:
    args = build_parser().parse_args(
        ["sim", "canopen", "--interface", "virtual", "--channel", "c", "--node", "5",
         "--node", "0x7f", "--max-rpm", "3600", "--heartbeat-ms", "50", "--abort-option", "3",
         "--operational"]
    )  # fmt: skip
    configs = node_configs(args)
    assert [c.node_id for c in configs] == [5, 127]
    assert {
        (c.max_rpm, c.heartbeat_ms, c.abort_connection_option, c.boot_state) for c in configs
    } == {(3600.0, 50, 3, BootState.OPERATIONAL)}
    assert configs[0].eds.name == "cia402-drive.eds"


def test_runs_for_a_while_on_virtual() -> None:
    argv = ["sim", "canopen", "--interface", "virtual", "--channel", "cli-co", "--node", "1"]
    assert main([*argv, "--node", "2", "--duration", "0.2", "--log-level", "WARNING"]) == 0


@pytest.mark.parametrize(
    ("argv", "why"),
    [
        (["--interface", "udp_multicast", "--node", "1"], "udp_multicast is not supported"),
        (["--node", "0"], "node ids are 1-127"),
        (["--node", "x"], "not a node id"),
    ],
)
def test_bad_arguments(argv: list[str], why: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["sim", "canopen", *argv])
    assert exit_info.value.code == 2
    assert why in capsys.readouterr().err


def test_an_eds_that_does_not_parse_names_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "broken.eds"
    bad.write_text("[1000]\nDataType=0x0007\n")
    with pytest.raises(SystemExit):
        main(["sim", "canopen", "--node", "1", "--eds", str(bad)])
    err = capsys.readouterr().err
    assert "broken.eds" in err and "not a readable EDS" in err


def test_a_node_given_twice_is_an_error(caplog: pytest.LogCaptureFixture) -> None:
    argv = ["sim", "canopen", "--interface", "virtual", "--channel", "c2", "--node", "3"]
    with caplog.at_level(logging.ERROR):
        assert main([*argv, "--node", "3", "--duration", "0.2"]) == 2
    assert "given twice" in caplog.text


def test_an_interface_that_cannot_open_is_an_error() -> None:
    argv = ["sim", "canopen", "--interface", "no-such-interface", "--node", "1"]
    assert main([*argv, "--duration", "0.2", "--log-level", "ERROR"]) == 2


def test_without_af_can_it_says_what_to_do(caplog: pytest.LogCaptureFixture) -> None:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        pass
    else:
        pytest.skip("this kernel has AF_CAN (the vcan suite covers it)")
    argv = ["sim", "canopen", "--interface", "socketcan", "--channel", "vcan0", "--node", "1"]
    with caplog.at_level(logging.ERROR):
        assert main([*argv, "--duration", "0.2", "--log-level", "ERROR"]) == 2
    assert "no SocketCAN (AF_CAN" in caplog.text and "--interface virtual" in caplog.text
