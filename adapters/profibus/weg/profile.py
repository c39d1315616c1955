"""The DP profile shared by the WEG CFW-11, CFW700 and CFW320 (raw words <-> drive model).

One instance per configured drive. The model's differences come from its
:class:`~adapters.profibus.weg.spec.ModelSpec`; :mod:`.cfw11`, :mod:`.cfw700` and
:mod:`.cfw320` only name the spec.

Cyclic words (telegram of ``words`` 16-bit words, big-endian, both directions):

* word 1 out: control word (P0684 manufacturer / P0967 PROFIdrive); in: status word
  (P0680 / P0968);
* word 2 out: speed reference (P0685 13 bits / 4000h = P0134); in: motor speed (P0681 / same);
* words 3..N: the parameters the drive is programmed with (P0742.. in, P0750.. / P746.. out).

Words 1 and 2 are the data profile's (P0741): the profile holds the one its config names,
from :data:`DATA_WORDS` (:mod:`.manufacturer`, :mod:`.profidrive`); words 3..N are read by
:mod:`.mapped`, the drive's programming is checked at connect by :mod:`.programming`.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any, ClassVar, Final

from adapters.profibus.codec.chkcfg import CompactId, IoDirection
from adapters.profibus.contract import (
    AddressRange,
    DiagEvent,
    DiagKind,
    DpProfileBase,
    EventSink,
    RecordChannel,
    SlaveSetup,
)
from adapters.profibus.errors import DecodeFailure, ProfibusDecodeError
from adapters.profibus.weg import words as w
from adapters.profibus.weg.dataprofile import DataProfileWords, Order, Sent
from adapters.profibus.weg.manufacturer import ManufacturerWords
from adapters.profibus.weg.mapped import Mapped, read_mapped
from adapters.profibus.weg.options import WegOptions, parse_options
from adapters.profibus.weg.paramtable import PARAM_TABLES
from adapters.profibus.weg.profidrive import ProfidriveWords
from adapters.profibus.weg.programming import (
    DataProfilePending,
    DriveProgrammingMismatch,
    check_data_profile,
    check_factory_settings,
    expected_programming,
    verify_programming,
    write_startup_param,
)
from adapters.profibus.weg.records import RecordParams
from adapters.profibus.weg.scales import Ratings, SpeedBase
from adapters.profibus.weg.spec import (
    NEUTRAL_STOP_WORD,
    SIGNED,
    DataProfile,
    ModelSpec,
    failsafe_of,
    failsafe_warning,
    scaled,
)
from gateway.adapter import Capabilities, ParamValue
from gateway.errors import ParameterError
from gateway.model import DesiredCommand, Device, Readings

if TYPE_CHECKING:
    from gateway.config import DriveConfig
    from gateway.schema import Table

log = logging.getLogger(__name__)

DATA_WORDS: Final[Mapping[DataProfile, Callable[[ModelSpec], DataProfileWords]]] = {
    DataProfile.MANUFACTURER: ManufacturerWords,
    DataProfile.PROFIDRIVE: ProfidriveWords,
}
"""The words of each data profile (P0741), for a model's spec."""

_OutMemory = tuple[bool, int | None, bool, Sent]
"""What ``outputs`` reads and writes of a profile's memory: stop held, the reset counter
seen, the pulse sent, the last telegram's ``_sent``."""


def _copy_readings(readings: Readings) -> Readings:
    """A copy the caller may keep or change (``values`` is the one nested dict)."""
    copy = readings.copy()
    values = readings.get("values")
    if values is not None:
        copy["values"] = dict(values)
    return copy


