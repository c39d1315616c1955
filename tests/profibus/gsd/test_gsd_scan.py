"""``drive-gateway profibus scan --gsd-dir DIR [--toml]`` against simulators configured from
the test GSD files: each station's Ident_Number from its diagnosis, its GSD and its module,
and a config stanza that loads and reaches data exchange."""

from __future__ import annotations

import asyncio
import io
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters.profibus.cli import Progress, build_line
from adapters.profibus.master.scan import Scanner
from adapters.profibus.master.timing import BusParams
from adapters.profibus.sim.port import SimPort
from gateway.cli import main
from gateway.config import parse
from tests.profibus.gsd.test_gsd_line import CONFIG, DRIVES, GSD_DIR
from tests.support.timing import scaled

# The simulated slaves answer from a thread of this process: on a loaded machine a reply
# came later than the slot time plus 10 ms and a station went unseen (3 of 4 answered).
TOLERANT = ["--latency", f"{scaled(0.05):g}", "--retries", "3"]


@pytest.fixture
def sim_path() -> Iterator[str]:
    """The four GSD-configured simulated drives on a pty, served by a loop in a thread."""
    config = parse(
        {"buses": {"pb": {"adapter": "profibus", "simulate": True, "drives": DRIVES}}}, CONFIG
    )
    line = build_line([], config)
    loop = asyncio.new_event_loop()
    ready = threading.Event()
    stop = asyncio.Event()
    holder: dict[str, Any] = {}

    async def serve() -> None:
        sim, path = SimPort.on_pty(line)
        sim.start()
        holder["path"] = path
        ready.set()
        try:
            await stop.wait()
        finally:
            sim.close()

    thread = threading.Thread(target=lambda: loop.run_until_complete(serve()))
    thread.start()
    try:
        assert ready.wait(10)
        yield str(holder["path"])
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(10)
        loop.close()


def test_scan_matches_each_station_to_its_gsd_and_module(
    sim_path: str, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["profibus", "scan", "--port", sim_path, "--from", "2", "--to", "7", *TOLERANT]
    assert main([*args, "--gsd-dir", str(GSD_DIR)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{sim_path}: 4 station(s) answered, addresses 2-7"
    assert out[1] == (
        "    3  slave, Ident_Number 0x0C11, configuration C0 C3 C3 (8 bytes in, 8 bytes out), "
        f"GSD {GSD_DIR / 'TEST_CFW11.gsd'}, module '4 words I/O (P0922 = 3)'"
    )
    assert out[3].endswith(
        "module 'Control and speed (2 words I/O)', 'Extra word I/O', 'Extra word I/O'"
    )
    assert out[4].startswith("    6  slave, Ident_Number 0x0600, configuration F0 A0 93")


def test_the_toml_stanzas_load_and_reach_data_exchange(
    sim_path: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    args = ["profibus", "scan", "--port", sim_path, "--from", "2", "--to", "7", *TOLERANT]
    assert main([*args, "--gsd-dir", str(GSD_DIR), "--toml"]) == 0
    stanzas = capsys.readouterr().out
    assert 'device = "CFW-11"\naddress = 3\n' in stanzas
    assert 'module = "4 words I/O (P0922 = 3)"\nwords = 4\n' in stanzas
    assert (
        'modules = ["Control and speed (2 words I/O)", "Extra word I/O", "Extra word I/O"]\nwords = 4'
        in stanzas
    )
    assert 'module = "Extended mode"\nmode = "extended"\n' in stanzas
    site = tmp_path / "site.toml"
    site.write_text('[buses.profibus]\nadapter = "profibus"\nsimulate = true\n\n' + stanzas)
    assert main(["check-config", str(site)]) == 0
    assert "4 drive(s)" in capsys.readouterr().out


def test_toml_needs_a_gsd_dir(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profibus", "scan", "--port", "/dev/null", "--toml"]) == 2
    assert "--toml needs --gsd-dir" in capsys.readouterr().err


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_rewrites_one_line_on_a_terminal_and_prints_plain_lines_otherwise() -> None:
    scanner = Scanner(BusParams.for_baudrate(500000), range(0, 33))
    tty, plain = _Tty(), io.StringIO()
    show_tty, show_plain = Progress(tty), Progress(plain)
    for n in range(scanner.total + 1):
        scanner.probed = n
        show_tty(scanner)
        show_plain(scanner)
    assert tty.getvalue().count("\r") == 33 and tty.getvalue().endswith("answered\n")
    assert plain.getvalue().splitlines() == [
        "scanned 0/32 addresses, 0 station(s) answered",
        "scanned 16/32 addresses, 0 station(s) answered",
        "scanned 32/32 addresses, 0 station(s) answered",
    ]
