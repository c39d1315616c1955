"""The DP profile shared by the WEG CFW-11, CFW700 and CFW320 (raw words <-> drive model).

One instance per configured drive. The model's differences come from its
:class:`~adapters.profibus.weg.spec.ModelSpec`; :mod:`.cfw11`, :mod:`.cfw700` and
:mod:`.cfw320` only name the spec.

Cyclic words (telegram of ``words`` 16-bit words, big-endian, both directions):

* word 1 out: control word (P0684 manufacturer / P0967 PROFIdrive); in: status word
  (P0680 / P0968);
* word 2 out: speed reference (P0685 13 bits / 4000h = P0134); in: motor speed (P0681 / same);
* words 3..N: the parameters the drive is programmed with (P0742.. in, P0750.. / P746.. out).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar, Final

from adapters.profibus.chkcfg import CompactId, IoDirection
from adapters.profibus.errors import DecodeFailure, ProfibusDecodeError
from adapters.profibus.profile import (
    AddressRange,
    DiagEvent,
    DiagKind,
    DpProfileBase,
    EventSink,
    RecordChannel,
    SlaveSetup,
)
from adapters.profibus.weg import words as w
from adapters.profibus.weg.options import WegOptions, parse_options
from adapters.profibus.weg.paramtable import PARAM_TABLES
from adapters.profibus.weg.records import RecordParams
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
from gateway.errors import GatewayError, ParameterError
from gateway.model import DesiredCommand, Device, Direction, DriveStatus, Readings, SpeedScale

if TYPE_CHECKING:
    from gateway.config import DriveConfig
    from gateway.schema import Table

log = logging.getLogger(__name__)

MAX_13BIT_PCT: Final = 100.0 * w.WORD_MAX / w.SPEED_13BIT_BASE  # 4 x base, saturating (P681)
MAX_PROFIDRIVE_PCT: Final = 100.0  # the drive limits the speed to P0134 = 4000h

# P0680 bits the model has no field for, published as ``DriveState.values`` entries (0/1)
# where the model's status word has the bit (docs/devices.md): CFW320 Table 4.2 bit 2 "Fire
# mode", CFW-11 Table 3.2 bit 14 "PID automatic" (reserved on the CFW700).
STATUS_VALUES: Final = (("fire_mode", "fire_mode"), ("pid_automatic", "automatic"))


class DriveProgrammingMismatch(GatewayError):
    """The drive's programming (P0741, P0922/P751, P0742..) differs from the drive's config."""


class DataProfilePending(GatewayError):
    """A ``startup_params`` write the drive takes only without cyclic data (P0741, P0922 /
    P751: CFW-11 l.959-961, CFW700 l.922-924 and l.1172, CFW320 l.547 and l.581) was made.

    The drive still speaks its old words until it leaves data exchange: the adapter takes
    the slave out of data exchange and parameterises it again (``reparameterise``), and the
    next connect finds the value in force (issue 32 item 2)."""

    reparameterise = True


class StartupParamRefused(ParameterError):
    """The drive refused a ``startup_params`` write: it stays "not configured".

    Reads as the reason an operator sees: "startup P0313 = 9: parameter value out of the
    limits (error 0x0002)".
    """

    def __str__(self) -> str:
        code = "" if self.code is None else f" (error 0x{self.code:04X})"
        return f"{self.text}{code}"


@dataclass(frozen=True)
class SpeedBase:
    """What the speed word's full scale means: ``rpm`` at ``full_scale`` (8192 or 4000h)."""

    rpm: float
    full_scale: int
    max_pct: float
    label: str

    def to_raw(self, rpm: float | None, pct: float | None) -> int:
        if rpm is not None:
            return w.speed_to_raw(rpm, self.rpm, self.full_scale)
        if pct is not None:
            return w.speed_to_raw(pct, 100.0, self.full_scale)
        return 0

    def rpm_of(self, raw: int) -> float:
        return w.raw_to_speed(raw, self.rpm, self.full_scale)

    def pct_of(self, raw: int) -> float:
        return w.raw_to_speed(raw, 100.0, self.full_scale)

    def scale(self) -> SpeedScale:
        return SpeedScale(base_rpm=self.rpm, max_pct=self.max_pct, label=self.label)


