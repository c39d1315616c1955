"""GSD files (the device data base of a DP slave): parse, render, and build a slave's setup.

Written from the GSD specification's facts (docs/devices.md, "GSD files"); the file format
is read in :mod:`adapters.profibus.codec.gsdparse`, the model is
:mod:`adapters.profibus.codec.gsdmodel`. What a master builds from a file:

* Chk_Cfg: the chosen modules' identifier bytes, one after another;
* the user parameter data (Set_Prm after the 7 standard bytes): with the Ext keywords
  (``ExtUserPrmData``, ``Ext_User_Prm_Data_Const/_Ref``, ``Max_User_Prm_Data_Len``) the
  station's block covers its placements, the constant bytes go in first and the defaults of
  the referenced parameters over them; each chosen module's block follows
  (``Ext_Module_Prm_Data_Len`` bytes, else up to its last placement, its own offsets); the
  whole is at most ``Max_User_Prm_Data_Len``. Without them, ``User_Prm_Data_Len`` bytes from
  ``User_Prm_Data``;
* DPV1_Slave = 1: the first three bytes of the user parameter data are DPV1_Status_1..3; the
  master sends its own DP-V1 status bytes (:class:`~adapters.profibus.codec.dp.SetPrm`) in
  their place.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from adapters.profibus.codec.chkcfg import decode_identifiers, total_input_bytes, total_output_bytes
from adapters.profibus.codec.gsdmodel import (
    BAUD_KEYS,
    DPV1_STATUS_BYTES,
    ENCODING,
    INT_KEYS,
    MAX_USER_PRM,
    STRING_KEYS,
    ExtUserPrmData,
    Gsd,
    GsdError,
    GsdModule,
    GsdSetupError,
    PrmPlacement,
    PrmText,
    SlotDef,
    UnitDiagArea,
    UnitDiagBit,
    station_prm_len,
    user_prm_bound,
)
from adapters.profibus.codec.gsdparse import decode, parse

__all__ = [
    "BAUD_KEYS",
    "DPV1_STATUS_BYTES",
    "ENCODING",
    "MAX_USER_PRM",
    "ExtUserPrmData",
    "Gsd",
    "GsdError",
    "GsdModule",
    "GsdSetup",
    "GsdSetupError",
    "PrmPlacement",
    "PrmText",
    "SlotDef",
    "UnitDiagArea",
    "UnitDiagBit",
    "build_setup",
    "check_user_prm",
    "decode",
    "default_user_prm",
    "match_modules",
    "parse",
    "render",
    "station_prm_len",
]

# ---------------------------------------------------------------------------- rendering


def render(gsd: Gsd) -> str:
    """GSD text that parses back to ``gsd`` (keys in a fixed order, names as the spec spells)."""
    out = ["#Profibus_DP", "; rendered by drive-gateway"]
    strings = dict(gsd.strings)
    out.extend(f'{spelled} = "{strings[k]}"' for k, spelled in STRING_KEYS.items() if k in strings)
    ints = dict(gsd.ints)
    out.extend(_int_line(k, spelled, ints[k]) for k, spelled in INT_KEYS.items() if k in ints)
    for baud, tsdr in gsd.baud_rates:
        out.append(f"{BAUD_KEYS[baud]}_supp = 1")
        if tsdr is not None:
            out.append(f"MaxTsdr_{BAUD_KEYS[baud]} = {tsdr}")
    if gsd.user_prm_data:
        out.append("User_Prm_Data = " + _hex_list(gsd.user_prm_data))
    for p in gsd.prm_texts:
        out.append(f"PrmText = {p.ref}")
        out.extend(f'Text({value}) = "{text}"' for value, text in p.texts)
        out.append("EndPrmText")
    for e in gsd.ext_user_prm:
        out.extend(_ext_lines(e))
    out.extend(_placement_line(p) for p in gsd.placements)
    for m in gsd.modules:
        out.extend(_module_lines(m))
    out.extend(_slot_lines(gsd.slots))
    out.extend(_diag_lines(gsd))
    return "\n".join(out) + "\n"


def _int_line(key: str, spelled: str, value: int) -> str:
    return f"{spelled} = 0x{value:04X}" if key == "ident_number" else f"{spelled} = {value}"


def _hex_list(data: bytes) -> str:
    return ",".join(f"0x{b:02X}" for b in data)


def _ext_lines(e: ExtUserPrmData) -> list[str]:
    lines = [f'ExtUserPrmData = {e.ref} "{e.name}"', _type_line(e)]
    if e.prm_text_ref is not None:
        lines.append(f"Prm_Text_Ref = {e.prm_text_ref}")
    if not e.changeable:
        lines.append("Changeable = 0")
    if not e.visible:
        lines.append("Visible = 0")
    return [*lines, "EndExtUserPrmData"]


def _type_line(e: ExtUserPrmData) -> str:
    head = {
        "bit": f"Bit({e.first_bit})",
        "bitarea": f"BitArea({e.first_bit}-{e.last_bit})",
    }.get(e.kind, e.data_type)
    span = ",".join(map(str, e.allowed)) if e.allowed else f"{e.minimum}-{e.maximum}"
    return f"{head} {e.default} {span}"


def _placement_line(p: PrmPlacement) -> str:
    if p.ref is None:
        return f"Ext_User_Prm_Data_Const({p.offset}) = {_hex_list(p.const)}"
    return f"Ext_User_Prm_Data_Ref({p.offset}) = {p.ref}"


def _module_lines(m: GsdModule) -> list[str]:
    lines = [f'Module = "{m.name}" {_hex_list(m.config)}']
    if m.reference is not None:
        lines.append(str(m.reference))
    if m.prm_len:
        lines.append(f"Ext_Module_Prm_Data_Len = {m.prm_len}")
    lines.extend(_placement_line(p) for p in m.placements)
    if m.f_parameters:
        lines.append("F_Ext_Module_Prm_Data_Len = 0 ; PROFIsafe parameters, not rendered")
    return [*lines, "EndModule"]


def _slot_lines(slots: Sequence[SlotDef]) -> list[str]:
    if not slots:
        return []
    lines = [
        f'Slot({s.number}) = "{s.name}" {s.default} {",".join(map(str, s.allowed))}' for s in slots
    ]
    return ["SlotDefinition", *lines, "EndSlotDefinition"]


def _diag_lines(gsd: Gsd) -> list[str]:
    lines = [
        f'Unit_Diag_{"Not_" if b.inverted else ""}Bit({b.bit}) = "{b.text}"'
        for b in gsd.unit_diag_bits
    ]
    for area in gsd.unit_diag_areas:
        lines.append(f"Unit_Diag_Area = {area.first}-{area.last}")
        lines.extend(f'Value({value}) = "{text}"' for value, text in area.values)
        lines.append("Unit_Diag_Area_End")
    return lines


# ---------------------------------------------------------------------------- a slave's setup


@dataclass(frozen=True)
class GsdSetup:
    """What a master sends a slave configured from a GSD (see :func:`build_setup`)."""

    ident_number: int
    cfg: bytes
    user_prm: bytes  # the whole user parameter data (with DPV1_Status_1..3 first if dpv1)
    input_len: int
    output_len: int
    dpv1: bool
    origin: str  # "GSD <file>, module 'x'" for events

    @property
    def user_prm_after_dpv1(self) -> bytes:
        """The user data after the DP-V1 status bytes (what :class:`SlaveParams` carries)."""
        return self.user_prm[DPV1_STATUS_BYTES:] if self.dpv1 else self.user_prm


def build_setup(
    gsd: Gsd, modules: Sequence[str], prm: Mapping[str, int | str] | None = None
) -> GsdSetup:
    """The Ident_Number, Chk_Cfg bytes and user parameter data of ``modules`` (by name).

    The user parameter data starts from the GSD's defaults (see the module docstring);
    ``prm`` sets single ExtUserPrmData values by name (a PrmText text or a number).
    """
    chosen = [_find_module(gsd, name) for name in modules]
    _check_modules(gsd, chosen)
    cfg = b"".join(m.config for m in chosen)
    ids = decode_identifiers(cfg)
    data, slots = default_user_prm(gsd, chosen)
    for name, value in (prm or {}).items():
        _set_prm(gsd, data, slots, name, value)
    names = ", ".join(repr(m.name) for m in chosen)
    label = "module" if len(chosen) == 1 else "modules"
    return GsdSetup(
        ident_number=gsd.ident_number,
        cfg=cfg,
        user_prm=bytes(data),
        input_len=total_input_bytes(ids),
        output_len=total_output_bytes(ids),
        dpv1=gsd.dpv1,
        origin=f"GSD {gsd.path}, {label} {names}",
    )


def _find_module(gsd: Gsd, name: str) -> GsdModule:
    module = gsd.module(name)
    if module is None:
        known = ", ".join(repr(m.name) for m in gsd.modules)
        raise GsdSetupError("module", f"{name!r} is not a module of {gsd.path} (it has {known})")
    return module


def _check_modules(gsd: Gsd, chosen: Sequence[GsdModule]) -> None:
    if not chosen:
        raise GsdSetupError("module", "no module chosen")
    if not gsd.modular and len(chosen) != 1:
        raise GsdSetupError(
            "modules", f"{gsd.path} is not a modular station (Modular_Station = 0): one module"
        )
    most = gsd.get("max_module")
    if gsd.modular and most is not None and len(chosen) > most:
        raise GsdSetupError("modules", f"{len(chosen)} modules, the GSD allows Max_Module = {most}")
    _check_sizes(gsd, chosen)
    _check_slots(gsd, chosen)
    _check_user_prm_len(gsd, chosen)
    for m in chosen:
        if m.f_parameters:
            raise GsdSetupError(
                "modules",
                f"module {m.name!r} carries PROFIsafe F-parameters (F_ keys), which the "
                "gateway does not build",
            )


def _check_sizes(gsd: Gsd, chosen: Sequence[GsdModule]) -> None:
    ins = sum(m.input_bytes for m in chosen)
    outs = sum(m.output_bytes for m in chosen)
    for key, have, label in (
        ("max_input_len", ins, "input"),
        ("max_output_len", outs, "output"),
        ("max_data_len", ins + outs, "input and output"),
    ):
        limit = gsd.get(key)
        if limit is not None and have > limit:
            raise GsdSetupError(
                "modules",
                f"{have} bytes of {label} data, the GSD allows {INT_KEYS[key]} = {limit}",
            )


def _check_slots(gsd: Gsd, chosen: Sequence[GsdModule]) -> None:
    """With a SlotDefinition, the n-th chosen module goes in the n-th slot (by number) and
    must be one of the slot's allowed modules (by reference number)."""
    if not gsd.slots:
        return
    slots = sorted(gsd.slots, key=lambda s: s.number)
    if len(chosen) > len(slots):
        raise GsdSetupError(
            "modules", f"{len(chosen)} modules, the GSD's SlotDefinition has {len(slots)} slots"
        )
    for slot, m in zip(slots, chosen, strict=False):
        if m.reference not in slot.allowed:
            allowed = ", ".join(repr(x.name) for x in gsd.modules if x.reference in slot.allowed)
            raise GsdSetupError(
                "modules",
                f"module {m.name!r} is not allowed in slot {slot.number} {slot.name!r} "
                f"(allowed: {allowed})",
            )


