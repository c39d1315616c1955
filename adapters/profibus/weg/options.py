"""The WEG profile's keys of a drive's config table (docs/devices.md lists them)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from adapters.profibus.weg.spec import FRAME20_INPUTS, FRAME20_WORDS, DataProfile, ModelSpec

if TYPE_CHECKING:
    from gateway.schema import Table

PARAM_MAX: Final = 1199  # P0742-P0757 range "0 a 1199": the highest parameter number
RECORDS: Final = (47, 48)  # PROFIdrive (4.2.4) or WEG (4.2.6) parameter access


@dataclass(frozen=True)
class WegOptions:
    """A WEG drive's profile options; every default matches the drive's factory setting."""

    data_profile: DataProfile = DataProfile.MANUFACTURER  # P0741 factory setting 1
    frame: int = 1  # PROFIdrive frame type 1 or 20 (CFW-11 only)
    words: int = 2  # I/O words (P0922 / P751 factory setting 1 = 2 words)
    words_in: tuple[int, ...] = ()  # parameters of input words 3.. (P0742..)
    words_out: tuple[int, ...] = ()  # parameters of output words 3.. (P0750.. / P746..)
    out_values: tuple[int, ...] = ()  # raw value sent in each output word until written
    param_record: int = 47  # DP-V1 record for parameter access: 47 or 48
    param_slot: int = 0  # WEG 4.2.3: slot 0
    startup_params: tuple[tuple[int, int], ...] = ()  # (number, raw value), in order
    sync_rpm: float | None = None  # 13-bit base (8192); None: from P0402/P0403 at connect
    max_rpm: float | None = None  # PROFIdrive base (4000h); None: P0134 at connect
    rated_hz: float | None = None  # None: P0403 at connect
    rated_rpm: float | None = None  # None: P0402 at connect
    rated_current_a: float | None = None  # None: P0401 at connect (frame 20, %FLC)
    rated_power_kw: float | None = None  # None: P0404 at connect (frame 20)
    ident_number: int | None = None  # None: the model's default (see docs/devices.md)
    verify_mapping: bool = True  # read P0741, P0922/P751 and the word mapping at connect
    reset_pulse: float = 0.1  # s the fault-reset bit stays set (at least one telegram)
    at_reference_band: float = 1.0  # % of the speed base: "at reference" tolerance
    record_retries: int = 20  # DS_Read retries while the answer is not ready (C3h)
    record_retry_delay: float = 0.02  # s between those retries
    second_ramp: bool = False  # P0684 bit 5: the second ramp P0102/P0103 (manufacturer)
    factory_settings: tuple[tuple[int, int], ...] = ()  # (number, raw): the drive's own

    def mapped_in(self) -> tuple[int, ...]:
        """Parameter of each input word 3..N (0 = disabled), padded to the telegram size."""
        return _padded(self.words_in, self.words)

    def mapped_out(self) -> tuple[int, ...]:
        return _padded(self.words_out, self.words)

    def out_value_of(self, index: int) -> int:
        return self.out_values[index] if index < len(self.out_values) else 0


def _padded(mapping: tuple[int, ...], words: int) -> tuple[int, ...]:
    return mapping + (0,) * (words - 2 - len(mapping))


def _optional_positive(t: Table, key: str, maximum: float) -> float | None:
    value: float | None = t.number(key, None, minimum=1e-6, maximum=maximum)
    return value


def parse_options(t: Table, spec: ModelSpec) -> WegOptions:
    """Read the profile's keys of a drive table; errors name the key and the reason."""
    d = WegOptions()
    name = spec.device.value
    profile = t.enum("data_profile", DataProfile, d.data_profile)
    if profile not in spec.profiles:
        raise t.error(
            "data_profile", f"the {name} manual has no PROFIdrive profile (no P0741 in it)"
        )
    frame = t.integer(
        "frame", 1, allowed=(1, 20) if spec.frame20 else (1,), what=f"a {name} frame type"
    )
    if frame == 20 and profile is not DataProfile.PROFIDRIVE:
        raise t.error("frame", "frame type 20 is a PROFIdrive frame (data_profile = profidrive)")
    words_default = FRAME20_WORDS if frame == 20 else d.words
    n_words: int = t.integer("words", words_default, minimum=2, maximum=spec.max_words)
    if frame == 20 and n_words != FRAME20_WORDS:
        raise t.error("words", f"frame type 20 takes {FRAME20_WORDS} words (P0922 = 5)")
    words_in = t.int_list("words_in", (), minimum=0, maximum=PARAM_MAX)
    words_out = t.int_list("words_out", (), minimum=0, maximum=PARAM_MAX)
    for key, mapping in (("words_in", words_in), ("words_out", words_out)):
        if len(mapping) > n_words - 2:
            raise t.error(key, f"{len(mapping)} entries for words 3..{n_words} ({n_words - 2})")
    if frame == 20:
        words_in, words_out = _frame20_mapping(t, words_in, words_out)
    out_values = t.int_list("out_values", (), minimum=-32768, maximum=0xFFFF)
    if len(out_values) != len(words_out):
        raise t.error(
            "out_values",
            f"gives {len(out_values)} values for {len(words_out)} words_out entries "
            "(one raw value per output word: the drive writes it into the parameter)",
        )
    second_ramp = t.boolean("second_ramp", d.second_ramp)
    if second_ramp and profile is not DataProfile.MANUFACTURER:
        raise t.error(
            "second_ramp",
            "the second ramp is P0684 bit 5 of the manufacturer profile; the PROFIdrive "
            "STW1 has no such bit (bit 5 reserved)",
        )
    options = WegOptions(
        data_profile=profile,
        frame=frame,
        words=n_words,
        words_in=tuple(words_in),
        words_out=tuple(words_out),
        out_values=tuple(out_values),
        param_record=t.integer("param_record", d.param_record, allowed=RECORDS, what="a record"),
        param_slot=t.integer("param_slot", d.param_slot, minimum=0, maximum=254),
        startup_params=_startup_params(t),
        sync_rpm=_optional_positive(t, "sync_rpm", 100000.0),
        max_rpm=_optional_positive(t, "max_rpm", 100000.0),
        rated_hz=_optional_positive(t, "rated_hz", 1000.0),
        rated_rpm=_optional_positive(t, "rated_rpm", 100000.0),
        rated_current_a=_optional_positive(t, "rated_current_a", 100000.0),
        rated_power_kw=_optional_positive(t, "rated_power_kw", 100000.0),
        ident_number=t.integer("ident_number", None, minimum=0, maximum=0xFFFF),
        verify_mapping=t.boolean("verify_mapping", d.verify_mapping),
        reset_pulse=t.number("reset_pulse", d.reset_pulse, minimum=0.0, maximum=10.0),
        at_reference_band=t.number(
            "at_reference_band", d.at_reference_band, minimum=0.0, maximum=100.0
        ),
        record_retries=t.integer("record_retries", d.record_retries, minimum=0, maximum=1000),
        record_retry_delay=t.number(
            "record_retry_delay", d.record_retry_delay, minimum=0.0, maximum=5.0
        ),
        second_ramp=second_ramp,
        factory_settings=_factory_settings(t, spec),
    )
    return options


