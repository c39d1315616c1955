"""The GSD parser on our own test files, on the file format's rules, on broken files (errors
name the file, the line and the key) and by round trips: render a model, parse it again."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.profibus.codec import gsd as g
from adapters.profibus.options import load_gsd
from gateway.errors import GatewayError

GSD_DIR = Path(__file__).resolve().parents[2] / "data" / "gsd"
FILES = sorted(GSD_DIR.glob("*.gsd"))

MINIMAL = """#Profibus_DP
Ident_Number = 0x1234
Module = "m" 0xF1
EndModule
"""


def test_the_test_files_are_ours_and_parse() -> None:
    assert [f.name for f in FILES] == [
        "TEST_CFW11.gsd",
        "TEST_CFW320.gsd",
        "TEST_CFW700.gsd",
        "TEST_MCD600.gsd",
    ]
    for path in FILES:
        text = path.read_bytes().decode("iso-8859-1")
        assert "TEST FILE" in text and "NOT a" in text  # labelled: not a vendor file
        parsed = load_gsd(path)
        assert len(parsed.modules) >= 2
        assert parsed.ext_user_prm


def test_cfw11_keys_a_master_needs() -> None:
    f = load_gsd(GSD_DIR / "TEST_CFW11.gsd")
    assert f.ident_number == 0x0C11
    assert f.get("Station_Type") == 0
    assert f.supports(9600) and f.max_tsdr(9600) == 15 and f.max_tsdr(12000000) == 50
    assert not f.supports(45450)
    assert f.get("Min_Slave_Intervall") == 1
    assert not f.modular
    assert (f.get("Max_Input_Len"), f.get("Max_Output_Len"), f.get("Max_Data_Len")) == (20, 20, 40)
    assert f.dpv1 and f.get("C1_Read_Write_supp") == 1
    assert (f.get("C1_Max_Data_Len"), f.get("C1_Response_Timeout")) == (240, 100)
    assert f.ext_prm and f.user_prm_data == b"" and f.get("User_Prm_Data_Len") is None
    assert f.get("Max_User_Prm_Data_Len") == 5
    # a "\" continuation joined the constant bytes
    assert f.placements[0] == g.PrmPlacement(0, const=bytes([0x80, 0, 0, 0, 0]))
    four = f.module("4 WORDS I/O (p0922 = 3)")  # names are found whatever their case
    assert four is not None and four.config == bytes([0xC0, 0xC3, 0xC3])
    assert (four.input_bytes, four.output_bytes, four.reference) == (8, 8, 3)
    # ISO-8859-1 text, read as such
    assert f.prm_text(1) == g.PrmText(1, ((0, "desligado"), (1, "Ação: alarme")))
    alarm = f.ext(1)
    assert alarm is not None and (alarm.data_type, alarm.first_bit, alarm.default) == ("Bit", 0, 1)
    delay = f.ext(2)  # "UNSIGNED8" in the file: keywords are case-insensitive
    assert delay is not None and (delay.data_type, delay.minimum, delay.maximum) == (
        "Unsigned8",
        0,
        20,
    )


def test_user_data_starts_from_the_defaults_and_prm_sets_values_by_name() -> None:
    f = load_gsd(GSD_DIR / "TEST_CFW11.gsd")
    s = g.build_setup(f, ["2 words I/O (P0922 = 1)"])
    assert s.user_prm == bytes([0x80, 0, 0, 0x01, 5])  # Bit(0) default 1, delay 5
    assert s.user_prm_after_dpv1 == bytes([0x01, 5])
    assert (s.ident_number, s.cfg, s.input_len, s.output_len) == (0x0C11, b"\xc0\xc1\xc1", 4, 4)
    s = g.build_setup(
        f,
        ["2 words I/O (P0922 = 1)"],
        {"test: START delay": 20, "Test: diagnosis alarm": "desligado"},
    )
    assert s.user_prm_after_dpv1 == bytes([0x00, 20])
    with pytest.raises(
        g.GsdSetupError, match=r"prm.Test: start delay: 21 is outside its range 0-20"
    ):
        g.build_setup(f, ["2 words I/O (P0922 = 1)"], {"Test: start delay": 21})
    with pytest.raises(g.GsdSetupError, match="'on' is not one of its texts"):
        g.build_setup(f, ["2 words I/O (P0922 = 1)"], {"Test: diagnosis alarm": "on"})
    with pytest.raises(g.GsdSetupError, match="not a user parameter"):
        g.build_setup(f, ["2 words I/O (P0922 = 1)"], {"nope": 1})
    with pytest.raises(g.GsdSetupError, match="'3 words' is not a module of"):
        g.build_setup(f, ["3 words"])
    with pytest.raises(g.GsdSetupError, match="not a modular station"):
        g.build_setup(f, ["2 words I/O (P0922 = 1)"] * 2)


def test_a_modular_station_appends_each_modules_parameter_block() -> None:
    f = load_gsd(GSD_DIR / "TEST_CFW320.gsd")
    mods = ["Control and speed (2 words I/O)", "Extra word I/O"]
    s = g.build_setup(f, mods, {"Test: local source": "keypad", "Test: extra word filter": -10})
    assert s.cfg == bytes([0xC0, 0xC1, 0xC1, 0xF0])
    assert s.user_prm == bytes([0x80, 0, 0, 0x80, 0xF6])
    with pytest.raises(g.GsdSetupError, match="Max_Module = 5"):
        g.build_setup(f, [mods[0]] + [mods[1]] * 5)
    assert g.build_setup(f, [mods[0]] + [mods[1]] * 4).input_len == 12  # Max_Input_Len
    small = g.parse(MINIMAL + "Max_Input_Len = 3\n", "small.gsd")
    with pytest.raises(
        g.GsdSetupError, match="4 bytes of input data, the GSD allows Max_Input_Len = 3"
    ):
        g.build_setup(small, ["m"])
    assert g.match_modules(f, bytes([0xC0, 0xC1, 0xC1, 0xF0, 0xF0])) == (
        f.modules[0],
        f.modules[1],
        f.modules[1],
    )
    assert g.match_modules(f, bytes([0xC0, 0xC1])) is None


def test_file_format_rules() -> None:
    text = (
        "#Profibus_DP\n"
        "  IDENT_NUMBER = 0x4711 ; a comment\n"
        'model_name = "a ; not a comment"\n'
        "User_Prm_Data_Len = 2\n"
        "user_prm_data = 0x01, \\\n"
        "   0x02\n"
        'MODULE = "m" 0x10, \\\n'
        "  0x20\n"
        "endmodule\n"
    )
    f = g.parse(text, "x.gsd")
    assert f.ident_number == 0x4711
    assert f.name == "a ; not a comment"
    assert f.user_prm_data == b"\x01\x02"
    assert f.modules[0].config == b"\x10\x20"


@pytest.mark.parametrize(
    ("text", "line", "key", "reason"),
    [
        ("#Profibus_DP\nIdent_Number = 0x12G4\n", 2, "Ident_Number", "'0x12G4' is not a number"),
        (MINIMAL + 'Module = "n" 0xF1\n', 5, "Module", "has no EndModule"),
        (MINIMAL + "EndModule\n", 5, "EndModule", "closes a block that was never opened"),
        (MINIMAL.replace("0xF1", "0x1F0"), 3, "Module", "496 is not a byte (0-255)"),
        (MINIMAL + "User_Prm_Data_Len = 300\n", 5, "User_Prm_Data_Len", "must be 0-237"),
        (
            MINIMAL + "Ext_User_Prm_Data_Ref(0) = 9\nUser_Prm_Data_Len = 1\n",
            5,
            "Ext_User_Prm_Data_Ref",
            "no ExtUserPrmData 9 in the file",
        ),
        (
            MINIMAL + 'ExtUserPrmData = 1 "p"\nUnsigned8 300 0-255\nEndExtUserPrmData\n',
            6,
            "Unsigned8 300 0-255",
            "default 300 is outside its own range",
        ),
        (
            MINIMAL + 'ExtUserPrmData = 1 "p"\nUnsigned8 0 0-300\nEndExtUserPrmData\n',
            6,
            "Unsigned8 0 0-300",
            "range 0-300 does not fit a Unsigned8",
        ),
        (
            MINIMAL + 'ExtUserPrmData = 1 "p"\nBit(9) 0 0-1\nEndExtUserPrmData\n',
            6,
            "Bit(9) 0 0-1",
            "'Bit(9) 0 0-1': bit numbers must be 0-7",
        ),
        (
            MINIMAL + 'ExtUserPrmData = 1 "p"\nUnsigned8 0 0-1\nPrm_Text_Ref = 4\n'
            "EndExtUserPrmData\n",
            5,
            "Prm_Text_Ref",
            "no PrmText 4",
        ),
        (
            MINIMAL + "Max_User_Prm_Data_Len = 1\nExt_User_Prm_Data_Const(1) = 0x01\n",
            6,
            "Ext_User_Prm_Data_Const",
            "offset 1 + 1 bytes is beyond Max_User_Prm_Data_Len = 1",
        ),
        ('#Profibus_DP\nModule = "m" 0xF1\nEndModule\n', 0, "Ident_Number", "is missing"),
        (
            'Module = "m" 0xF1\nEndModule\n',
            0,
            "#Profibus_DP",
            "the file has no #Profibus_DP line: not a DP slave's GSD",
        ),
        (MINIMAL + 'Module = "M" 0xF2\nEndModule\n', 5, "Module", "module 'M' is defined twice"),
        (
            MINIMAL + 'Module = "x" 0x40\nEndModule\n',
            5,
            "Module",
            "module 'x': special identifier 0x40 cut short",
        ),
    ],
)
def test_errors_name_the_file_the_line_and_the_key(
    text: str, line: int, key: str, reason: str
) -> None:
    with pytest.raises(g.GsdError) as info:
        g.parse(text, "site/broken.gsd")
    e = info.value
    assert isinstance(e, GatewayError) and isinstance(e, ValueError)
    assert (e.file, e.line, e.key, e.reason) == ("site/broken.gsd", line, key, reason)
    where = f"site/broken.gsd:{line}" if line else "site/broken.gsd"
    assert str(e) == f"{where}: {key}: {reason}"


def test_a_missing_file_is_a_gsd_error(tmp_path: Path) -> None:
    with pytest.raises(g.GsdError, match=r"none\.gsd: does not exist"):
        load_gsd(tmp_path / "none.gsd")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_the_test_files_round_trip(path: Path) -> None:
    f = load_gsd(path)
    assert g.parse(g.render(f), "again.gsd") == f


# ------------------------------------------------------------------ hypothesis

names = st.text(
    st.characters(min_codepoint=32, max_codepoint=255, exclude_characters='";\\'),
    min_size=1,
    max_size=20,
)


@st.composite
def ext_prm(draw: st.DrawFn, ref: int) -> g.ExtUserPrmData:
    kind = draw(st.sampled_from(["Unsigned8", "Unsigned16", "Signed16", "Bit", "BitArea"]))
    first = last = 0
    if kind == "Bit":
        first = last = draw(st.integers(0, 7))
        low, high = 0, 1
    elif kind == "BitArea":
        first = draw(st.integers(0, 6))
        last = draw(st.integers(first, 7))
        low, high = 0, (1 << (last - first + 1)) - 1
    elif kind == "Signed16":
        low = draw(st.integers(-32768, 0))
        high = draw(st.integers(0, 32767))
    else:
        high = draw(st.integers(0, 255 if kind == "Unsigned8" else 65535))
        low = draw(st.integers(0, high))
    allowed: tuple[int, ...] = ()
    if draw(st.booleans()):
        allowed = tuple(sorted(draw(st.sets(st.integers(low, high), min_size=1, max_size=4))))
        default = draw(st.sampled_from(allowed))
        low, high = allowed[0], allowed[-1]
    else:
        default = draw(st.integers(low, high))
    return g.ExtUserPrmData(ref, draw(names), kind, default, low, high, allowed, first, last)


@st.composite
def gsd_models(draw: st.DrawFn) -> g.Gsd:
    n_ext = draw(st.integers(0, 3))
    exts = tuple(draw(ext_prm(ref)) for ref in range(1, n_ext + 1))
    texts = tuple(
        g.PrmText(ref, tuple((v, draw(names)) for v in range(draw(st.integers(1, 3)))))
        for ref in range(1, draw(st.integers(0, 2)) + 1)
    )
    if texts and exts:
        e = exts[0]
        exts = (
            g.ExtUserPrmData(
                e.ref,
                e.name,
                e.data_type,
                e.default,
                e.minimum,
                e.maximum,
                e.allowed,
                e.first_bit,
                e.last_bit,
                texts[0].ref,
            ),
            *exts[1:],
        )
    dpv1 = draw(st.booleans())
    length = 4 * n_ext + draw(st.integers(3 if dpv1 else 0, 4))
    placements = tuple(g.PrmPlacement(4 * i, ref=e.ref) for i, e in enumerate(exts))
    if draw(st.booleans()) and length:
        placements += (g.PrmPlacement(length - 1, const=bytes([draw(st.integers(0, 255))])),)
    if dpv1 and (exts or placements):  # DPV1_Status_1..3 first (the references overwrite)
        placements = (g.PrmPlacement(0, const=b"\x80\x00\x00"), *placements)
    module_names = draw(st.lists(names, min_size=1, max_size=4, unique_by=str.casefold))
    configs = st.sampled_from([b"\xf1", b"\xc0\xc1\xc1", b"\xf0\xa0\x93", b"\x13", b"\x00"])
    modules = tuple(
        g.GsdModule(n, draw(configs), draw(st.none() | st.integers(0, 99))) for n in module_names
    )
    ints = {"ident_number": draw(st.integers(0, 0xFFFF)), "user_prm_data_len": length}
    for key in ("station_type", "modular_station", "max_module", "c1_max_data_len"):
        if draw(st.booleans()):
            ints[key] = draw(st.integers(1 if key == "max_module" else 0, 240))  # a GSD's 1+
    if dpv1:
        ints["dpv1_slave"] = 1
    bauds = draw(st.lists(st.sampled_from(list(g.BAUD_KEYS)), unique=True))
    return g.Gsd(
        ints=tuple(sorted(ints.items())),
        strings=(("model_name", draw(names)),),
        baud_rates=tuple(
            (b, draw(st.none() | st.integers(1, 999))) for b in g.BAUD_KEYS if b in bauds
        ),
        user_prm_data=bytes(draw(st.lists(st.integers(0, 255), max_size=length))),
        placements=placements,
        modules=modules,
        prm_texts=texts,
        ext_user_prm=exts,
    )


@given(gsd_models())
def test_render_then_parse_gives_the_model_back(model: g.Gsd) -> None:
    text = g.render(model)
    assert g.parse(text, "r.gsd") == model
    again = g.parse(text.encode("iso-8859-1").decode("iso-8859-1"), "r.gsd")
    assert g.render(again) == text


@given(gsd_models(), st.data())
def test_the_user_data_built_from_a_model_is_what_a_slave_checking_it_accepts(
    model: g.Gsd, data: st.DataObject
) -> None:
    module = data.draw(st.sampled_from(model.modules))
    values: dict[str, int | str] = {}
    for e in model.ext_user_prm:
        if data.draw(st.booleans()):
            values[e.name] = data.draw(
                st.sampled_from(e.allowed) if e.allowed else st.integers(e.minimum, e.maximum)
            )
    names = [e.name.casefold() for e in model.ext_user_prm]
    values = {k: v for k, v in values.items() if names.count(k.casefold()) == 1}
    setup = g.build_setup(model, [module.name], values)
    assert g.check_user_prm(model, (module,), setup.user_prm) is None
    assert len(setup.user_prm) == g.station_prm_len(model) + module.prm_len
    _, slots = g.default_user_prm(model, (module,))
    for slot in slots:
        if slot.ext.name in values:
            assert slot.ext.get(setup.user_prm, slot.offset) == values[slot.ext.name]
    assert setup.cfg == module.config and setup.ident_number == model.ident_number
