"""The GSD specification's rules the parser follows, each on a small file of its own: the
Ext keywords superseding User_Prm_Data(_Len), Max_User_Prm_Data_Len, module blocks, the
``#Profibus_DP`` section, and the errors of the newer keywords (file, line, key, reason)."""

from __future__ import annotations

import pytest

from adapters.profibus.codec import gsd as g

HEAD = "#Profibus_DP\nIdent_Number = 0x1234\n"
ONE = 'Module = "m" 0xF1\nEndModule\n'


def test_max_user_prm_data_len_and_a_constant_without_user_prm_data_len() -> None:
    f = g.parse(HEAD + "Max_User_Prm_Data_Len = 3\nExt_User_Prm_Data_Const(0) = 1,2,3\n" + ONE)
    assert f.ext_prm and g.station_prm_len(f) == 3
    assert g.build_setup(f, ["m"]).user_prm == b"\x01\x02\x03"


def test_any_ext_keyword_leaves_user_prm_data_out() -> None:
    legacy = HEAD + "User_Prm_Data_Len = 2\nUser_Prm_Data = 7,8\n"
    assert g.build_setup(g.parse(legacy + ONE), ["m"]).user_prm == b"\x07\x08"
    for ext in (
        "Max_User_Prm_Data_Len = 4\n",
        'ExtUserPrmData = 1 "p"\nUnsigned8 0 0-9\nEndExtUserPrmData\n',
        'Module = "k" 0x10\nExt_User_Prm_Data_Const(0) = 5\nEndModule\n',
    ):
        f = g.parse(legacy + ext + ONE)
        assert f.ext_prm and g.build_setup(f, ["m"]).user_prm == b"", ext
    # and then neither is checked: they are not read
    g.parse(HEAD + "User_Prm_Data_Len = 1\nUser_Prm_Data = 1,2\nMax_User_Prm_Data_Len = 0\n" + ONE)
    g.parse(HEAD + "User_Prm_Data_Len = 300\nMax_User_Prm_Data_Len = 0\n" + ONE)


def test_a_definition_further_down_gives_a_module_its_block_length() -> None:
    text = (
        HEAD
        + "Modular_Station = 1\n"
        + 'Module = "w" 0x10\nExt_User_Prm_Data_Ref(0) = 1\nEndModule\n'
        + 'ExtUserPrmData = 1 "word"\nUnsigned16 258 0-999\nEndExtUserPrmData\n'
    )
    f = g.parse(text)
    assert f.modules[0].prm_len == 2
    assert g.build_setup(f, ["w", "w"]).user_prm == bytes.fromhex("01 02 01 02")


def test_the_whole_user_data_within_max_user_prm_data_len() -> None:
    text = (
        HEAD
        + "Modular_Station = 1\nMax_User_Prm_Data_Len = 2\n"
        + 'Module = "p" 0x10\nExt_Module_Prm_Data_Len = 1\nEndModule\n'
    )
    f = g.parse(text)
    assert g.build_setup(f, ["p", "p"]).user_prm == b"\x00\x00"
    with pytest.raises(
        g.GsdSetupError,
        match="3 bytes of user parameters, the GSD allows Max_User_Prm_Data_Len = 2",
    ):
        g.build_setup(f, ["p", "p", "p"])


def test_only_the_profibus_dp_section_is_read() -> None:
    text = (
        'Model_Name = "before the header: not read"\n'
        + HEAD.replace("#Profibus_DP", "#PROFIBUS_DP ; any case")
        + ONE
        + "#Another_Section\nIdent_Number = 0x9999\nthis is not GSD text\n"
    )
    f = g.parse(text, "s.gsd")
    assert f.ident_number == 0x1234 and f.name == "s"


def test_slot_definition_spellings_and_lists() -> None:
    text = (
        HEAD
        + "Modular_Station = 1\n"
        + 'Module = "a" 0x10\n1\nEndModule\nModule = "b" 0x20\n2\nEndModule\n'
        + 'Module = "c" 0x30\n3\nEndModule\n'
        + 'Slot_Definition\nSLOT(2) = "second" 3 1-2,3\nSlot(1) = "first" 1 1\n'
        + "EndSlot_Definition\n"
    )
    f = g.parse(text)
    assert f.slots == (g.SlotDef(2, "second", 3, (1, 2, 3)), g.SlotDef(1, "first", 1, (1,)))
    assert g.build_setup(f, ["a", "c"]).cfg == b"\x10\x30"
    with pytest.raises(g.GsdSetupError, match="3 modules, the GSD's SlotDefinition has 2 slots"):
        g.build_setup(f, ["a", "b", "c"])


