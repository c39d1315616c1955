"""The CANopen bus and drive keys: an EDS that does not parse, an object it lacks, bad
option codes and startup SDOs are config errors naming the file, the key and the object."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from adapters.can.bits import frame_bits
from adapters.canopen.options import BusOptions, Mode, cycle_bits, min_sync_period
from adapters.canopen.plan import node_config
from gateway.config import parse, shipped_file
from gateway.errors import ConfigErrors

EDS = shipped_file("eds/cia402-drive.eds")


def config(drive: dict[str, Any], **bus: Any) -> Any:
    table = {
        "adapter": "canopen",
        "interface": "virtual",
        "channel": "x",
        **bus,
        "drives": [{"id": "d5", "device": "CiA 402", "address": 5, "eds": str(EDS), **drive}],
    }
    return parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": table}},
        "site.toml",
    )


def error_of(drive: dict[str, Any], **bus: Any) -> str:
    with pytest.raises(ConfigErrors) as info:
        config(drive, **bus)
    return str(info.value)


def without(tmp_path: Path, *sections: str) -> Path:
    text = EDS.read_text()
    for section in sections:
        text = re.sub(rf"\n\[{section}\][^\[]*", "\n", text)
    path = tmp_path / "cut.eds"
    path.write_text(text)
    return path


def test_the_demo_eds_gives_a_full_plan() -> None:
    cfg = config({"mode": "profile_velocity", "comm_loss_option": 1, "quick_stop_option": 2})
    bus = cfg.buses[0]
    opts = bus.drives[0].options
    assert opts.mode is Mode.PROFILE_VELOCITY and opts.max_rpm == 1800.0
    plan = node_config(5, opts, bus.options)
    whats = [s.what for s in plan.steps]
    assert whats[0] == "controlword 0x6040 = Shutdown (a running drive stops first)"
    assert (plan.steps[0].data, plan.steps[0].read_back) == (b"\x06\x00", False)
    assert whats[1] == "producer heartbeat time 0x1017"
    assert any(w.startswith("consumer heartbeat time 0x1016:1 (node 127") for w in whats)
    assert "abort connection option 0x6007 (fault signal)" in whats
    assert [(f.entry.index, f.entry.bits) for f in plan.tpdo] == [
        (0x6041, 16),
        (0x606C, 32),
        (0x6078, 16),
    ]
    assert [(f.entry.index, f.entry.bits) for f in plan.rpdo] == [(0x6040, 16), (0x60FF, 32)]
    # CiA 301 re-mapping order: disable, clear, entries, count, type, enable
    tpdo = [(s.index, s.subindex, s.data) for s in plan.steps if s.index in (0x1800, 0x1A00)]
    assert tpdo[0] == (0x1800, 1, (0x80000185).to_bytes(4, "little"))
    assert tpdo[1] == (0x1A00, 0, b"\x00")
    assert tpdo[2] == (0x1A00, 1, (0x60410010).to_bytes(4, "little"))
    assert tpdo[-1] == (0x1800, 1, (0x185).to_bytes(4, "little"))
    # every other PDO of the EDS switched off (CiA 301 §7.5.2.35/36: bit 31), before 0x6060
    off = [(s.index, s.subindex, s.data, s.mask, s.optional) for s in plan.steps if s.optional]
    assert off == [
        (0x1401, 1, bytes.fromhex("05 03 00 80"), 0x80000000, True),
        (0x1801, 1, bytes.fromhex("85 02 00 80"), 0x80000000, True),
    ]
    assert whats.index("TPDO2 switched off (not used): 0x1801:1 bit 31") < len(whats) - 1
    assert whats.index("TPDO1 enabled") < whats.index(
        "RPDO2 switched off (not used): 0x1401:1 bit 31"
    )


def test_unused_pdos_of_a_wider_eds(tmp_path: Path) -> None:
    text = EDS.read_text()
    start = text.index("[1801]")
    # a TPDO3 beside TPDO2: its COB-ID from the EDS, bit 31 set
    tpdo3 = text[start : text.index("[", text.index("[1801sub6]") + 1)]
    tpdo3 = tpdo3.replace("[1801", "[1802").replace("$NODEID+0x280", "$NODEID+0x380")
    wider = tmp_path / "wider.eds"
    wider.write_text(text[:start] + tpdo3 + text[start:])
    opts = config({"eds": str(wider)}).buses[0]
    plan = node_config(5, opts.drives[0].options, opts.options)
    assert [(s.index, s.data) for s in plan.steps if s.optional] == [
        (0x1401, bytes.fromhex("05 03 00 80")),
        (0x1801, bytes.fromhex("85 02 00 80")),
        (0x1802, bytes.fromhex("85 03 00 80")),
    ]


def test_bus_defaults() -> None:
    assert config({}).buses[0].options == BusOptions(interface="virtual", channel="x")


def test_an_eds_that_does_not_parse(tmp_path: Path) -> None:
    bad = tmp_path / "broken.eds"
    bad.write_text("[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0xZZ\n")
    text = error_of({"eds": str(bad)})
    assert "site.toml: buses.co.drives[d5].eds:" in text
    assert str(bad) in text and "does not parse as an EDS/DCF" in text


def test_a_missing_eds(tmp_path: Path) -> None:
    text = error_of({"eds": str(tmp_path / "nowhere.eds")})
    assert "nowhere.eds: does not exist" in text


def test_an_object_the_eds_lacks(tmp_path: Path) -> None:
    cut = without(tmp_path, "60FF")
    text = error_of({"eds": str(cut), "mode": "profile_velocity"})
    assert "buses.co.drives[d5].mode" in text
    assert f"{cut}: 0x60FF: the EDS has no object 0x60FF (mode profile_velocity)" in text
    config({"eds": str(cut)})  # velocity mode does not need it


def test_an_option_the_eds_lacks(tmp_path: Path) -> None:
    cut = without(tmp_path, "6007")
    text = error_of({"eds": str(cut), "comm_loss_option": 1})
    assert "comm_loss_option" in text and "no object 0x6007" in text


def test_option_codes() -> None:
    assert "is not a CiA 402 option code" in error_of({"quick_stop_option": 9})
    assert config({"quick_stop_option": -1}).buses[0].drives[0].options.quick_stop_option == -1


def test_startup_sdo() -> None:
    opts = config({"startup_sdo": {"0x6083": 500, "0x2000:4": 1500}}).buses[0].drives[0].options
    assert [(w.variable.index, w.variable.subindex, w.data) for w in opts.startup_sdo] == [
        (0x6083, 0, (500).to_bytes(4, "little")),
        (0x2000, 4, (1500).to_bytes(2, "little")),
    ]
    assert "no object 0x2000:9" in error_of({"startup_sdo": {"0x2000:9": 1}})
    assert "0x6041 is not writable" in error_of({"startup_sdo": {"0x6041": 1}})
    assert "is not an object index" in error_of({"startup_sdo": {"6083": 1}})
    assert "70000 is outside 100..6000" in error_of({"startup_sdo": {"0x2000:4": 70000}})


def test_writable_params_take_canopen_objects() -> None:
    d = config({"writable_params": ["0x6083", "0x2000:4", 24708]}).buses[0].drives[0]
    assert d.writable_params == frozenset({0x6083, 0x6084})
    assert d.writable_entries == frozenset({(0x2000, 4)})
    assert "is not a parameter" in error_of({"writable_params": ["0xZZ"]})


def test_node_ids() -> None:
    assert "address" in error_of({"address": 0})
    assert "address" in error_of({"address": 128})


def test_simulate_needs_virtual() -> None:
    assert "needs interface = 'virtual'" in error_of({}, simulate=True, interface="socketcan")


def test_worst_case_frame_lengths() -> None:
    # CAN 2.0A with worst-case stuffing and the intermission: the textbook 55 bits of an
    # empty frame and 135 of an 8-byte one (47 + 8n + floor((34 + 8n - 1) / 4))
    assert [frame_bits(n) for n in (0, 4, 8)] == [55, 95, 135]


def test_sync_period_shorter_than_a_cycle_on_the_line() -> None:
    # one vl drive of the demo EDS: SYNC 55 + RPDO1 (4 bytes) 95 + TPDO1 (8 bytes) 135 bits
    opts = config({}, bitrate=500_000).buses[0].drives[0].options
    assert (opts.rpdo1_bytes, opts.tpdo1_bytes) == (4, 8)
    assert cycle_bits([opts]) == 285
    assert min_sync_period(500_000, [opts]) == pytest.approx(570e-6)
    assert min_sync_period(1_000_000, [opts] * 32) == pytest.approx(7415e-6)
    text = error_of({}, bitrate=500_000, sync_period=0.0005)
    assert "site.toml" in text and "sync_period" in text
    assert "500 us is shorter than one cycle" in text and "at least 570 us" in text
    assert "500000 bit/s" in text and "1 drive(s) take 285 bits" in text
    assert config({}, bitrate=500_000, sync_period=0.00057).buses[0].options.sync_period == (
        pytest.approx(0.00057)
    )
    assert config({}, bitrate=1_000_000, sync_period=0.0003).buses[0].options.sync_period


def test_sync_period_absolute_floor_and_none() -> None:
    text = error_of({}, bitrate=1_000_000, sync_period=0.00005)
    assert "sync_period" in text and "at least 100 us" in text
    assert config({}, sync_period=0, bitrate=10_000).buses[0].options.sync_period == 0