def _frame20_mapping(
    t: Table, words_in: tuple[int, ...], words_out: tuple[int, ...]
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Frame 20 fixes words 3-6: P0760-P0763 in, nothing out (CFW-11 Table 3.6)."""
    if words_in and tuple(words_in) != FRAME20_INPUTS:
        raise t.error("words_in", f"frame type 20 reads {list(FRAME20_INPUTS)} in words 3-6")
    if any(words_out):
        raise t.error("words_out", "frame type 20 has P0750-P0753 = 0 (no output words)")
    return FRAME20_INPUTS, ()


def _factory_settings(t: Table, spec: ModelSpec) -> tuple[tuple[int, int], ...]:
    """``[...drives.factory_settings]``: the drive's factory values of the parameters its
    manual says must keep them (CFW320 2.4: P308, P310, P311, P312), where they are not
    the ones the gateway takes (docs/devices.md)."""
    out = _param_values(t, "factory_settings")
    for number, _ in out:
        if number not in spec.factory_settings:
            named = ", ".join(spec.pname(n) for n in spec.factory_settings) or "none"
            raise t.table("factory_settings").error(
                spec.pname(number),
                f"not a parameter the {spec.device.value} manual says must keep its factory "
                f"setting ({named})",
            )
    return out


def _startup_params(t: Table) -> tuple[tuple[int, int], ...]:
    """``[...drives.startup_params]``: "P0313" = 1 (or "313" = 1), written at every connect."""
    return _param_values(t, "startup_params")


def _param_values(t: Table, table: str) -> tuple[tuple[int, int], ...]:
    """A table of "P0313" = 1 (or "313" = 1) entries, in order."""
    sub = t.table(table)
    out: list[tuple[int, int]] = []
    for key in sub.data:
        text = key[1:] if key[:1] in ("P", "p") else key
        if not text.isdigit() or not 0 < int(text) <= PARAM_MAX:
            raise sub.error(key, f"{key!r} is not a parameter number (like P0313 or 313)")
        value: int = sub.integer(key, minimum=-32768, maximum=0xFFFF)
        out.append((int(text), value))
    numbers = [n for n, _ in out]
    if len(set(numbers)) != len(numbers):
        raise t.error(table, "names a parameter twice")
    return tuple(out)
