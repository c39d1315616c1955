"""``profibus scan --toml`` against a simulated drive as ``drive-gateway sim profibus
--slaves 3:cfw11`` starts it (not configured from a GSD: its Get_Cfg is its own default
form), pasted under a bus table: check-config takes it as it is."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters.profibus.cli import GsdMatch, build_line, parse_spec, stanza
from adapters.profibus.sim.port import SimPort
from gateway.cli import main
from tests.profibus.gsd.test_gsd_line import GSD_DIR
from tests.support.timing import scaled

TOLERANT = ["--latency", f"{scaled(0.05):g}", "--retries", "3"]


@pytest.fixture
def cfw11_path() -> Iterator[str]:
    line = build_line(parse_spec("3:cfw11"))
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


def test_a_pasted_scan_of_the_simulated_cfw11_passes_check_config(
    cfw11_path: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    args = ["profibus", "scan", "--port", cfw11_path, "--from", "2", "--to", "4", *TOLERANT]
    assert main([*args, "--gsd-dir", str(GSD_DIR), "--toml"]) == 0
    stanzas = capsys.readouterr().out
    assert 'module = ""' not in stanzas
    assert 'module = "2 words I/O (P0922 = 1)"  # its I/O sizes; the slave answered F1' in stanzas
    site = tmp_path / "site.toml"
    bus = f'[buses.profibus]\nadapter = "profibus"\nport = "{cfw11_path}"\n\n'
    site.write_text(bus + stanzas)
    assert main(["check-config", str(site)]) == 0, capsys.readouterr()
    assert "station3         CFW-11" in capsys.readouterr().out


def test_a_configuration_no_module_has_leaves_the_choice_named(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """No module of the GSD has the slave's I/O: no ``module = ""`` (a TOML error pasted),
    the modules named in a comment, and check-config names them again."""
    from adapters.profibus.options import load_gsd

    gsd = load_gsd(GSD_DIR / "TEST_CFW11.gsd")
    text = stanza(3, GsdMatch(gsd, None, bytes([0xF7])))
    assert "module =" not in text
    assert '"4 words I/O (P0922 = 3)"' in text and "configuration F7 is no module" in text
    site = tmp_path / "site.toml"
    site.write_text('[buses.profibus]\nadapter = "profibus"\nsimulate = true\n\n' + text)
    assert main(["check-config", str(site)]) == 2
    assert "module: is required with gsd (the modules of" in capsys.readouterr().err
