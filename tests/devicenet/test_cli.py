"""``drive-gateway sim devicenet``."""

from __future__ import annotations

import argparse
import logging
import socket

import pytest

from adapters.devicenet.cli import node_configs, parse_nodes
from gateway.cli import main
from gateway.cli.parser import build_parser


def test_parse_nodes() -> None:
    assert parse_nodes("1,2,5-8") == [1, 2, 5, 6, 7, 8]
    assert parse_nodes("63") == [63]
    assert parse_nodes("1-63") == list(range(1, 64))
    for bad, why in [("64", "0-63"), ("a", "not a MAC ID"), ("3-1", "0-63"), ("1,1", "twice")]:
        with pytest.raises(argparse.ArgumentTypeError, match=why):
            parse_nodes(bad)


def test_arguments_become_node_configs() -> None:
    args = build_parser().parse_args(
        ["sim", "devicenet", "--interface", "virtual", "--channel", "c", "--nodes", "3-4",
         "--assembly", "100", "--p313", "1", "--max-rpm", "3600", "--weg-speed-scale", "16384"]
    )  # fmt: skip
    configs = node_configs(args)
    assert [c.mac for c in configs] == [3, 4]
    assert {(c.p710, c.p313, c.max_rpm, c.weg_speed_scale) for c in configs} == {
        (2, 1, 3600.0, 16384)
    }


def test_runs_for_a_while_on_virtual() -> None:
    argv = ["sim", "devicenet", "--interface", "virtual", "--channel", "cli-test", "--nodes", "1-3"]
    assert main([*argv, "--duration", "0.2", "--log-level", "WARNING"]) == 0


def test_udp_multicast_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["sim", "devicenet", "--interface", "udp_multicast", "--nodes", "1"])
    assert exit_info.value.code == 2
    assert "udp_multicast is not supported" in capsys.readouterr().err


def test_an_interface_that_cannot_open_is_an_error() -> None:
    argv = ["sim", "devicenet", "--interface", "no-such-interface", "--nodes", "1"]
    assert main([*argv, "--duration", "0.2", "--log-level", "ERROR"]) == 2


def test_without_af_can_it_says_what_is_missing_and_what_to_do(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """On a kernel without SocketCAN (these build machines), not a bare
    ``[Errno 97] Address family not supported by protocol``."""
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        pass
    else:
        pytest.skip("this kernel has AF_CAN (the vcan suite covers it)")
    argv = ["sim", "devicenet", "--interface", "socketcan", "--channel", "vcan0", "--nodes", "1"]
    with caplog.at_level(logging.ERROR):
        assert main([*argv, "--duration", "0.2", "--log-level", "ERROR"]) == 2
    text = caplog.text
    assert "[Errno 97]" in text and "no SocketCAN (AF_CAN" in text
    assert "modprobe vcan" in text and "ip link add dev vcan0 type vcan" in text
    assert "--interface virtual" in text