def _check_user_prm_len(gsd: Gsd, chosen: Sequence[GsdModule]) -> None:
    have = station_prm_len(gsd) + sum(m.prm_len for m in chosen)
    most, label = user_prm_bound(gsd)
    if have > min(most, MAX_USER_PRM):
        raise GsdSetupError("modules", f"{have} bytes of user parameters, the GSD allows {label}")


@dataclass(frozen=True)
class _Slot:
    offset: int
    ext: ExtUserPrmData
    where: str


def default_user_prm(gsd: Gsd, chosen: Sequence[GsdModule]) -> tuple[bytearray, list[_Slot]]:
    """The user parameter data with every default in place, and where each named
    parameter sits."""
    size = station_prm_len(gsd)
    slots: list[_Slot] = []
    if gsd.ext_prm:
        data = bytearray(size)
        _apply(gsd, data, 0, gsd.placements, slots=slots, where="station")
    else:
        data = bytearray(bytes(gsd.user_prm_data[:size]).ljust(size, b"\0"))
    for m in chosen:
        base = len(data)
        data.extend(bytes(m.prm_len))
        _apply(gsd, data, base, m.placements, slots=slots, where=f"module {m.name!r}")
    return data, slots


def _apply(
    gsd: Gsd,
    data: bytearray,
    base: int,
    placements: Iterable[PrmPlacement],
    *,
    slots: list[_Slot],
    where: str,
) -> None:
    """The constant bytes first, then the referenced parameters' defaults over them."""
    placements = tuple(placements)
    for p in placements:
        if p.ref is None:
            data[base + p.offset : base + p.offset + len(p.const)] = p.const
    for p in placements:
        ext = None if p.ref is None else gsd.ext(p.ref)
        if ext is not None:  # a reference to no definition is refused at parse time
            ext.put(data, base + p.offset, ext.default)
            slots.append(_Slot(base + p.offset, ext, where))


