"""The GSD corpus (tests/data/gsd/corpus, written from the GSD specification in the styles
different vendors use): every file parsed, its Chk_Cfg and user parameter bytes against
the bytes worked out by hand (tests/profibus/gsd/corpus.py says how), and what each style
adds: parameters by name, slots, diagnosis texts, DP-V1 status bytes, PROFIsafe modules."""

from __future__ import annotations

import pytest

from adapters.profibus.codec import gsd as g
from adapters.profibus.codec.dp import Dpv1Status, SetPrm
from adapters.profibus.options import load_gsd
from tests.profibus.gsd.corpus import CASES, CORPUS_DIR, Case


def load(name: str) -> g.Gsd:
    return load_gsd(CORPUS_DIR / name)


def test_the_corpus_is_every_file_of_its_folder() -> None:
    files = sorted(p.name for p in CORPUS_DIR.glob("*.gsd"))
    assert files == sorted(c.file for c in CASES)
    assert len(files) >= 8
    for path in CORPUS_DIR.glob("*.gsd"):
        text = path.read_bytes().decode("iso-8859-1")
        assert "Not a vendor file" in text and "written from the GSD specification" in text


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.file)
def test_each_file_gives_the_bytes_worked_out_by_hand(case: Case) -> None:
    setup = g.build_setup(load(case.file), case.modules)
    assert setup.cfg.hex(" ") == case.cfg.hex(" "), case.how
    assert setup.user_prm.hex(" ") == case.user_prm.hex(" "), case.how


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.file)
def test_each_file_round_trips(case: Case) -> None:
    f = load(case.file)
    again = g.parse(g.render(f), "again.gsd")
    assert again == f
    assert g.build_setup(again, case.modules).user_prm == case.user_prm


def test_compact_legacy_keeps_the_legacy_keywords() -> None:
    f = load("compact_legacy.gsd")
    assert not f.ext_prm and f.get("GSD_Revision") is None  # revision 0
    assert (f.user_prm_data, f.get("User_Prm_Data_Len")) == (b"\x01\x02", 4)
    assert f.supports(1500000) and f.max_tsdr(1500000) == 150 and not f.supports(12000000)


def test_compact_ext_sets_parameters_sharing_a_byte() -> None:
    f = load("compact_ext.gsd")
    assert f.ext_prm and f.user_prm_data == b"" and f.get("Max_User_Prm_Data_Len") == 6
    modules = ["Control and speed, 2 words in/out"]
    s = g.build_setup(f, modules, {"Speed unit": "Hz", "speed trim [%]": 20})
    assert s.user_prm == bytes.fromhex("11 00 32 14 00")  # Hz = 1 << 4 beside bit 0 = 1
    s = g.build_setup(f, modules, {"Fault reset at power-up": "disabled", "Speed trim [%]": -20})
    assert s.user_prm == bytes.fromhex("20 00 32 EC 00")
    with pytest.raises(g.GsdSetupError, match=r"6001 is outside its range 0-6000"):
        g.build_setup(f, modules, {"Ramp time [100 ms]": 6001})


def test_modular_blocks_follow_the_station_in_slot_order() -> None:
    f = load("modular_ext_module_prm.gsd")
    assert [m.prm_len for m in f.modules] == [2, 1, 3, 0]
    s = g.build_setup(
        f,
        ["DO 8 x 24 V / 0.5 A", "AI 2 x 0-10 V"],
        {"Outputs on Clear": "substitute", "Filter [ms]": 250},
    )
    assert s.cfg == bytes.fromhex("20 51")
    assert s.user_prm == bytes.fromhex("40 00 02 02 00 FA")
    with pytest.raises(g.GsdSetupError, match=r"3 is outside its range 0,1,2"):
        g.build_setup(f, ["DO 8 x 24 V / 0.5 A"], {"Outputs on Clear": 3})


def test_mixed_file_keeps_the_legacy_bytes_but_builds_from_the_ext_keywords() -> None:
    f = load("mixed_legacy_ext.gsd")
    assert f.ext_prm and f.user_prm_data == bytes.fromhex("AA BB CC DD")
    assert g.station_prm_len(f) == 3


def test_odd_layout_reads_case_continuations_comments_and_iso_8859_1() -> None:
    path = CORPUS_DIR / "odd_layout.gsd"
    assert b"\r\n" in path.read_bytes() and "ü".encode("iso-8859-1") in path.read_bytes()
    f = load("odd_layout.gsd")
    assert f.ident_number == 0x7A05 and f.get("GSD_Revision") == 2
    assert dict(f.strings)["vendor_name"] == "Müller & Söhne; Antriebe"
    assert f.name == "Umrichter Größe Ä"
    assert f.supports(9600) and f.max_tsdr(1500000) == 150
    watch = f.ext(1)
    assert watch is not None and (watch.name, watch.data_type, watch.first_bit) == (
        "Überwachung",
        "Bit",
        3,
    )
    limit = f.ext(2)
    assert limit is not None and (limit.default, limit.maximum) == (100, 200)
    assert f.prm_text(1) == g.PrmText(1, ((0, "aus"), (1, "ein")))
    module = f.modules[0]
    assert (module.reference, module.input_bytes, module.output_bytes) == (1, 4, 4)
    s = g.build_setup(f, [module.name.upper()], {"ÜBERWACHUNG": "aus"})
    assert s.user_prm == bytes.fromhex("00 64 00 00")