class WegProfile(DpProfileBase):
    """DpProfile of a WEG drive on Profibus DP (see the module docstring)."""

    device: ClassVar[Device]
    spec: ClassVar[ModelSpec]
    addresses: ClassVar[AddressRange]  # from the spec, set for each subclass
    # the drive's reaction to a lost master (P0313) needs the DP watchdog: with it off the
    # drive never detects the loss (the adapter publishes failsafe false then)
    failsafe_needs_watchdog: ClassVar[bool] = True
    # Clear: the manuals give A138/F238 per P0313 and nothing on the outputs (all zero in
    # Clear); taken as not applied, as the simulator does (decision 0091)
    outputs_in_clear: ClassVar[str] = (
        "in Clear a WEG drive takes no outputs (its P0313 acts: A138/F238), so no client's "
        "stop would reach it while one drive's lost client holds the line in Clear"
    )

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        spec: ModelSpec | None = cls.__dict__.get("spec")
        if spec is not None:
            low, high = spec.address_range
            cls.addresses = AddressRange(low, high, spec.address_source)

    @classmethod
    def telegram_keys(cls, input_bytes: int, output_bytes: int) -> tuple[str, ...]:
        """``words`` for a telegram of other than 2 words in and out (P0922 / P751)."""
        if input_bytes == output_bytes and input_bytes != 4:
            return (f"words = {input_bytes // 2}",)
        return ()

    @classmethod
    def telegram_text(cls, options: Any) -> str:
        """The telegram words (P0922 / P751), or frame 20 on a CFW-11."""
        if not isinstance(options, WegOptions):
            return super().telegram_text(options)
        if options.frame == 20:
            return f"frame 20, {options.words} words (P0922 = 5)"
        return f"words = {options.words}, P0922 (CFW320: P751) = {options.words - 1}"

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> WegOptions:
        return parse_options(table, cls.spec)

    @classmethod
    def safety_warnings(cls, drive: DriveConfig, watchdog: float) -> list[str]:
        """``check-config``: the drive's reaction to a lost master from the config alone
        (the DP watchdog, P0313 as ``startup_params`` writes it; :func:`.spec.failsafe_warning`)."""
        opts = drive.options if isinstance(drive.options, WegOptions) else WegOptions()
        p0313 = dict(opts.startup_params).get(313)
        text = failsafe_warning(cls.spec, p0313, watchdog)
        return [] if text is None else [text]

    def __init__(self, drive: DriveConfig) -> None:
        opts = drive.options if isinstance(drive.options, WegOptions) else WegOptions()
        self.drive = drive
        self.options = opts
        self.params = RecordParams(
            opts.param_record, opts.param_slot, opts.record_retries, opts.record_retry_delay
        )
        self.in_map = opts.mapped_in()
        self.out_map = opts.mapped_out()
        self.out_values = [w.to_word(opts.out_value_of(i)) for i in range(len(self.out_map))]
        self.data_words: DataProfileWords = DATA_WORDS[opts.data_profile](self.spec)
        self.ratings = Ratings(
            rated_hz=opts.rated_hz,
            rated_rpm=opts.rated_rpm,
            sync_rpm=opts.sync_rpm,
            max_rpm=opts.max_rpm,
            rated_current_a=opts.rated_current_a,
            rated_power_kw=opts.rated_power_kw,
        )
        self.base: SpeedBase | None = self._speed_base(self.ratings)
        self._reset_seen: int | None = None
        self._pulse_until: float | None = None
        self._pulse_sent = False
        self._sent = Sent()
        self._zsw: w.ProfidriveStatus | None = None
        self._faulted = False
        self._alarm = False
        self._polled_fault: int | None = None
        self._polled_alarm: int | None = None
        self.control_type: int | None = None  # P0202 as read at connect (CFW-11, CFW700)
        self._reported_type: int | None = None  # the last P0202 taken
        self._event: EventSink | None = None
        self._stop_held = False  # a quick/coast stop seen: no run until run and JOG seen off
        self._p0741_seen: int | None = None  # P0741 read in this data exchange (not yet: None)
        self._status_values: dict[str, int] = {}  # P0680 bits of the last status word
        self._factory_values: dict[str, int] = {}  # CFW320 P308, P310-P312 read at connect
        # inputs' fast path: (key, the memory the call left, its readings)
        self._inputs_memo: tuple[tuple[object, ...], tuple[object, ...], Readings] | None = None
        # outputs' fast path: (key, the memory before the call, the memory after, telegram)
        self._outputs_memo: tuple[tuple[object, ...], _OutMemory, _OutMemory, bytes] | None = None

    # ------------------------------------------------------------------ setup

    def setup(self) -> SlaveSetup:
        """Ident number, one consistent word identifier for the I/O words, no user data.

        The manuals give the telegram sizes (P0922 / P751) but not the GSD modules: we
        send one compact identifier ``F0h + words - 1`` (words in and out, consistent),
        the form of the fact sheet's 0xF1 for telegram 1 (1.7).
        """
        n = self.options.words
        cfg = CompactId(IoDirection.INPUT_OUTPUT, n, words=True, consistent=True).encode()
        ident = self.options.ident_number
        return SlaveSetup(
            ident_number=self.spec.default_ident if ident is None else ident,
            cfg=cfg,
            user_prm=b"",
            input_len=2 * n,
            output_len=2 * n,
            dpv1=True,
        )

    def capabilities(self) -> Capabilities:
        """The CFW320 has no quick stop (P684 bit 6 "Reserved", Table 4.3): a quick stop is
        its ramp stop (bit 0 = 0), the nearest controlled stop it has (docs/devices.md; a
        coast stop would leave an overhauling load without torque). The hub substitutes it
        and says so once (issue 32 item 4); it is never refused."""
        substitutes: dict[str, str] = {}
        if not self.spec.quick_stop:
            substitutes["quick_stop"] = "run"
        scale = None if self.base is None else self.base.scale()
        # alarm texts of the model's manual (CFW-11 section 5, CFW700 6, CFW320 7)
        return Capabilities(
            speed_scale=scale,
            alarm_texts=self.spec.alarms,
            params=PARAM_TABLES[self.spec.device],  # the manual's parameter table
            stop_substitutes=substitutes,
        )

    # ------------------------------------------------------------------ connect

    async def on_connect(self, channel: RecordChannel, event: EventSink) -> Readings:
        """Write ``startup_params``, check the drive's programming, read the scales and the
        drive's reaction to a lost master (P0313).

        A written P0741 or telegram size is in force only after the drive left cyclic data
        (:class:`DataProfilePending`: the adapter re-parameterises the slave). P0741 is
        checked at every connect, ``verify_mapping`` or not (issue 32 item 2); until then
        the adapter sends :meth:`unconfigured_outputs`, a stop in both data profiles.
        """
        # P0741 first: the value in force is the one read right after Set_Prm
        p0741 = await self._read_data_profile(channel) if self.spec.reads_data_profile else None
        offline_taken = {741, self.spec.telegram_param}
        written: list[int] = []
        for number, value in self.options.startup_params:
            if await write_startup_param(self.params, channel, event, self.spec, (number, value)):
                written += [number] if number in offline_taken else []
        if written:
            names = ", ".join(self.spec.pname(n) for n in written)
            raise DataProfilePending(
                f"{names} written: the drive takes it only without cyclic data, "
                "the slave is parameterised again"
            )
        if p0741 is not None:
            check_data_profile(self.spec, self.options.data_profile, p0741)
        if self.options.verify_mapping:
            expected = expected_programming(self.spec, self.options, self.in_map, self.out_map)
            await verify_programming(self.params, channel, self.spec, expected)
        await self._read_ratings(channel)
        self._factory_values = await check_factory_settings(
            self.params, channel, event, self.spec, self.options
        )
        self._event = event
        if self.spec.reads_control_type:
            self._set_control_type(await self.params.read(channel, 202))
        p0313, p0206 = await self.params.read_many(channel, [(313, 0), (206, 0)])
        failsafe, failsafe_text = failsafe_of(self.spec, p0313, p0206)
        changes: Readings = {
            "speed_base": None if self.base is None else self.base.label,
            "failsafe": failsafe,
            "failsafe_text": failsafe_text,
        }
        if self.control_type is not None or self._factory_values:
            changes["values"] = self._own_values()
        return changes

    def unconfigured_outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The telegram while the drive is not configured (its P0741 not verified): the
        control word :data:`~.spec.NEUTRAL_STOP_WORD`, a stop without JOG in both data
        profiles, and a zero reference (issue 32 item 2). The cyclic parameter words are
        the configured ones (no motion); nothing of the output memory is touched."""
        words = [NEUTRAL_STOP_WORD, 0, *self.out_values]
        return struct.pack(f">{len(words)}H", *words)

    # ------------------------------------------------------------------ P0202

    @property
    def quick_stop_as_ramp(self) -> bool:
        """True when a quick stop is sent as a ramp stop (P0202 V/f or VVW, see spec)."""
        ct = self.control_type
        return ct is not None and self.spec.quick_stop_as_ramp(ct)

    def _set_control_type(self, raw: int) -> None:
        """Take P0202 (read at connect or written): says once when quick stop falls back."""
        before = self._reported_type is not None and self.spec.quick_stop_as_ramp(
            self._reported_type
        )
        self.control_type = self._reported_type = raw
        what = self.spec.control_type_text(raw)
        if self.quick_stop_as_ramp == before:
            log.debug("%s: %s", self.drive.id, what)
            return
        if self.quick_stop_as_ramp:
            text = f"quick stop falls back to ramp stop: {what}"
        else:
            text = f"quick stop is the drive's quick stop again: {what}"
        log.warning("%s: %s", self.drive.id, text)
        if self._event is not None:
            self._event(
                text, DiagKind.SAFETY, control_type=raw, quick_stop_as_ramp=self.quick_stop_as_ramp
            )

    def _own_values(self) -> dict[str, float | int]:
        """The profile's entries of ``DriveState.values`` (docs/devices.md)."""
        own: dict[str, float | int] = dict(self._factory_values)
        if self.control_type is not None:
            own[self.spec.pname(202)] = self.control_type
            own["quick_stop_as_ramp"] = int(self.quick_stop_as_ramp)
        return own

    async def _read_data_profile(self, channel: RecordChannel) -> int:
        """P0741 as read at this connect. The first value read after the slave entered data
        exchange is the one in force; a later read of another value (changed at the HMI
        while this master exchanges cyclic data) is not in force before the drive leaves
        data exchange ([11] l.959-961, [700] l.922-924): :class:`DataProfilePending`."""
        got = await self.params.read(channel, 741)
        seen = self._p0741_seen
        if seen is None:
            self._p0741_seen = got  # the value in force: read first after Set_Prm
        elif got != seen:
            raise DataProfilePending(
                f"{self.spec.pname(741)} changed from {seen} to {got} during cyclic data: "
                "the slave is parameterised again"
            )
        return got

    def _rating_params(self) -> dict[str, int]:
        """Ratings field -> parameter, for what the config leaves to the drive.

        P0134 is read in both profiles: the PROFIdrive base, and the limit of the 13-bit
        references (the drive limits the speed to P0134 whatever the word says).
        """
        r, need = self.ratings, {}
        if r.max_rpm is None:
            need["max_rpm"] = 134
        need.update(self.data_words.rating_params(r))
        if self.options.frame == 20:
            if r.rated_current_a is None:
                need["rated_current_a"] = 401
            if r.rated_power_kw is None:
                need["rated_power_kw"] = 404
        return need

    async def _read_ratings(self, channel: RecordChannel) -> None:
        need = self._rating_params()
        if need:
            raws = await self.params.read_many(channel, [(n, 0) for n in need.values()])
            read = {
                key: float(scaled(n, raw)) for (key, n), raw in zip(need.items(), raws, strict=True)
            }
            for key, value in read.items():
                if value <= 0:
                    raise DriveProgrammingMismatch(
                        f"{self.spec.pname(need[key])} = {value:g}: no scale can be derived"
                    )
            self.ratings = replace(self.ratings, **read)
        self.base = self._speed_base(self.ratings)

    def _speed_base(self, r: Ratings) -> SpeedBase | None:
        """The speed word's base from the ratings known so far (None: not yet)."""
        suffix = " (configured)" if self.data_words.base_configured(self.options) else ""
        return self.data_words.speed_base(r, suffix)

    # ------------------------------------------------------------------ outputs

    def outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The output telegram for ``desired`` (called on every Data_Exchange reply).

        Fast path: cycle after cycle the desired command is the same. The telegram is a
        function of the command, of the speed base, P0202, the last PROFIdrive status and
        the cyclic parameter words, and of the profile's output memory (stop held, the
        reset counter seen, the last telegram's ``_sent``); of ``now`` only while a reset
        pulse runs. When all of those equal a call's with no pulse before or after it,
        that call's telegram and memory are taken again without encoding
        (``tests/profibus/weg/test_outputs_fast_path.py`` checks both paths).
        """
        if self._pulse_until is None:
            key = (desired, self.base, self.control_type, self._zsw, *self.out_values)
            memory = self._outputs_memory()
            memo = self._outputs_memo
            if memo is not None and memo[0] == key and memo[1] == memory:
                self._stop_held, self._reset_seen, self._pulse_sent, self._sent = memo[2]
                return memo[3]
            telegram = self._encode_outputs(desired, now)
            if self._pulse_until is None:  # no pulse started: nothing depended on now
                self._outputs_memo = (key, memory, self._outputs_memory(), telegram)
            return telegram
        return self._encode_outputs(desired, now)

    def _outputs_memory(self) -> _OutMemory:
        """What :meth:`_encode_outputs` reads or writes of the profile's own state (with
        ``_pulse_until`` None: the fast path's condition)."""
        return (self._stop_held, self._reset_seen, self._pulse_sent, self._sent)

    def _encode_outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The general path of :meth:`outputs`."""
        reset = self._reset_pulse(desired.fault_reset_seq, now)
        run, jog = self._run_jog(desired)
        order = Order(
            desired,
            run,
            jog,
            reset,
            self._reference(desired),
            self.quick_stop_as_ramp,
            self._zsw,
            self.options.second_ramp,
        )
        control, reference, self._sent = self.data_words.control(order)
        words = [control, w.to_word(reference), *self.out_values]
        return struct.pack(f">{len(words)}H", *words)

    def _reset_pulse(self, seq: int, now: float) -> bool:
        """One reset pulse each time ``fault_reset_seq`` grows; never repeated on its own.

        The bit is held for ``reset_pulse`` seconds and at least one telegram, then dropped.
        The first telegram after start or a communication loss adopts the counter as seen.
        """
        if self._reset_seen is None:
            self._reset_seen = seq
        elif seq > self._reset_seen:
            self._reset_seen = seq
            self._pulse_until = now + self.options.reset_pulse
            self._pulse_sent = False
        if self._pulse_until is None:
            return False
        if not self._pulse_sent or now < self._pulse_until:
            self._pulse_sent = True
            return True
        self._pulse_until = None
        return False

    def _reference(self, desired: DesiredCommand) -> int:
        """Speed magnitude (and sign) asked for, as a raw word of the speed scale."""
        if self.base is None:
            return 0
        return self.base.to_raw(desired.speed_rpm, desired.speed_pct)

    def _run_jog(self, d: DesiredCommand) -> tuple[bool, bool]:
        """Run and JOG as sent: off with a quick or coast stop, and after its release until
        the desired command has had run and JOG off (safety rule 1: the release of a stop
        never restarts the motor on a run that was asked before it). A stop whose desired
        command has run and JOG off (the hub clears them) holds nothing: the next run is new.
        """
        if d.quick_stop or d.coast_stop:
            self._stop_held = d.run or d.jog
        elif not d.run and not d.jog:
            self._stop_held = False
        if self._stop_held:
            return False, False
        return d.run, d.jog

    # ------------------------------------------------------------------ inputs

    def inputs(self, data: bytes, now: float) -> Readings:
        """The readings of one input telegram.

        Fast path: a drive at rest sends the same telegram cycle after cycle, and the
        readings are a function of the telegram, of what the last outputs asked for
        (``_sent``), of the speed base, ratings and P0202, and of the codes polled by DP-V1.
        When all of those equal the last call's, and the profile's own memory is still what
        that call left (nothing else wrote it since), the decode would give the same
        readings and leave the same memory: they are returned again (a fresh dict) without
        decoding (``tests/profibus/test_weg_inputs_fast_path.py`` checks both paths).
        """
        key = (data, self._sent_key(), self.base, self.ratings, self.control_type)
        memo = self._inputs_memo
        if memo is not None and memo[0] == key and memo[1] == self._inputs_memory():
            return _copy_readings(memo[2])
        changes = self._decode_inputs(data)
        self._inputs_memo = (key, self._inputs_memory(), _copy_readings(changes))
        return changes

    def _sent_key(self) -> tuple[bool, bool, int, bool, bool]:
        s = self._sent
        return (s.run, s.forward, s.reference, s.remote, s.jog)

    def _inputs_memory(self) -> tuple[object, ...]:
        """What :meth:`_decode_inputs` reads or writes of the profile's own state."""
        return (
            self._faulted,
            self._alarm,
            self._zsw,
            self._polled_fault,
            self._polled_alarm,
            dict(self._status_values),
        )

    def _decode_inputs(self, data: bytes) -> Readings:
        """The general path of :meth:`inputs`: the telegram decoded word by word."""
        n = self.options.words
        if len(data) != 2 * n:
            raise ProfibusDecodeError(
                DecodeFailure.BAD_LENGTH, f"input telegram of {len(data)} bytes, not {2 * n}", data
            )
        raw = struct.unpack(f">{n}H", data)
        changes: Readings = {}
        speed = w.signed(raw[1])
        self._speed_fields(speed, changes)
        heard = self.data_words.status(raw[0], speed, self._sent, self._near_reference, changes)
        self._zsw, self._status_values = heard.zsw, heard.status_values
        self._faulted, self._alarm = heard.faulted, heard.alarm
        mapped = read_mapped(self.spec, self.ratings, self.in_map, raw[2:], changes)
        self._resolve_codes(changes, mapped)
        mapped.values.update(self._own_values())
        mapped.values.update(self._status_values)
        if mapped.values:
            changes["values"] = dict(mapped.values)
        return changes

    def _speed_fields(self, speed: int, changes: Readings) -> None:
        if self.base is None:
            return
        changes["speed_rpm"] = round(self.base.rpm_of(speed), 3)
        changes["speed_pct"] = round(self.base.pct_of(speed), 3)
        if self._sent.remote:
            effective = w.effective_reference(self._sent.forward, self._sent.reference)
            changes["speed_ref_rpm"] = round(self.base.rpm_of(effective), 3)
            changes["speed_ref_pct"] = round(self.base.pct_of(effective), 3)
        else:
            changes["speed_ref_rpm"] = changes["speed_ref_pct"] = None

    def _near_reference(self, speed: int) -> bool:
        if self.base is None:
            return False
        effective = w.effective_reference(self._sent.forward, self._sent.reference)
        band = self.options.at_reference_band
        return abs(self.base.pct_of(speed) - self.base.pct_of(effective)) <= band

    # ------------------------------------------------------------------ fault, alarm codes

    def _resolve_codes(self, changes: Readings, m: Mapped) -> None:
        """Fault and alarm codes with their texts from the drive's own tables."""
        if self._faulted:
            code = m.fault if m.fault is not None else self._polled_fault
            text = None
            categories = w.namur_categories(m.namur)
            if code is None and len(categories) == 1 and len(categories[0][1]) == 1:
                code = categories[0][1][0]  # a NAMUR bit naming exactly one fault
            if code is not None:
                text = self.spec.fault_text(code)
            elif categories:
                text = "; ".join(c for c, _ in categories)
            changes.update({"fault_code": code, "fault_text": text})
        else:
            self._polled_fault = None
            changes.update({"fault_code": None, "fault_text": None})
        if m.alarm is not None:
            alarm: int | None = m.alarm  # P0048 in a telegram word
        elif self._alarm:
            alarm = self._polled_alarm  # read by DP-V1 while the alarm bit stays set
        else:
            alarm = self._polled_alarm = None  # the bit dropped: that alarm is gone
        if not self._alarm and not alarm:
            changes["alarm_code"] = None
        else:
            changes["alarm_code"] = alarm or None
            if alarm:
                changes["alarm"] = True

    # ------------------------------------------------------------------ codes by DP-V1

    @property
    def steady(self) -> bool:
        """No reset pulse running (the only use of ``now`` in :meth:`outputs`): the
        telegrams are then functions of the inputs, the desired command, and what a
        parameter write or a codes read changes (the adapter is told of those)."""
        return self._pulse_until is None

    @property
    def wants_codes(self) -> bool:
        """True when the status shows a fault or alarm that no telegram word numbers.

        The adapter then calls :meth:`read_codes` (DpProfile hooks, DpProfileBase defaults).
        """
        # the status bits first: the word map is looked at only when one is set
        if (
            self._faulted
            and self._polled_fault is None
            and not any(p in (49, 947) for p in self.in_map)
        ):
            return True
        return self._alarm and self._polled_alarm is None and 48 not in self.in_map

    async def read_codes(self, channel: RecordChannel) -> Readings:
        """Read P0049 (present fault) and P0048 (present alarm) through DP-V1."""
        fault, alarm = await self.params.read_many(channel, [(49, 0), (48, 0)])
        changes: Readings = {}
        if self._faulted and fault:
            self._polled_fault = fault
            changes.update({"fault_code": fault, "fault_text": self.spec.fault_text(fault)})
        if self._alarm and alarm:
            self._polled_alarm = alarm
            changes.update({"alarm_code": alarm})
        return changes

    def alarm_text(self, code: int) -> str:
        """The manual's text of an alarm code (A138...), or the code as shown."""
        return self.spec.alarm_text(code)

    # ------------------------------------------------------------------ diag, loss

    def on_ext_diag(self, data: bytes) -> list[DiagEvent]:
        """The WEG manuals define no device-related diagnosis (faults are parameters)."""
        if not data:
            return []
        return [
            DiagEvent(
                f"unexpected device diagnosis {data.hex(' ')}",
                kind=DiagKind.INFO,
                data={"raw": data.hex()},
            )
        ]

    def on_comm_lost(self) -> None:
        self._p0741_seen = None
        self._reset_seen = None
        self._pulse_until = None
        self._pulse_sent = False
        self._zsw = None
        self._sent = Sent()
        self._polled_fault = self._polled_alarm = None

    # ------------------------------------------------------------------ parameters

    async def read_param(self, channel: RecordChannel, number: int, subindex: int) -> ParamValue:
        """The raw word (signed for the signed parameters), as the manuals list values."""
        raw = await self.params.read(channel, number, subindex)
        return w.signed(raw) if number in SIGNED else raw

    async def write_param(
        self, channel: RecordChannel, number: int, subindex: int, value: ParamValue
    ) -> None:
        raw = _raw(value)
        await self.params.write(channel, number, raw, subindex)
        if subindex == 0:
            self._after_write(number, raw)

    def _after_write(self, number: int, raw: int) -> None:
        """Keep cyclic output words and the speed scale in step with a parameter written."""
        for i, param in enumerate(self.out_map):
            if param == number:
                self.out_values[i] = raw
        name = _SCALE_FIELDS.get(number)
        configured = {
            "max_rpm": self.options.max_rpm,
            "rated_hz": self.options.rated_hz,
            "rated_rpm": self.options.rated_rpm,
            "rated_current_a": self.options.rated_current_a,
            "rated_power_kw": self.options.rated_power_kw,
        }
        if number == 202 and self.spec.reads_control_type:
            self._set_control_type(raw)
        if name is None or configured[name] is not None or self.base is None:
            return
        value = float(scaled(number, raw))
        if value > 0:
            self.ratings = replace(self.ratings, **{name: value})
            self.base = self._speed_base(self.ratings)


_SCALE_FIELDS: Final[Mapping[int, str]] = {
    134: "max_rpm",
    403: "rated_hz",
    402: "rated_rpm",
    401: "rated_current_a",
    404: "rated_power_kw",
}


def _raw(value: ParamValue) -> int:
    """A parameter value as the raw word: an integer (no decimal point on the wire)."""
    if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
        raise ParameterError(
            f"{value!r} is not a raw parameter value (integers, without decimal point: "
            "P0100 = 8.5 s is written as 85)"
        )
    number = int(value)
    if not w.WORD_MIN <= number <= 0xFFFF:
        raise ParameterError(f"{number} does not fit a 16-bit parameter")
    return number & 0xFFFF
