"""The GSD corpus (tests/data/gsd/corpus): each file, the modules chosen, and the Chk_Cfg and
user parameter bytes worked out by hand from the GSD specification.

How the bytes are worked out (the same for every file):

* Chk_Cfg: the chosen modules' identifier bytes, one after another, as the Module lines
  write them.
* User parameter data (Set_Prm after the 7 standard bytes; with DPV1_Slave = 1 its first
  three bytes are DPV1_Status_1..3):
  - legacy file (no Ext keyword): User_Prm_Data_Len bytes, User_Prm_Data first, zeros after;
  - Ext keywords: the station's block runs to the last byte its Ext_User_Prm_Data_Const/_Ref
    lines cover; the constant bytes go in first, then each referenced ExtUserPrmData's
    default, big-endian for the 16/32-bit types, into its bits for Bit(b) and BitArea(f-l);
    each chosen module's block follows (Ext_Module_Prm_Data_Len bytes, else to the last
    byte it covers), worked the same way from the block's start. User_Prm_Data and
    User_Prm_Data_Len are not evaluated.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Final

CORPUS_DIR: Final = Path(__file__).resolve().parents[2] / "data" / "gsd" / "corpus"


@dataclass(frozen=True)
class Case:
    file: str
    modules: tuple[str, ...]
    cfg: bytes
    user_prm: bytes
    how: str  # the arithmetic behind ``user_prm``

    @property
    def path(self) -> Path:
        return CORPUS_DIR / self.file


CASES: Final[tuple[Case, ...]] = (
    Case(
        "compact_legacy.gsd",
        ("8 DI + 8 DO",),
        bytes.fromhex("10 20"),  # 0x10 1 byte in, 0x20 1 byte out
        bytes.fromhex("01 02 00 00"),
        "User_Prm_Data_Len = 4: User_Prm_Data 01 02, then two zero bytes",
    ),
    Case(
        "compact_ext.gsd",
        ("Control and speed, 2 words in/out",),
        bytes.fromhex("F1"),
        bytes.fromhex("21 00 32 FB 00"),
        "Const(0) = 5 zero bytes; byte 0: Bit(0) default 1 | BitArea(4-5) default 2 << 4 = "
        "0x21; bytes 1-2: Unsigned16 50 = 00 32; byte 3: Signed8 -5 = 0xFB; byte 4: 0",
    ),
    Case(
        "modular_ext_module_prm.gsd",
        ("DI 8 x 24 V", "AI 2 x 0-10 V", "DO 8 x 24 V / 0.5 A", "Empty slot"),
        bytes.fromhex("10 51 20 00"),
        bytes.fromhex("40 00 01 03 02 00 64 01"),
        "station 40 00 (Const; Bit(6) default 1 = 0x40 already); DI block of 2: 01 03 "
        "(Unsigned8 3 at 1); AI block of 3: 02 00 64 (Unsigned16 100 at 1); DO block of 1: "
        "BitArea(0-1) default 1 = 01; the empty slot: no block",
    ),
    Case(
        "mixed_legacy_ext.gsd",
        ("2 bytes in/out",),
        bytes.fromhex("31"),
        bytes.fromhex("00 10 02"),
        "the Ext entries alone: Const(0) 00 10 02, Unsigned8 default 2 at 2; the legacy "
        "User_Prm_Data AA BB CC DD (length 4) is not evaluated",
    ),
    Case(
        "odd_layout.gsd",
        ("Ausgänge 2 Wörter, Eingänge 2 Wörter",),
        bytes.fromhex("C0 41 41"),  # special format: 2 words out, 2 words in
        bytes.fromhex("08 64 00 00"),
        "Const(0) = 4 zero bytes (three continued lines); Bit(3) default 1 at 0 = 0x08; "
        "Unsigned8 default 0X64 at 1",
    ),
    Case(
        "rev1_compact.gsd",
        ("Counter, 2 words in",),
        bytes.fromhex("51"),
        bytes.fromhex("05 01"),
        "Const(0) 05 01; Unsigned8 default 1 (allowed 0,1,3) at 1 = 01",
    ),
    Case(
        "rev5_slots.gsd",
        ("AI short", "Totalizer"),
        bytes.fromhex("94 41 84 85"),
        bytes.fromhex("00 00 00 00 01"),
        "station: DPV1_Status_1..3 = 00 00 00; Totalizer block of 2: Const 00 01, "
        "Unsigned8 0 at 0, Unsigned8 1 at 1; AI short has no block",
    ),
    Case(
        "dpv1_drive.gsd",
        ("PKW, 4 words consistent", "PZD, 2 words"),
        bytes.fromhex("F3 71"),
        bytes.fromhex("80 20 00 01 F4"),
        "Const(0) 80 00 00 00 00; Bit(5) default 1 at 1 = 0x20 (DPV1_Status_2's diagnostic "
        "alarm); Unsigned16 500 at 3 = 01 F4",
    ),
    Case(
        "ref_before_const.gsd",
        ("Input 8 bytes", "Output 8 bytes"),
        bytes.fromhex("17 27"),
        bytes.fromhex("01 05 00"),
        "station: Const(0) 00 00 first, then Bit(0) default 1 at 0 and Unsigned8 5 at 1 = "
        "01 05 (the Ref lines come first in the file); Input block: to its last byte, "
        "Bit(7) default 0 = 00; Output: no block",
    ),
)
