"""The profile's config keys and what they put in the slave set-up (guide 3.3, 4.1)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from adapters.mcd600.layout import Mode
from adapters.mcd600.options import Mcd600Options, parse_user_prm, user_prm_data
from adapters.mcd600.profile import Mcd600Profile
from adapters.mcd600.words import MotorSet
from adapters.profibus.contract import PROFILES, load_profile
from gateway.errors import ConfigError, GatewayError
from gateway.model import Device
from gateway.schema import Table
from tests.mcd600.loop import drive_config


def parse(data: dict[str, Any]) -> Mcd600Options:
    table = Table(data, "site.toml", "buses.pb.drives[0]")
    options = Mcd600Profile.parse_options(table, drive_config())
    table.finish()
    return options


def test_defaults() -> None:
    assert parse({}) == Mcd600Options()
    assert Mcd600Options().comm_timeout == 10  # guide 3.3 default


def test_all_keys() -> None:
    options = parse(
        {
            "mode": "parameter",
            "flc_a": 52,
            "motor_set": "secondary",
            "comm_timeout": 0,
            "request_period": 0.5,
            "param_timeout": 1.0,
            "reset_pulse": 0.1,
            "current_x10": True,
            "ident_number": 0x1234,
            "group": 3,
            "sim_params": {"9": 3, "4": 2},
            "sim_time_scale": 10,
        }
    )
    assert options.mode is Mode.PARAMETER
    assert options.flc_a == 52.0
    assert options.motor_set is MotorSet.SECONDARY
    assert options.current_scale == 0.1
    assert options.group_mask == 0b100
    assert options.sim_params == ((4, 2), (9, 3)) and options.sim_time_scale == 10.0


@pytest.mark.parametrize(
    ("data", "key", "reason"),
    [
        ({"mode": "fast"}, "mode", "'fast' is not one of 'basic', 'extended', 'parameter'"),
        ({"comm_timeout": 101}, "comm_timeout", "101 is above the maximum 100"),
        ({"comm_timeout": 2.5}, "comm_timeout", "must be an integer"),
        ({"flc_a": 0}, "flc_a", "below the minimum"),
        ({"motor_set": "third"}, "motor_set", "is not one of"),
        ({"group": 9}, "group", "above the maximum 8"),
        ({"sim_params": 4}, "sim_params", "must be a table"),
        ({"sim_params": {"99": 1}}, "sim_params.99", "not a settable simulated parameter"),
        ({"sim_params": {"12": 1}}, "sim_params.12", "not a settable simulated parameter"),
        ({"sim_params": {"start": 1}}, "sim_params.start", "not a settable simulated"),
        ({"sim_params": {"4": 0}}, "sim_params.4", "0 is below the minimum 1"),
        ({"sim_params": {"4": 1.5}}, "sim_params.4", "must be an integer"),
        ({"sim_time_scale": 0}, "sim_time_scale", "below the minimum"),
    ],
)
def test_errors_name_the_key(data: dict[str, Any], key: str, reason: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse(data)
    assert info.value.key == f"buses.pb.drives[0].{key}"
    assert reason in info.value.reason


def test_unknown_key_is_left_for_finish() -> None:
    with pytest.raises(ConfigError, match="unknown key"):
        parse({"speed": 1})


@pytest.mark.parametrize(
    ("mode", "cfg", "out_len", "in_len"),
    [
        (Mode.BASIC, "F0", 2, 2),
        (Mode.EXTENDED, "F0A093", 3, 6),
        (Mode.PARAMETER, "F0A093B3", 7, 10),
    ],
)
def test_setup_per_mode(mode: Mode, cfg: str, out_len: int, in_len: int) -> None:
    setup = Mcd600Profile(drive_config(mode=mode, comm_timeout=25, group=1)).setup()
    assert setup.cfg == bytes.fromhex(cfg)
    assert (setup.output_len, setup.input_len) == (out_len, in_len)
    assert setup.user_prm == bytes([25])  # user data byte 0: comm timeout in s
    assert setup.dpv1 is False
    assert setup.group == 1
    assert setup.ident_number == Mcd600Options().ident_number


def test_user_prm_parsing() -> None:
    assert user_prm_data(Mcd600Options(comm_timeout=100)) == b"\x64"
    assert parse_user_prm(b"\x00") == 0
    assert parse_user_prm(b"\x65") is None  # 101 s: out of 0-100
    assert parse_user_prm(b"") is None
    assert parse_user_prm(b"\x0a\x00") is None


def test_registered_in_the_profile_table() -> None:
    assert PROFILES[Device.MCD600] == "adapters.mcd600.profile:Mcd600Profile"
    assert load_profile(Device.MCD600) is Mcd600Profile


def test_options_come_from_the_drive_config() -> None:
    cfg = drive_config(mode=Mode.EXTENDED)
    assert Mcd600Profile(cfg).options.mode is Mode.EXTENDED
    assert Mcd600Profile(replace(cfg, options=None)).options == Mcd600Options()
    with pytest.raises(GatewayError, match="options missing"):
        Mcd600Profile(replace(cfg, options={"mode": "basic"}))