def _set_prm(gsd: Gsd, data: bytearray, slots: list[_Slot], name: str, value: int | str) -> None:
    matching = [s for s in slots if s.ext.name.casefold() == name.casefold()]
    if not matching:
        known = ", ".join(sorted({repr(s.ext.name) for s in slots})) or "none"
        raise GsdSetupError(
            f"prm.{name}", f"not a user parameter of the chosen module(s) (known: {known})"
        )
    for slot in matching:
        number = _prm_value(gsd, slot.ext, name, value)
        slot.ext.put(data, slot.offset, number)


def _prm_value(gsd: Gsd, ext: ExtUserPrmData, name: str, value: int | str) -> int:
    texts = gsd.prm_text(ext.prm_text_ref)
    if isinstance(value, str):
        found = texts.value_of(value) if texts is not None else None
        if found is None:
            choices = ", ".join(repr(t) for _, t in texts.texts) if texts else "numbers only"
            raise GsdSetupError(f"prm.{name}", f"{value!r} is not one of its texts ({choices})")
        value = found
    if isinstance(value, bool) or not ext.accepts(value):
        span = ",".join(map(str, ext.allowed)) if ext.allowed else f"{ext.minimum}-{ext.maximum}"
        raise GsdSetupError(f"prm.{name}", f"{value!r} is outside its range {span}")
    if not ext.changeable and value != ext.default:
        raise GsdSetupError(
            f"prm.{name}", f"the GSD fixes it (Changeable = 0) at its default {ext.default}"
        )
    return value


def check_user_prm(gsd: Gsd, chosen: Sequence[GsdModule], data: bytes) -> str | None:
    """Why ``data`` (the whole user parameter data) is not valid for ``chosen``; None if it is."""
    expected, slots = default_user_prm(gsd, chosen)
    if len(data) != len(expected):
        return f"{len(data)} bytes of user parameters, the GSD gives {len(expected)}"
    for slot in slots:
        value = slot.ext.get(data, slot.offset)
        if not slot.ext.accepts(value):
            return f"{slot.ext.name!r} = {value} is outside its range"
    return None


def match_modules(gsd: Gsd, cfg: bytes) -> tuple[GsdModule, ...] | None:
    """The modules whose identifier bytes, one after another, are ``cfg`` (None: no match)."""
    if not cfg:
        return None
    for m in sorted(gsd.modules, key=lambda m: -len(m.config)):
        if cfg.startswith(m.config):
            if len(m.config) == len(cfg):
                return (m,)
            rest = match_modules(gsd, cfg[len(m.config) :])
            if rest is not None:
                return (m, *rest)
    return None