def test_revision_1_diagnosis_and_an_enumerated_parameter() -> None:
    f = load("rev1_compact.gsd")
    assert f.get("GSD_Revision") == 1
    assert f.unit_diag_bits == (
        g.UnitDiagBit(0, "Sensor break, channel 1"),
        g.UnitDiagBit(1, "Sensor break, channel 2"),
    )
    assert f.unit_diag_areas == (
        g.UnitDiagArea(8, 9, ((0, "Measuring"), (1, "Overrange"), (2, "Underrange"))),
    )
    module = ["Counter, 2 words in"]
    assert g.build_setup(f, module, {"Measuring range": "PT100"}).user_prm == b"\x05\x03"
    with pytest.raises(g.GsdSetupError, match=r"2 is outside its range 0,1,3"):
        g.build_setup(f, module, {"Measuring range": 2})


def test_revision_5_slots_changeable_and_diagnosis() -> None:
    f = load("rev5_slots.gsd")
    assert f.dpv1 and f.modular and f.get("C2_Max_Count_Channels") == 1
    assert f.slots == (
        g.SlotDef(1, "Analog input", 2, (1, 2, 3)),
        g.SlotDef(2, "Totalizer", 4, (1, 4)),
    )
    assert g.UnitDiagBit(31, "Device not yet initialised", inverted=True) in f.unit_diag_bits
    assert f.unit_diag_areas[0].values[-1] == (2, "Sensor failure")  # Value_Help read over
    version = f.ext(22)
    assert version is not None and not version.changeable and not version.visible
    s = g.build_setup(f, ["AI long", "Empty module"])
    assert (s.cfg, s.user_prm, s.input_len) == (bytes.fromhex("42 84 08 05 00"), bytes(3), 5)
    assert s.user_prm_after_dpv1 == b""
    with pytest.raises(g.GsdSetupError, match=r"'Totalizer' is not allowed in slot 1"):
        g.build_setup(f, ["Totalizer", "AI short"])
    with pytest.raises(g.GsdSetupError, match=r"Changeable = 0\) at its default 1"):
        g.build_setup(f, ["AI short", "Totalizer"], {"Block profile version": 2})
    s = g.build_setup(
        f, ["AI short", "Totalizer"], {"Totalizer mode [SlotNumber]": "negative only"}
    )
    assert s.user_prm == bytes.fromhex("00 00 00 02 01")


def test_dpv1_status_bytes_come_first_and_the_master_sends_its_own() -> None:
    f = load("dpv1_drive.gsd")
    keys = ("C1_Max_Data_Len", "C2_Response_Timeout", "WD_Base_1ms_supp", "Diagnostic_Alarm_supp")
    assert [f.get(k) for k in keys] == [240, 1000, 1, 1]
    s = g.build_setup(f, ["PKW, 4 words consistent", "PZD, 2 words"])
    assert s.dpv1 and s.user_prm_after_dpv1 == bytes.fromhex("01 F4")
    status = Dpv1Status.decode(s.user_prm[:3])
    assert status == Dpv1Status(dpv1_enable=True, diagnostic_alarm=True)
    # the whole Set_Prm: Lock_Req | WD_On, factors 10 x 10, min TSDR 0, the Ident_Number,
    # group 0, then DPV1_Status_1..3 and the drive's two bytes
    telegram = SetPrm(
        ident_number=s.ident_number,
        wd_on=True,
        wd_fact_1=10,
        wd_fact_2=10,
        dpv1=status,
        user_prm_data=s.user_prm_after_dpv1,
    ).encode()
    assert telegram == bytes.fromhex("88 0A 0A 00 7A 08 00 80 20 00 01 F4")
    with pytest.raises(
        g.GsdSetupError, match=r"'PROFIsafe telegram' carries PROFIsafe F-parameters"
    ):
        g.build_setup(f, ["PZD, 2 words", "PROFIsafe telegram"])


def test_constants_go_in_before_the_parameters_whatever_the_line_order() -> None:
    f = load("ref_before_const.gsd")
    assert [p.keyword for p in f.placements] == [
        "Ext_User_Prm_Data_Ref",
        "Ext_User_Prm_Data_Ref",
        "Ext_User_Prm_Data_Const",
    ]
    assert [m.prm_len for m in f.modules] == [1, 0, 0]  # no Ext_Module_Prm_Data_Len: its extent
    s = g.build_setup(f, ["Input 8 bytes"], {"Word order high first": 1, "Watchdog [s]": 60})
    assert s.user_prm == bytes.fromhex("01 3C 80")