@dataclass(frozen=True)
class Ratings:
    """Scale parameters read at connect (or fixed by the config)."""

    rated_hz: float | None = None  # P0403
    rated_rpm: float | None = None  # P0402
    sync_rpm: float | None = None  # from the two above (13-bit base)
    max_rpm: float | None = None  # P0134 (PROFIdrive base)
    rated_current_a: float | None = None  # P0401 (frame 20 P0760)
    rated_power_kw: float | None = None  # P0404 (frame 20 P0761)


@dataclass
class _Sent:
    """What the last output telegram asked for (inputs are judged against it)."""

    run: bool = False
    forward: bool = True
    reference: int = 0  # signed raw word as sent
    remote: bool = True
    jog: bool = False


_OutMemory = tuple[bool, int | None, bool, _Sent]
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
        self._sent = _Sent()
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
        self._status_values: dict[str, int] = {}  # STATUS_VALUES of the last P0680
        # inputs' fast path: (key, the memory the call left, its readings)
        self._inputs_memo: tuple[tuple[object, ...], tuple[object, ...], Readings] | None = None
        # outputs' fast path: (key, the memory before the call, the memory after, telegram)
        self._outputs_memo: tuple[tuple[object, ...], _OutMemory, _OutMemory, bytes] | None = None

    # ------------------------------------------------------------------ setup

    @property
    def profidrive(self) -> bool:
        return self.options.data_profile is DataProfile.PROFIDRIVE

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
            if await self._startup_param(channel, event, number, value):
                written += [number] if number in offline_taken else []
        if written:
            names = ", ".join(self.spec.pname(n) for n in written)
            raise DataProfilePending(
                f"{names} written: the drive takes it only without cyclic data, "
                "the slave is parameterised again"
            )
        if p0741 is not None:
            self._check_data_profile(p0741)
        if self.options.verify_mapping:
            await self._verify_programming(channel)
        await self._read_ratings(channel)
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
        if self.control_type is not None:
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
        if self.control_type is None:
            return {}
        return {
            self.spec.pname(202): self.control_type,
            "quick_stop_as_ramp": int(self.quick_stop_as_ramp),
        }

    async def _startup_param(
        self, channel: RecordChannel, event: EventSink, number: int, value: int
    ) -> bool:
        """Write one ``startup_params`` entry where the drive differs; True when written."""
        name = self.spec.pname(number)
        raw = w.to_word(value)
        written = False
        try:
            if await self.params.read(channel, number) != raw:
                written = True
                await self.params.write(channel, number, raw)
                event(
                    f"startup {name} = {value} written",
                    DiagKind.PARAMETER,
                    number=number,
                    value=value,
                )
            back = await self.params.read(channel, number)
        except ParameterError as exc:
            raise StartupParamRefused(f"startup {name} = {value}: {exc.text}", exc.code) from exc
        if back != raw:
            raise DriveProgrammingMismatch(f"startup {name} = {value}: read back {back}")
        return written

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

    def _check_data_profile(self, got: int) -> None:
        """P741 against the configured data profile (CFW320 Table 4.6 note: the control,
        status, speed reference and motor speed words depend on it): a mismatch would be
        misread, so the drive is not brought online."""
        want = self.options.data_profile
        if got == want.p0741:
            return
        names = {p.p0741: p.value for p in DataProfile}
        raise DriveProgrammingMismatch(
            f"{self.spec.pname(741)} = {got} ({names.get(got, 'unknown data profile')}), "
            f"the config's data_profile is {want.value} ({self.spec.pname(741)} = {want.p0741}): "
            "its words would be misread"
        )

    def _expected_programming(self) -> list[tuple[int, int]]:
        """(parameter, expected raw value) that the config implies about the drive."""
        spec, opts = self.spec, self.options
        out = [(spec.telegram_param, spec.telegram_code(opts.words))]
        if len(spec.profiles) > 1 and not spec.reads_data_profile:
            out.append((741, opts.data_profile.p0741))
        for i, param in enumerate(self.in_map):
            out.append((spec.read_map_param(i + 3), param))
        for i, param in enumerate(self.out_map):
            out.append((spec.write_map_param(i + 3), param))
        return out

    async def _verify_programming(self, channel: RecordChannel) -> None:
        expected = self._expected_programming()
        values = await self.params.read_many(channel, [(n, 0) for n, _ in expected])
        wrong = [
            f"{self.spec.pname(n)} = {got} (config: {want})"
            for (n, want), got in zip(expected, values, strict=True)
            if got != want
        ]
        if wrong:
            raise DriveProgrammingMismatch(
                "the drive is programmed differently from its config: " + ", ".join(wrong)
            )

    def _rating_params(self) -> dict[str, int]:
        """Ratings field -> parameter, for what the config leaves to the drive.

        P0134 is read in both profiles: the PROFIdrive base, and the limit of the 13-bit
        references (the drive limits the speed to P0134 whatever the word says).
        """
        r, need = self.ratings, {}
        if r.max_rpm is None:
            need["max_rpm"] = 134
        if not self.profidrive and (
            r.sync_rpm is None or (self.spec.device is Device.CFW320 and r.rated_hz is None)
        ):
            if r.rated_hz is None:
                need["rated_hz"] = 403
            if r.rated_rpm is None and r.sync_rpm is None:
                need["rated_rpm"] = 402
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

    def _base_configured(self) -> bool:
        o = self.options
        if self.profidrive:
            return o.max_rpm is not None
        return o.sync_rpm is not None or (o.rated_hz is not None and o.rated_rpm is not None)

    def _speed_base(self, r: Ratings) -> SpeedBase | None:
        """The speed word's base from the ratings known so far (None: not yet)."""
        suffix = " (configured)" if self._base_configured() else ""
        if self.profidrive:
            if r.max_rpm is None:
                return None
            label = f"4000h = {self.spec.pname(134)} {r.max_rpm:g} rpm{suffix}"
            return SpeedBase(r.max_rpm, w.PROFIDRIVE_SPEED_BASE, MAX_PROFIDRIVE_PCT, label)
        sync = r.sync_rpm
        if sync is None and r.rated_hz is not None and r.rated_rpm is not None:
            sync = w.synchronous_rpm(r.rated_hz, r.rated_rpm)
        if sync is None:
            return None
        if self.spec.device is Device.CFW320:
            hz = "" if r.rated_hz is None else f" {r.rated_hz:g} Hz"
            label = f"8192 = {self.spec.pname(403)}{hz} = {sync:g} rpm{suffix}"
        else:
            label = f"8192 = {sync:g} rpm synchronous{suffix}"
        limit = MAX_13BIT_PCT if r.max_rpm is None else min(MAX_13BIT_PCT, 100 * r.max_rpm / sync)
        return SpeedBase(sync, w.SPEED_13BIT_BASE, limit, label)

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
        if self.profidrive:
            control, reference = self._profidrive_out(desired, reset)
        else:
            control, reference = self._manufacturer_out(desired, reset)
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

    def _manufacturer_out(self, d: DesiredCommand, reset: bool) -> tuple[int, int]:
        """P0684 and P0685 (Table 3.3 / 4.3; P0685 bit 2 cases).

        Run = run/stop + general enable + remote; coast stop drops general enable; quick
        stop is bit 6 where the model has it. Bit 2 = 1 for forward and 0 for reverse, so
        the sign of the speed (normally positive) keeps the manual's meaning.

        Quick stop and coast stop clear run (bit 0) and JOG (bit 3): a drive that does not
        execute bit 6 (CFW700 "not allowed" in V/f or VVW) still ramps down, and the
        release of either stop never restarts the motor. With P0202 V/f or VVW bit 6 is
        not sent: the quick stop is a ramp stop (docs/devices.md).
        """
        forward = d.direction is Direction.FORWARD
        reference = self._reference(d)
        run, jog = self._run_jog(d)
        control = w.ManufacturerControl(
            run=run,
            general_enable=not d.coast_stop,
            forward=forward,
            jog=jog,
            remote=d.remote,
            quick_stop=d.quick_stop and self.spec.quick_stop and not self.quick_stop_as_ramp,
            fault_reset=reset,
        )
        self._sent = _Sent(run or jog, forward, reference, d.remote, jog)
        return control.encode(self.spec.control_bits), reference

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

    def _profidrive_out(self, d: DesiredCommand, reset: bool) -> tuple[int, int]:
        """STW1 (P0967, Table 3.8 / 4.7) walking the switching-on states, and NSOLL.

        Switching on inhibited: ON = 0 (the drive goes to ready to switch on); then ON = 1
        with enable operation, ramp and setpoint (switched on, then operation). A fault is
        acknowledged with one bit-7 pulse and ON = 0. Reverse is a negative reference
        (P0967 note). Reserved bits 5 and 9 are sent as 0.

        Quick stop (bit 2 = 0, OFF3) and coast stop (bit 1 = 0, OFF2) go with ON = 0 and
        JOG = 0, so their release never switches the drive back on. With P0202 V/f or VVW
        (bit 2 note: not recommended) a quick stop is OFF1: ON = 0 with bit 2 = 1.
        """
        state = w.ProfidriveState.SWITCHING_ON_INHIBITED if self._zsw is None else self._zsw.state
        run, jog = self._run_jog(d)
        want = run or jog
        walkable = state in (
            w.ProfidriveState.READY_TO_SWITCH_ON,
            w.ProfidriveState.SWITCHED_ON,
            w.ProfidriveState.OPERATION,
        )
        on = want and walkable
        magnitude = self._reference(d)
        forward = d.direction is Direction.FORWARD
        reference = w.saturate(magnitude if forward else -magnitude)
        control = w.ProfidriveControl(
            on=on,
            no_coast_stop=not d.coast_stop,
            no_quick_stop=not (d.quick_stop and not self.quick_stop_as_ramp),
            enable_operation=True,
            enable_ramp=True,
            enable_setpoint=True,
            fault_ack=reset,
            jog=jog and on,
            control_by_plc=d.remote,
        )
        self._sent = _Sent(on, True, reference, d.remote, jog and on)
        return control.encode(w.STW1_BITS), reference

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
        if self.profidrive:
            self._profidrive_in(raw[0], speed, changes)
        else:
            self._manufacturer_in(raw[0], speed, changes)
        mapped = _Mapped()
        for param, word in zip(self.in_map, raw[2:], strict=True):
            if param:
                self._mapped_word(param, word, changes, mapped)
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

    def _manufacturer_in(self, word: int, speed: int, changes: Readings) -> None:
        """P0680 (Table 3.2 / 4.2) and P0681 (13 bits, 8192 = synchronous speed / P403).

        A drive jogging (bit 11 "JOG active", CFW-11 Table 3.2, CFW700 Table 4.2, CFW320
        Table 4.2) runs at its own JOG speed: commanded and at that reference (issue 32
        item 8). Local control is bit 12 LOC/REM = 0: the drive follows its local sources,
        not the network (issue 32 item 6; docs/devices.md).
        """
        st = w.ManufacturerStatus.decode(word, self.spec.status_bits)
        self._status_values = {
            key: int(getattr(st, bit)) for key, bit in STATUS_VALUES if self._has_status_bit(bit)
        }
        self._speed_fields(speed, changes)
        if self.spec.device is Device.CFW320:
            commanded = st.run_command or st.jog  # CFW320 bit 1 "Run command" (JOG: no)
        else:
            commanded = self._sent.run if st.remote else True
        jogging = st.running and st.jog
        at_ref = jogging or (st.running and commanded and st.remote and self._near_reference(speed))
        if st.fault:
            status = DriveStatus.FAULTED
        elif st.config_mode or st.undervoltage:
            status = DriveStatus.NOT_READY
        elif not st.running:
            status = DriveStatus.READY
        elif st.quick_stop_active or not commanded:
            status = DriveStatus.STOPPING
        elif at_ref or not st.remote:
            status = DriveStatus.RUNNING
        else:
            status = DriveStatus.STARTING
        self._faulted, self._alarm = st.fault, st.alarm
        changes.update(
            {
                "status": status,
                "running": st.running,
                "direction": Direction.FORWARD if st.forward else Direction.REVERSE,
                "at_reference": at_ref,
                "remote": st.remote,
                "local_control": not st.remote,
                "alarm": st.alarm,
            }
        )

    def _has_status_bit(self, bit: str) -> bool:
        return any(name == bit for name, _ in self.spec.status_bits)

    def _profidrive_in(self, word: int, speed: int, changes: Readings) -> None:
        """P0968 ZSW1 (Table 3.9 / 4.8) and NIST (4000h = P0134)."""
        zsw = w.ProfidriveStatus.decode(word, self.spec.zsw1_bits)
        self._zsw = zsw
        state = zsw.state
        self._speed_fields(speed, changes)
        operation = state is w.ProfidriveState.OPERATION
        running = operation and (self._sent.run or speed != 0)
        if self._sent.jog:  # JOG 1 (STW1 bit 8): the drive's own JOG speed is its reference
            at_ref = operation and speed != 0
        elif any(name == "frequency_reached" for name, _ in self.spec.zsw1_bits):
            at_ref = operation and self._sent.run and zsw.frequency_reached  # CFW-11 bit 10
        else:
            at_ref = operation and self._sent.run and self._near_reference(speed)
        status = _PROFIDRIVE_STATUS[state]
        if operation:
            if not self._sent.run or not zsw.quick_stop_not_active:
                status = DriveStatus.STOPPING if speed else DriveStatus.READY
            else:
                status = DriveStatus.RUNNING if at_ref else DriveStatus.STARTING
        elif state is w.ProfidriveState.SWITCHED_ON and self._sent.run:
            status = DriveStatus.STARTING
        if speed > 0:
            direction = Direction.FORWARD
        elif speed < 0:
            direction = Direction.REVERSE
        else:
            direction = Direction.FORWARD if self._sent.reference >= 0 else Direction.REVERSE
        self._faulted, self._alarm = zsw.fault, zsw.warning
        changes.update(
            {
                "status": status,
                "running": running,
                "direction": direction,
                "at_reference": at_ref,
                "remote": zsw.control_requested,
                "local_control": not zsw.control_requested,  # ZSW1 bit 9 (Table 3.9 / 4.8)
                "alarm": zsw.warning,
            }
        )

    # ------------------------------------------------------------------ mapped words

    def _mapped_word(self, param: int, word: int, changes: Readings, m: _Mapped) -> None:
        handler = _KNOWN.get(param)
        if handler is None:
            m.values[self.spec.pname(param)] = scaled(param, word)
        else:
            handler(self, word, changes, m)

    def _current(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0003 motor current, one decimal (P0742 description: 4.7 A is sent as 47)."""
        amps = word / 10.0
        changes["current_a"] = amps
        if self.ratings.rated_current_a:
            changes["current_pct_flc"] = round(100.0 * amps / self.ratings.rated_current_a, 2)

    def _alarm_word(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0048 present alarm (Table 3.2 bit 7 note)."""
        m.alarm = word

    def _fault_word(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0049 present fault (Table 3.2 bit 15 note) / P0947 fault number."""
        if word:
            m.fault = word

    def _power(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0010 output power, kW with one decimal (P0761 description)."""
        changes["power_kw"] = word / 10.0

    def _pd_current(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0760: 4000h = 100 % of the motor rated current P0401."""
        pct = 100.0 * word / w.PROFIDRIVE_PERCENT_BASE
        changes["current_pct_flc"] = round(pct, 2)
        if self.ratings.rated_current_a:
            changes["current_a"] = round(pct * self.ratings.rated_current_a / 100.0, 2)

    def _pd_power(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0761 = (P0010 / P0404) x 4000h."""
        if self.ratings.rated_power_kw:
            frac = word / w.PROFIDRIVE_PERCENT_BASE
            changes["power_kw"] = round(frac * self.ratings.rated_power_kw, 3)
        else:
            m.values["power_pct"] = round(100.0 * word / w.PROFIDRIVE_PERCENT_BASE, 2)

    def _pd_torque(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0762: 4000h = 100 % of the output torque."""
        m.values["torque_pct"] = round(100.0 * word / w.PROFIDRIVE_PERCENT_BASE, 2)

    def _namur(self, word: int, changes: Readings, m: _Mapped) -> None:
        """P0763 VIK-NAMUR status (Table 3.7): fault categories."""
        m.namur = word
        m.values[self.spec.pname(763)] = word

    def _resolve_codes(self, changes: Readings, m: _Mapped) -> None:
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
        self._sent = _Sent()
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

_PROFIDRIVE_STATUS: Final[Mapping[w.ProfidriveState, DriveStatus]] = {
    w.ProfidriveState.NOT_READY: DriveStatus.NOT_READY,
    w.ProfidriveState.SWITCHING_ON_INHIBITED: DriveStatus.NOT_READY,
    w.ProfidriveState.READY_TO_SWITCH_ON: DriveStatus.READY,
    w.ProfidriveState.SWITCHED_ON: DriveStatus.READY,
    w.ProfidriveState.OPERATION: DriveStatus.RUNNING,
    w.ProfidriveState.FAULT: DriveStatus.FAULTED,
}


@dataclass
class _Mapped:
    """What the mapped words of one input telegram said."""

    fault: int | None = None
    alarm: int | None = None
    namur: int = 0
    values: dict[str, float | int] = field(default_factory=dict)


_Handler = Callable[[WegProfile, int, Readings, _Mapped], None]

_KNOWN: Final[Mapping[int, _Handler]] = {
    3: WegProfile._current,
    10: WegProfile._power,
    48: WegProfile._alarm_word,
    49: WegProfile._fault_word,
    947: WegProfile._fault_word,
    760: WegProfile._pd_current,
    761: WegProfile._pd_power,
    762: WegProfile._pd_torque,
    763: WegProfile._namur,
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
