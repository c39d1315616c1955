"""Drive config keys for the start-up bytes: gsd/module/modules/prm, or explicit cfg,
ident_number and user_prm; check-config says exactly how a module differs from the profile."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from adapters.profibus.adapter import ProfibusAdapter
from adapters.profibus.master.events import SlaveParams
from gateway.cli import main
from gateway.config import Config, parse
from gateway.errors import ConfigError, ConfigErrors

GSD_DIR = Path(__file__).resolve().parents[2] / "data" / "gsd"
CONFIG = str(GSD_DIR / "site.toml")


def config(**drive: Any) -> Config:
    d = {"id": "d", "device": "CFW700", "address": 4, **drive}
    table = {"adapter": "profibus", "simulate": True, "drives": [d]}
    return parse({"buses": {"pb": table}}, CONFIG)


def params(**drive: Any) -> SlaveParams:
    (p,) = ProfibusAdapter(config(**drive).buses[0]).master.slave_params()
    return p


def error(**drive: Any) -> str:
    with pytest.raises((ConfigError, ConfigErrors)) as info:
        config(**drive)
    return str(info.value)


def test_without_a_gsd_the_built_in_guesses_stay() -> None:
    p = params()
    assert (p.ident_number, p.cfg, p.user_prm, p.origin) == (0x0C70, b"\xf1", b"", "")


def test_explicit_cfg_ident_and_user_prm_replace_the_built_in_guesses() -> None:
    p = params(cfg=[0xC0, 0xC1, 0xC1], ident_number=0x0A0B, user_prm=[1, 2])
    assert (p.ident_number, p.cfg, p.user_prm) == (0x0A0B, b"\xc0\xc1\xc1", b"\x01\x02")
    assert p.origin == "cfg and ident_number and user_prm of the drive's config"
    assert params(cfg=[0xF5], words=6).cfg == b"\xf5"  # fact sheet 1.7: 6 words in and out


def test_a_gsd_gives_ident_cfg_and_user_data() -> None:
    p = params(gsd="TEST_CFW700.gsd", module="3 words I/O", words=3)
    assert (p.ident_number, p.cfg) == (0x0C70, b"\xc0\xc2\xc2")
    assert p.user_prm == bytes([0x00, 0x03, 0xE8])  # defaults: ramp stop, 1000
    assert p.origin == f"GSD {GSD_DIR / 'TEST_CFW700.gsd'}, module '3 words I/O'"


@pytest.mark.parametrize(
    ("drive", "message"),
    [
        (
            {"gsd": "TEST_CFW700.gsd", "module": "4 words I/O"},
            "buses.pb.drives[d].module: GSD {dir}/TEST_CFW700.gsd, module '4 words I/O' gives "
            "8 bytes in and 8 out; the drive's profile (words = 2, P0922 (CFW320: P751) = 1) "
            "has 4 in and 4 out",
        ),
        (
            {
                "device": "CFW-11",
                "gsd": "TEST_CFW11.gsd",
                "module": "4 words I/O (P0922 = 3)",
                "data_profile": "profidrive",
                "frame": 20,
            },
            "module '4 words I/O (P0922 = 3)' gives 8 bytes in and 8 out; the drive's profile "
            "(frame 20, 6 words (P0922 = 5)) has 12 in and 12 out",
        ),
        (
            {
                "device": "MCD 600",
                "address": 6,
                "gsd": "TEST_MCD600.gsd",
                "module": "Basic mode",
                "mode": "parameter",
            },
            "module 'Basic mode' gives 2 bytes in and 2 out; the drive's profile "
            "(MCD 600 mode = 'parameter') has 10 in and 7 out",
        ),
        ({"cfg": [0xF3]}, "cfg = [0xF3] gives 8 bytes in and 8 out"),
        ({"cfg": [0x40]}, "buses.pb.drives[d].cfg: not Chk_Cfg identifiers"),
        ({"module": "2 words I/O"}, "buses.pb.drives[d].module: needs gsd"),
        ({"gsd": "TEST_CFW700.gsd"}, "module: is required with gsd (the modules of"),
        (
            {"gsd": "TEST_CFW700.gsd", "module": "2 words I/O", "cfg": [0xF1]},
            "buses.pb.drives[d].cfg: the GSD file gives it",
        ),
        (
            {"gsd": "TEST_CFW700.gsd", "module": "2 words I/O", "prm": {"Test: word limit": 40000}},
            "buses.pb.drives[d].prm.Test: word limit: 40000 is outside its range 0-30000",
        ),
        (
            {"gsd": "none.gsd", "module": "x"},
            "buses.pb.drives[d].gsd: {dir}/none.gsd: does not exist",
        ),
        (
            {"gsd": "TEST_CFW700.gsd", "module": "2 words I/O", "modules": ["x"]},
            "give module (one) or modules (a list), not both",
        ),
    ],
)
def test_config_errors_say_exactly_what_differs(drive: dict[str, Any], message: str) -> None:
    assert message.format(dir=GSD_DIR) in error(**drive)


def test_check_config_reports_the_difference(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    site = tmp_path / "site.toml"
    gsd = GSD_DIR / "TEST_CFW700.gsd"
    site.write_text(
        '[buses.pb]\nadapter = "profibus"\nsimulate = true\n'
        f'[[buses.pb.drives]]\nid = "d"\ndevice = "CFW700"\naddress = 4\n'
        f'gsd = "{gsd}"\nmodule = "4 words I/O"\n'
    )
    assert main(["check-config", str(site)]) == 2
    err = capsys.readouterr().err
    assert "gives 8 bytes in and 8 out; the drive's profile (words = 2" in err


def test_the_lines_baud_rate_and_max_tsdr_must_suit_the_gsd() -> None:
    drive = {"id": "d", "device": "CFW-11", "address": 3, "gsd": "TEST_CFW11.gsd"}
    drive["module"] = "2 words I/O (P0922 = 1)"
    table: dict[str, Any] = {"adapter": "profibus", "simulate": True, "drives": [drive]}
    with pytest.raises((ConfigError, ConfigErrors), match=r"does not support 45450 baud"):
        parse({"buses": {"pb": {**table, "baudrate": 45450}}}, CONFIG)
    with pytest.raises((ConfigError, ConfigErrors), match=r"MaxTsdr = 50 bit times at 12000000"):
        parse({"buses": {"pb": {**table, "baudrate": 12000000, "max_tsdr": 40}}}, CONFIG)
    parse({"buses": {"pb": {**table, "baudrate": 9600}}}, CONFIG)