@pytest.mark.parametrize(
    ("text", "line", "key", "reason"),
    [
        (
            HEAD + "Max_User_Prm_Data_Len = 238\n" + ONE,
            3,
            "Max_User_Prm_Data_Len",
            "must be 0-237",
        ),
        (
            HEAD + "Ext_User_Prm_Data_Const(236) = 1,2\n" + ONE,
            3,
            "Ext_User_Prm_Data_Const",
            "offset 236 + 2 bytes is beyond the 237 bytes a Set_Prm carries",
        ),
        (
            HEAD + 'Module = "m" 0xF1\nExt_Module_Prm_Data_Len = 1\n'
            "Ext_User_Prm_Data_Const(0) = 1,2\nEndModule\n",
            5,
            "Ext_User_Prm_Data_Const",
            "module 'm': offset 0 + 2 bytes is beyond Ext_Module_Prm_Data_Len = 1",
        ),
        (
            HEAD + 'Module = "m" 0xF1\nExt_User_Prm_Data_Ref(1) = 4\nEndModule\n',
            4,
            "Ext_User_Prm_Data_Ref",
            "no ExtUserPrmData 4 in the file",
        ),
        (
            HEAD
            + "DPV1_Slave = 1\nMax_User_Prm_Data_Len = 9\nExt_User_Prm_Data_Const(0) = 0x80\n"
            + ONE,
            3,
            "DPV1_Slave",
            "a DP-V1 slave's user parameter data starts with DPV1_Status_1..3; the file gives "
            "the station 1 byte(s) of it",
        ),
        (
            HEAD
            + 'ExtUserPrmData = 1 "p"\nUnsigned8 0 0-9\nSigned8 0 0-9\nEndExtUserPrmData\n'
            + ONE,
            5,
            "Signed8 0 0-9",
            "ExtUserPrmData 1 has a second data type line",
        ),
        (
            HEAD
            + 'ExtUserPrmData = 1 "p"\nUnsigned8 0 0-9\nChangeable = 2\nEndExtUserPrmData\n'
            + ONE,
            5,
            "Changeable",
            "2 is not 0 or 1",
        ),
        (
            HEAD + ONE + 'SlotDefinition\nSlot(1) = "s" 1 1\nEndSlotDefinition\n',
            6,
            "Slot(1)",
            "no module has the reference number 1",
        ),
        (
            HEAD + 'Module = "m" 0xF1\n1\nEndModule\nSlotDefinition\nSlot(1) = "s" 2 1\n'
            "EndSlotDefinition\n",
            7,
            "Slot(1)",
            "default module 2 is not an allowed one",
        ),
        (
            HEAD + ONE + "SlotDefinition\nModule_Count = 2\nEndSlotDefinition\n",
            6,
            "Module_Count",
            'only Slot(n) = "name" default allowed lines go in a SlotDefinition',
        ),
        (
            HEAD + ONE + "SlotDefinition\n",
            5,
            "SlotDefinition",
            "has no EndSlotDefinition",
        ),
        (
            HEAD + ONE + 'Unit_Diag_Area = 9-8\nValue(0) = "x"\nUnit_Diag_Area_End\n',
            5,
            "Unit_Diag_Area",
            "range '9-8' runs backwards",
        ),
        (
            HEAD + ONE + 'Unit_Diag_Area = 8-9\nText(0) = "x"\nUnit_Diag_Area_End\n',
            6,
            "Text(0)",
            'only Value(n) = "text" lines go in a Unit_Diag_Area',
        ),
        (
            HEAD + ONE + "Unit_Diag_Area_End\n",
            5,
            "Unit_Diag_Area_End",
            "closes a block that was never opened",
        ),
        (HEAD + ONE + 'Unit_Diag_Bit(x) = "t"\n', 5, "Unit_Diag_Bit(x)", "'x' is not a number"),
    ],
)
def test_errors_name_the_file_the_line_and_the_key(
    text: str, line: int, key: str, reason: str
) -> None:
    with pytest.raises(g.GsdError) as info:
        g.parse(text, "site/new.gsd")
    e = info.value
    assert (e.file, e.line, e.key, e.reason) == ("site/new.gsd", line, key, reason)
