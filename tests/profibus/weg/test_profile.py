"""The WEG profile on its own: options, set-up, output words and input words."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from adapters.profibus.contract import (
    PROFILES,
    DpProfile,
    SimDevice,
    load_profile,
)
from adapters.profibus.weg.cfw11 import Cfw11Profile
from adapters.profibus.weg.cfw320 import Cfw320Profile
from adapters.profibus.weg.cfw700 import Cfw700Profile
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim
from adapters.profibus.weg.spec import DataProfile
from gateway.errors import ConfigError, FrameDecodeError
from gateway.model import DesiredCommand, Device, Direction, DriveStatus
from gateway.schema import Table
from tests.profibus.weg.helpers import Loop, drive, profile

SYNC = WegOptions(sync_rpm=1800.0)


def words(*values: int) -> bytes:
    return struct.pack(f">{len(values)}H", *values)


def out(p: WegProfile, now: float = 0.0, **desired: Any) -> tuple[int, ...]:
    data = p.outputs(DesiredCommand(**desired), now)
    return struct.unpack(f">{len(data) // 2}H", data)


# ----------------------------------------------------------------- registry and options


def test_classes_meet_the_contract() -> None:
    # checked by mypy: the classes satisfy the protocols of adapters/profibus/contract.py
    # (not ProfileFactory: mypy never matches its ClassVar against a class object)
    profiles: list[DpProfile] = [
        Cfw11Profile(drive(Device.CFW11)),
        Cfw700Profile(drive(Device.CFW700)),
        Cfw320Profile(drive(Device.CFW320)),
    ]
    sims: list[SimDevice] = [Cfw11Sim(), Cfw700Sim(), Cfw320Sim()]
    assert [p.device for p in profiles] == [Device.CFW11, Device.CFW700, Device.CFW320]
    assert [s.ident_number for s in sims] == [0x0C11, 0x0C70, 0x0C32]


def test_profiles_are_registered() -> None:
    assert load_profile(Device.CFW11) is Cfw11Profile
    assert load_profile(Device.CFW700) is Cfw700Profile
    assert load_profile(Device.CFW320) is Cfw320Profile
    assert set(PROFILES) >= {Device.CFW11, Device.CFW700, Device.CFW320}


def parse(cls: type[WegProfile], **data: Any) -> WegOptions:
    table = Table(data, "site.toml", "buses.pb.drives[0]")
    options = cls.parse_options(table, drive(cls.device))
    assert table.unread() == []
    return options


def test_options_defaults_are_the_factory_settings() -> None:
    assert parse(Cfw11Profile) == WegOptions()
    assert WegOptions().words == 2  # P0922 = 1
    assert WegOptions().data_profile is DataProfile.MANUFACTURER  # P0741 = 1


def test_options_full() -> None:
    o = parse(
        Cfw11Profile,
        words=5,
        words_in=[3, 49],
        words_out=[100, 101],
        out_values=[50, 50],
        param_record=48,
        startup_params={"P0313": 1, "220": 10},
        sync_rpm=1800,
    )
    assert o.mapped_in() == (3, 49, 0)
    assert o.mapped_out() == (100, 101, 0)
    assert o.startup_params == ((313, 1), (220, 10))
    assert o.param_record == 48
    frame20 = parse(Cfw11Profile, data_profile="profidrive", frame=20)
    assert (frame20.words, frame20.words_in) == (6, (760, 761, 762, 763))


@pytest.mark.parametrize(
    ("cls", "data", "message"),
    [
        (Cfw320Profile, {"data_profile": "profidrive"}, "has no PROFIdrive profile"),
        (Cfw700Profile, {"data_profile": "profidrive", "frame": 20}, "not a CFW700 frame"),
        (Cfw11Profile, {"frame": 20}, "data_profile = profidrive"),
        (Cfw11Profile, {"data_profile": "profidrive", "frame": 20, "words": 4}, "takes 6"),
        (Cfw11Profile, {"data_profile": "profidrive", "frame": 20, "words_out": [100]}, "P0750"),
        (Cfw320Profile, {"words": 7}, "above the maximum 6"),
        (Cfw11Profile, {"words": 11}, "above the maximum 10"),
        (Cfw11Profile, {"words": 3, "words_in": [3, 4]}, "2 entries for words 3..3"),
        (Cfw11Profile, {"words": 3, "words_out": [100]}, "one raw value per output word"),
        (Cfw11Profile, {"words_in": [1200]}, "above the maximum 1199"),
        (Cfw11Profile, {"param_record": 49}, "not a record"),
        (Cfw11Profile, {"startup_params": {"X1": 1}}, "is not a parameter number"),
        (Cfw11Profile, {"startup_params": {"P0313": 70000}}, "above the maximum"),
        (Cfw11Profile, {"startup_params": {"P0313": 1, "313": 2}}, "twice"),
        (Cfw11Profile, {"sync_rpm": 0}, "below the minimum"),
    ],
)
def test_option_errors_name_the_key(
    cls: type[WegProfile], data: dict[str, Any], message: str
) -> None:
    with pytest.raises(ConfigError, match=message) as err:
        parse(cls, **data)
    assert err.value.file == "site.toml"
    assert err.value.key.startswith("buses.pb.drives[0].")


# ----------------------------------------------------------------- set-up and capabilities


def test_setup_is_one_consistent_word_identifier() -> None:
    s = profile(Device.CFW11).setup()
    assert s.cfg == bytes([0xF1])  # telegram 1: 2 words in and out (fact sheet 1.7)
    assert (s.input_len, s.output_len, s.user_prm, s.dpv1) == (4, 4, b"", True)
    assert s.ident_number == 0x0C11
    ten = profile(Device.CFW700, WegOptions(words=10, ident_number=0x1234)).setup()
    assert (ten.cfg, ten.ident_number, ten.input_len) == (bytes([0xF9]), 0x1234, 20)


def test_capabilities() -> None:
    assert profile(Device.CFW11).capabilities().speed_scale is None  # not connected yet
    caps = profile(Device.CFW11, SYNC).capabilities()
    assert caps.unsupported == {}
    assert caps.speed_scale is not None
    assert caps.speed_scale.base_rpm == 1800.0
    assert caps.speed_scale.max_pct == pytest.approx(400.0, abs=0.02)
    assert caps.speed_scale.label == "8192 = 1800 rpm synchronous (configured)"
    cfw320_caps = profile(Device.CFW320).capabilities()
    # issue 32 item 4: never refused, a ramp stop instead (P684 bit 6 reserved, Table 4.3)
    assert cfw320_caps.unsupported == {}
    assert cfw320_caps.stop_substitutes == {"quick_stop": "run"}
    pdrive = profile(Device.CFW700, WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1500))
    scale = pdrive.capabilities().speed_scale
    assert scale is not None
    assert (scale.base_rpm, scale.max_pct) == (1500.0, 100.0)
    # alarm texts for the hub's events: each model's own manual
    assert caps.alarm_texts[140] == "Profibus DP module access error"
    assert cfw320_caps.alarm_texts == {
        138: "Profibus DP interface in clear mode",
        139: "Offline Profibus DP interface",
    }


# ----------------------------------------------------------------- outputs


def test_run_forward_900_rpm() -> None:
    # Table 3.3: run + general enable + bit 2 + remote; P0685 example: 900 rpm -> 4096
    assert out(profile(Device.CFW11, SYNC), run=True, speed_rpm=900.0) == (0x0017, 4096)


def test_reverse_is_bit_2_cleared_with_a_positive_reference() -> None:
    # "Bit 2 = 0 e P0685 > 0: referência para o sentido reverso"
    p = profile(Device.CFW700, SYNC)
    assert out(p, run=True, speed_rpm=900.0, direction=Direction.REVERSE) == (0x0013, 4096)
    assert out(p, run=True, speed_pct=50.0) == (0x0017, 4096)


def test_stop_coast_quick_stop_local() -> None:
    p = profile(Device.CFW11, SYNC)
    assert out(p, run=False)[0] == 0x0016  # ramp stop keeps general enable
    # coast: general enable off, and run off (issue 17 item 4: test_quick_stop.py)
    assert out(p, run=True, coast_stop=True)[0] == 0x0014
    assert out(p, run=True, quick_stop=True)[0] == 0x0056  # bit 6 with run off
    assert out(p, run=False)[0] == 0x0016  # run seen off after the stop: run allowed again
    assert out(p, run=True, remote=False)[0] == 0x0007  # bit 4 = 0: local
    assert out(p, jog=True)[0] == 0x001E
    c = profile(Device.CFW320, SYNC)
    assert out(c, run=True, quick_stop=True)[0] == 0x0016  # CFW320: bit 6 reserved


def test_no_speed_scale_sends_zero_reference() -> None:
    assert out(profile(Device.CFW11), run=True, speed_rpm=900.0) == (0x0017, 0)


def test_fault_reset_is_one_pulse_per_request() -> None:
    p = profile(Device.CFW11, SYNC)
    bit7 = 0x0080
    assert not out(p, 0.0, fault_reset_seq=0)[0] & bit7  # first telegram: adopt the counter
    assert out(p, 1.0, fault_reset_seq=1)[0] & bit7
    assert out(p, 1.05, fault_reset_seq=1)[0] & bit7  # held for reset_pulse (0.1 s)
    assert not out(p, 1.11, fault_reset_seq=1)[0] & bit7
    assert not any(out(p, 1.2 + i, fault_reset_seq=1)[0] & bit7 for i in range(5))
    assert out(p, 9.0, fault_reset_seq=2)[0] & bit7  # the next request: the next pulse


def test_a_reset_is_not_replayed_after_a_communication_loss() -> None:
    p = profile(Device.CFW11, WegOptions(reset_pulse=0.0))
    out(p, 0.0, fault_reset_seq=3)
    p.on_comm_lost()
    assert not out(p, 1.0, fault_reset_seq=4)[0] & 0x80
    assert out(p, 2.0, fault_reset_seq=5)[0] & 0x80
    assert not out(p, 2.01, fault_reset_seq=5)[0] & 0x80  # one telegram when reset_pulse = 0


async def test_output_words_carry_their_parameters_values() -> None:
    options = WegOptions(words=4, words_out=(100, 101), out_values=(50, 60))
    p = profile(Device.CFW11, options)
    assert out(p)[2:] == (50, 60)

    class Ok:
        async def write_record(self, slot: int, index: int, data: bytes) -> None:
            pass

        async def read_record(self, slot: int, index: int, length: int) -> bytes:
            return bytes([1, 2, 0, 1])

    await p.write_param(Ok(), 101, 0, 85)
    assert out(p)[2:] == (50, 85)


def test_profidrive_outputs_walk_from_the_last_status() -> None:
    p = profile(Device.CFW11, WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1800))
    assert out(p, run=True, speed_rpm=900.0) == (0x045E, 0x2000)  # unknown: ON = 0 first
    p.inputs(words(0x0040, 0), 0.0)  # switching on inhibited
    assert out(p, run=True, speed_rpm=900.0)[0] == 0x045E
    p.inputs(words(0x0231, 0), 0.0)  # ready to switch on
    assert out(p, run=True, speed_rpm=900.0, direction=Direction.REVERSE) == (0x045F, 0xE000)
    p.inputs(words(0x0008, 0), 0.0)  # fault
    assert out(p, 1.0, run=True)[0] == 0x045E
    assert out(p, 2.0, fault_reset_seq=1)[0] == 0x04DE  # 04FEh with reserved bit 5 cleared
    assert out(p, 2.0, coast_stop=True)[0] & 0x0002 == 0
    assert out(p, 2.0, quick_stop=True)[0] & 0x0004 == 0


# ----------------------------------------------------------------- inputs


def test_input_length_is_checked() -> None:
    with pytest.raises(FrameDecodeError):
        profile(Device.CFW11).inputs(b"\x00\x00\x00", 0.0)


def test_status_word_to_model() -> None:
    p = profile(Device.CFW11, SYNC)
    p.outputs(DesiredCommand(run=True, speed_rpm=450.0), 0.0)
    s = p.inputs(words(0x1700, 2048), 0.0)  # running, enabled, forward, remote; 450 rpm
    assert s["status"] is DriveStatus.RUNNING
    assert (s["speed_rpm"], s["speed_pct"], s["speed_ref_rpm"]) == (450.0, 25.0, 450.0)
    assert (s["running"], s["at_reference"], s["remote"]) == (True, True, True)
    assert s["direction"] is Direction.FORWARD
    assert p.inputs(words(0x1700, 1024), 0.0)["status"] is DriveStatus.STARTING
    assert p.inputs(words(0x1310, 1024), 0.0)["status"] is DriveStatus.STOPPING  # bit 4
    assert p.inputs(words(0x1200, 0), 0.0)["status"] is DriveStatus.READY
    assert p.inputs(words(0x1240, 0), 0.0)["status"] is DriveStatus.NOT_READY  # config mode
    assert p.inputs(words(0x3200, 0), 0.0)["status"] is DriveStatus.NOT_READY  # undervoltage
    reverse = p.inputs(words(0x1300, 0xF800), 0.0)
    assert (reverse["direction"], reverse["speed_rpm"]) == (Direction.REVERSE, -450.0)


def test_stop_shows_stopping_while_the_ramp_runs() -> None:
    p = profile(Device.CFW700, SYNC)
    p.outputs(DesiredCommand(run=False), 0.0)
    assert p.inputs(words(0x1700, 2048), 0.0)["status"] is DriveStatus.STOPPING


def test_cfw320_uses_its_run_command_bit() -> None:
    p = profile(Device.CFW320, SYNC)
    p.outputs(DesiredCommand(run=True, speed_rpm=900.0), 0.0)
    assert p.inputs(words(0x1702, 4096), 0.0)["status"] is DriveStatus.RUNNING
    assert p.inputs(words(0x1700, 4096), 0.0)["status"] is DriveStatus.STOPPING


def test_mapped_words_fill_the_model_and_values() -> None:
    p = profile(Device.CFW11, WegOptions(words=6, words_in=(3, 48, 49, 2), rated_current_a=10))
    s = p.inputs(words(0x9280, 0, 47, 139, 239, 1200), 0.0)
    assert s["status"] is DriveStatus.FAULTED
    assert (s["current_a"], s["current_pct_flc"]) == (4.7, 47.0)
    assert (s["alarm"], s["alarm_code"]) == (True, 139)
    assert (s["fault_code"], s["fault_text"]) == (239, "Profibus DP interface offline")
    assert s["values"] == {"P0002": 1200, "pid_automatic": 0}  # Table 3.2 bit 14
    ok = p.inputs(words(0x1200, 0, 0, 0, 0, 0), 0.0)
    assert (ok["fault_code"], ok["fault_text"], ok["alarm_code"]) == (None, None, None)


def test_unknown_fault_is_shown_as_its_code() -> None:
    p = profile(Device.CFW320, WegOptions(words=3, words_in=(49,)))
    assert p.inputs(words(0x8000, 0, 123), 0.0)["fault_text"] == "F123"
    assert p.inputs(words(0x8000, 0, 32), 0.0)["fault_text"] == (
        "Comm. plug-in module communication lost"
    )
    named = profile(Device.CFW320, WegOptions(words=3, words_in=(742,)))
    assert named.inputs(words(0, 0, 3), 0.0)["values"] == {"P742": 3, "fire_mode": 0}


def test_frame_20_words() -> None:
    options = WegOptions(
        data_profile=DataProfile.PROFIDRIVE,
        frame=20,
        words=6,
        words_in=(760, 761, 762, 763),
        max_rpm=1800,
        rated_current_a=10.0,
        rated_power_kw=5.5,
    )
    p = profile(Device.CFW11, options)
    s = p.inputs(words(0x0237, 0x2000, 0x2000, 0x4000, 0x1000, 0), 0.0)
    assert (s["speed_rpm"], s["current_pct_flc"], s["current_a"]) == (900.0, 50.0, 5.0)
    assert s["power_kw"] == 5.5
    assert s["values"] == {"torque_pct": 25.0, "P0763": 0}
    fault = p.inputs(words(0x0008, 0, 0, 0, 0, 0x0004), 0.0)  # NAMUR bit 2
    assert (fault["fault_code"], fault["fault_text"]) == (22, "DC link overvoltage")
    hot = p.inputs(words(0x0008, 0, 0, 0, 0, 0x0010), 0.0)  # bit 4: F0051, F0054 or F0057
    assert (hot["fault_code"], hot["fault_text"]) == (None, "inverter overtemperature")
    no_rating = profile(Device.CFW11, WegOptions(**{**options.__dict__, "rated_power_kw": None}))
    assert no_rating.inputs(words(0x0237, 0, 0, 0x2000, 0, 0), 0.0)["values"]["power_pct"] == 50


def test_profidrive_status_to_model() -> None:
    p = profile(Device.CFW700, WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1800))
    assert p.inputs(words(0x0040, 0), 0.0)["status"] is DriveStatus.NOT_READY
    s = p.inputs(words(0x0231, 0), 0.0)
    assert (s["status"], s["remote"]) == (DriveStatus.READY, True)
    p.outputs(DesiredCommand(run=True, speed_rpm=900.0), 0.0)
    assert p.inputs(words(0x0237, 0x1000), 0.0)["status"] is DriveStatus.STARTING
    at = p.inputs(words(0x02B7, 0x2000), 0.0)
    assert (at["status"], at["at_reference"], at["alarm"]) == (DriveStatus.RUNNING, True, True)
    assert p.inputs(words(0x0217, 0x2000), 0.0)["status"] is DriveStatus.STOPPING  # OFF3
    assert p.inputs(words(0x0008, 0), 0.0)["status"] is DriveStatus.FAULTED


def test_ext_diag() -> None:
    p = profile(Device.CFW11)
    assert p.on_ext_diag(b"") == []
    (event,) = p.on_ext_diag(b"\x01\x02")
    assert event.kind == "info"
    assert "01 02" in event.text


async def test_fault_code_read_through_dpv1_when_no_word_carries_it() -> None:
    loop = Loop(Device.CFW700)
    await loop.connect()
    loop.command(run=True, speed_rpm=300.0)
    loop.step(5)
    loop.sim.inject_fault(71, loop.now)
    loop.sim.inject_alarm(139)
    state = loop.step()
    assert state["status"] is DriveStatus.FAULTED
    assert state["fault_code"] is None
    assert loop.profile.wants_codes
    changes = await loop.profile.read_codes(loop.channel)
    assert changes == {"fault_code": 71, "fault_text": "F071", "alarm_code": 139}
    assert not loop.profile.wants_codes
    assert loop.step()["fault_code"] == 71  # kept while the fault lasts
    assert loop.profile.alarm_text(139) == "Profibus DP interface offline"


async def test_an_alarm_read_through_dpv1_goes_with_the_status_bit() -> None:
    loop = Loop(Device.CFW320)  # 2 words: P048 only through DP-V1
    await loop.connect()
    loop.step()  # online (the first exchange would clear an A139)
    loop.sim.inject_alarm(139)
    assert loop.step()["alarm"] is True
    assert await loop.profile.read_codes(loop.channel) == {"alarm_code": 139}
    assert loop.step()["alarm_code"] == 139  # kept while bit 7 stays set
    loop.sim.clear_alarm()
    s = loop.step()  # P680 bit 7 dropped: no alarm, and no stale code
    assert (s["alarm"], s["alarm_code"]) == (False, None)
    assert not loop.profile.wants_codes
    loop.sim.inject_alarm(138)  # the next alarm is read again
    loop.step()
    assert loop.profile.wants_codes


@pytest.mark.parametrize(
    ("device", "bit", "key"),
    [
        (Device.CFW320, 2, "fire_mode"),  # CFW320 Table 4.2 bit 2 "Fire mode"
        (Device.CFW11, 14, "pid_automatic"),  # CFW-11 Table 3.2 bit 14 "PID automático"
    ],
)
def test_fire_mode_and_pid_automatic_bits_are_published_in_values(
    device: Device, bit: int, key: str
) -> None:
    p = profile(device, WegOptions(words=2, sync_rpm=1800))
    assert p.inputs(words(1 << bit, 0), 0.0)["values"] == {key: 1}
    assert p.inputs(words(0, 0), 0.0)["values"] == {key: 0}


def test_the_cfw700_has_neither_bit() -> None:
    # CFW700 Table 4.2: bit 14 reserved, no fire mode
    p = profile(Device.CFW700, WegOptions(words=2, sync_rpm=1800))
    assert "values" not in p.inputs(words(0xFFFF & ~0x8000, 0), 0.0)
