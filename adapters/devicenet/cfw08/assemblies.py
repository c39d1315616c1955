"""WEG CFW-08 on DeviceNet: the device profile (raw I/O words <-> the common drive model).

Source of truth: ``weg-cfw08-devicenet.pt.md`` (the seed; sections cited as "seed 3.3",
tables as "table 6"). Assemblies 20/70 and 21/71 follow the ODVA AC/DC drive profile
(fact sheet 2.11); 100/150 are WEG's own. Every assembly is two words, little-endian
(seed 4.1.8, table 11). P710 selects the pair in the drive (seed 4.1.8); the config
selects it in the gateway and the adapter checks both agree at connect.

Speeds: assemblies 20/70 and 21/71 carry rpm (seed 3.1.1, 3.1.2). For 100/150 the seed
gives no scale: the gateway's decision (docs/devices.md) is WEG's Profibus convention,
``weg_speed_scale`` counts (default 8192 = 2**13 = 0x2000, which takes 14 bits of the
16-bit word) for the drive's maximum speed ``max_rpm``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, ClassVar, Protocol

from adapters.devicenet.codec.datatypes import CipType, encode_value, read_value
from adapters.devicenet.errors import AssemblyDecodeError, DataTypeDecodeError
from gateway.adapter import Capabilities
from gateway.errors import FrameEncodeError
from gateway.model import DesiredCommand, Direction, DriveStatus, Readings, SpeedScale

ASSEMBLY_SIZE = 4  # seed 4.1.8 and table 11: every instance is 2 words
DEFAULT_WEG_SPEED_SCALE = 8192  # decision (100/150): 8192 counts = max_rpm
SPEED_REF_MAX_RPM = 9999  # seed table 17: AC/DC Drive Speed Ref 0-9999
DEFAULT_AT_REFERENCE_RPM = 30.0  # seed 3.1.1: "at reference" within 1 Hz (30 rpm, 4-pole 60 Hz)


class AssemblyPair(IntEnum):
    """The I/O instance pairs of the CFW-08; the value is the output (consumed) instance."""

    BASIC = 20  # 20/70 "Basic Speed" (seed 3.2, table 5), P710 = 0
    EXTENDED = 21  # 21/71 "Extended Speed" (seed 3.3, table 6), P710 = 1
    WEG = 100  # 100/150 WEG specific (seed 3.4, table 7), P710 = 2

    @property
    def output_instance(self) -> int:
        return int(self)

    @property
    def input_instance(self) -> int:
        return _INPUT_INSTANCE[self]

    @property
    def p710(self) -> int:
        """The P710 value that selects this pair in the drive (seed 4.1.8)."""
        return _P710[self]

    @property
    def label(self) -> str:
        return f"{self.output_instance}/{self.input_instance}"

    @classmethod
    def from_p710(cls, value: int) -> AssemblyPair | None:
        return _BY_P710.get(value)


_INPUT_INSTANCE = {AssemblyPair.BASIC: 70, AssemblyPair.EXTENDED: 71, AssemblyPair.WEG: 150}
_P710 = {AssemblyPair.BASIC: 0, AssemblyPair.EXTENDED: 1, AssemblyPair.WEG: 2}
_BY_P710 = {v: k for k, v in _P710.items()}


class DriveStateCode(IntEnum):
    """Drive State, byte 1 of assembly 71 and Control Supervisor attribute 6 (seed 3.1.1)."""

    NON_EXISTENT = 0
    STARTUP = 1
    NOT_READY = 2
    READY = 3
    ENABLED = 4
    STOPPING = 5
    FAULT_STOP = 6
    FAULTED = 7


# ---------------------------------------------------------------- assembly codecs


def _bit(byte: int, n: int) -> bool:
    return bool(byte >> n & 1)


def _bits(*flags: tuple[int, bool]) -> int:
    return sum(1 << n for n, on in flags if on)


def _check_length(data: bytes, instance: int) -> bytes:
    raw = bytes(data)
    if len(raw) != ASSEMBLY_SIZE:
        raise AssemblyDecodeError(
            f"assembly {instance} has {ASSEMBLY_SIZE} bytes, got {len(raw)}", raw
        )
    return raw


def _word(cip_type: CipType, raw: bytes) -> int:
    return read_value(cip_type, raw, 2)[0]


class Assembly(Protocol):
    instance: ClassVar[int]

    def encode(self) -> bytes: ...


@dataclass(frozen=True, slots=True)
class Out20:
    """Output assembly 20 (seed table 5): b0 Run Fwd, b2 Fault Reset; speed reference rpm."""

    instance: ClassVar[int] = 20
    run_fwd: bool = False
    fault_reset: bool = False
    speed_rpm: int = 0  # INT, rpm (seed 3.1.2)

    def encode(self) -> bytes:
        first = _bits((0, self.run_fwd), (2, self.fault_reset))
        return bytes((first, 0)) + encode_value(CipType.INT, self.speed_rpm)

    @classmethod
    def decode(cls, data: bytes) -> Out20:
        raw = _check_length(data, cls.instance)
        return cls(_bit(raw[0], 0), _bit(raw[0], 2), _word(CipType.INT, raw))


@dataclass(frozen=True, slots=True)
class Out21:
    """Output assembly 21 (seed table 6): Run Fwd b0, Run Rev b1, Fault Reset b2,
    NetCtrl b5, NetRef b6; speed reference rpm (seed 3.1.2)."""

    instance: ClassVar[int] = 21
    run_fwd: bool = False
    run_rev: bool = False
    fault_reset: bool = False
    net_ctrl: bool = False
    net_ref: bool = False
    speed_rpm: int = 0

    def encode(self) -> bytes:
        first = _bits(
            (0, self.run_fwd),
            (1, self.run_rev),
            (2, self.fault_reset),
            (5, self.net_ctrl),
            (6, self.net_ref),
        )
        return bytes((first, 0)) + encode_value(CipType.INT, self.speed_rpm)

    @classmethod
    def decode(cls, data: bytes) -> Out21:
        raw = _check_length(data, cls.instance)
        b = raw[0]
        return cls(
            _bit(b, 0), _bit(b, 1), _bit(b, 2), _bit(b, 5), _bit(b, 6), _word(CipType.INT, raw)
        )


@dataclass(frozen=True, slots=True)
class Out100:
    """Output assembly 100 (seed table 7).

    b0 Habilita Rampa, b1 Habilita Geral, b2 Sentido de Giro (0 = horário, 1 =
    anti-horário: 1 is reverse), b3 JOG, b4 Local/Remoto (1 = remote), b7 Reset de Erros
    (edge; the drive goes offline during the reset, seed 3.4 note). Speed: counts
    (gateway decision: ``weg_speed_scale`` counts = max_rpm).
    """

    instance: ClassVar[int] = 100
    ramp_enable: bool = False
    general_enable: bool = False
    reverse: bool = False
    jog: bool = False
    remote: bool = False
    fault_reset: bool = False
    speed_counts: int = 0  # UINT

    def encode(self) -> bytes:
        first = _bits(
            (0, self.ramp_enable),
            (1, self.general_enable),
            (2, self.reverse),
            (3, self.jog),
            (4, self.remote),
            (7, self.fault_reset),
        )
        return bytes((first, 0)) + encode_value(CipType.UINT, self.speed_counts)

    @classmethod
    def decode(cls, data: bytes) -> Out100:
        raw = _check_length(data, cls.instance)
        b = raw[0]
        return cls(
            _bit(b, 0),
            _bit(b, 1),
            _bit(b, 2),
            _bit(b, 3),
            _bit(b, 4),
            _bit(b, 7),
            _word(CipType.UINT, raw),
        )


@dataclass(frozen=True, slots=True)
class In70:
    """Input assembly 70 (seed table 5): b0 Faulted, b2 Running1; speed actual rpm."""

    instance: ClassVar[int] = 70
    faulted: bool = False
    running1: bool = False
    speed_rpm: int = 0

    def encode(self) -> bytes:
        first = _bits((0, self.faulted), (2, self.running1))
        return bytes((first, 0)) + encode_value(CipType.INT, self.speed_rpm)

    @classmethod
    def decode(cls, data: bytes) -> In70:
        raw = _check_length(data, cls.instance)
        return cls(_bit(raw[0], 0), _bit(raw[0], 2), _word(CipType.INT, raw))


@dataclass(frozen=True, slots=True)
class In71:
    """Input assembly 71 (seed table 6 and 3.1.1): b0 Faulted, b1 Warning (always 0 on the
    CFW-08), b2 Running1 (fwd), b3 Running2 (rev), b4 Ready, b5 Ctrl from Net, b6 Ref from
    Net, b7 At Reference; byte 1 Drive State; speed actual rpm."""

    instance: ClassVar[int] = 71
    faulted: bool = False
    warning: bool = False
    running1: bool = False
    running2: bool = False
    ready: bool = False
    ctrl_from_net: bool = False
    ref_from_net: bool = False
    at_reference: bool = False
    drive_state: int = DriveStateCode.NON_EXISTENT
    speed_rpm: int = 0

    def encode(self) -> bytes:
        first = _bits(
            (0, self.faulted),
            (1, self.warning),
            (2, self.running1),
            (3, self.running2),
            (4, self.ready),
            (5, self.ctrl_from_net),
            (6, self.ref_from_net),
            (7, self.at_reference),
        )
        return (
            bytes((first,))
            + encode_value(CipType.USINT, self.drive_state)
            + encode_value(CipType.INT, self.speed_rpm)
        )

    @classmethod
    def decode(cls, data: bytes) -> In71:
        raw = _check_length(data, cls.instance)
        b = raw[0]
        return cls(
            faulted=_bit(b, 0),
            warning=_bit(b, 1),
            running1=_bit(b, 2),
            running2=_bit(b, 3),
            ready=_bit(b, 4),
            ctrl_from_net=_bit(b, 5),
            ref_from_net=_bit(b, 6),
            at_reference=_bit(b, 7),
            drive_state=raw[1],
            speed_rpm=_word(CipType.INT, raw),
        )


@dataclass(frozen=True, slots=True)
class In150:
    """Input assembly 150 (seed table 7).

    Byte 0 "Estado Lógico (código de erro)": the error code while b7 of byte 1 is set.
    Byte 1: b0 Rampa Habilitada, b1 Habilitado Geral, b2 Sentido de Giro (1 = horário:
    forward; note the output bit has the opposite sense), b3 JOG, b4 Local/Remoto
    (1 = remote), b5 Subtensão, b7 Erro. Speed: counts (see module doc).
    """

    instance: ClassVar[int] = 150
    error_code: int = 0
    ramp_enabled: bool = False
    general_enabled: bool = False
    forward: bool = True
    jog: bool = False
    remote: bool = False
    undervoltage: bool = False
    error: bool = False
    speed_counts: int = 0

    def encode(self) -> bytes:
        second = _bits(
            (0, self.ramp_enabled),
            (1, self.general_enabled),
            (2, self.forward),
            (3, self.jog),
            (4, self.remote),
            (5, self.undervoltage),
            (7, self.error),
        )
        return (
            encode_value(CipType.USINT, self.error_code)
            + bytes((second,))
            + encode_value(CipType.UINT, self.speed_counts)
        )

    @classmethod
    def decode(cls, data: bytes) -> In150:
        raw = _check_length(data, cls.instance)
        b = raw[1]
        return cls(
            raw[0],
            _bit(b, 0),
            _bit(b, 1),
            _bit(b, 2),
            _bit(b, 3),
            _bit(b, 4),
            _bit(b, 5),
            _bit(b, 7),
            _word(CipType.UINT, raw),
        )


OutputAssembly = Out20 | Out21 | Out100
InputAssembly = In70 | In71 | In150

OUTPUT_DECODERS: Mapping[int, Any] = {20: Out20.decode, 21: Out21.decode, 100: Out100.decode}
INPUT_DECODERS: Mapping[int, Any] = {70: In70.decode, 71: In71.decode, 150: In150.decode}


def decode_output(instance: int, data: bytes) -> OutputAssembly:
    decoder = OUTPUT_DECODERS.get(instance)
    if decoder is None:
        raise AssemblyDecodeError(f"no output assembly {instance}", bytes(data))
    result: OutputAssembly = decoder(data)
    return result


def decode_input(instance: int, data: bytes) -> InputAssembly:
    decoder = INPUT_DECODERS.get(instance)
    if decoder is None:
        raise AssemblyDecodeError(f"no input assembly {instance}", bytes(data))
    result: InputAssembly = decoder(data)
    return result


# ---------------------------------------------------------------- speed scale (100/150)


def rpm_to_counts(rpm: float, max_rpm: float, scale: int = DEFAULT_WEG_SPEED_SCALE) -> int:
    """|rpm| as 100/150 counts (decision: ``scale`` counts = ``max_rpm``), UINT-bounded."""
    if max_rpm <= 0 or not math.isfinite(rpm):
        raise FrameEncodeError(f"cannot scale {rpm!r} rpm with max_rpm {max_rpm!r}")
    counts = round(abs(rpm) * scale / max_rpm)
    if counts > CipType.UINT.maximum:
        raise FrameEncodeError(f"{rpm:g} rpm is {counts} counts, beyond a UINT")
    return counts


def counts_to_rpm(counts: int, max_rpm: float, scale: int = DEFAULT_WEG_SPEED_SCALE) -> float:
    return counts * max_rpm / scale


# ---------------------------------------------------------------- WEG parameter classes

WEG_CLASS_FIRST = 100  # seed 5.10, table 19: P000-P099 -> class 100 (64h) ... P700-P799 -> 107
WEG_CLASS_LAST = 107
WEG_INSTANCE = 1  # seed 5.10 note: only instance 1
WEG_ATTRIBUTE_OFFSET = 100  # seed 5.10 note: attribute = 100 + the last two digits
MAX_PARAMETER = 799


@dataclass(frozen=True, slots=True)
class AttributePath:
    class_id: int
    instance_id: int
    attribute_id: int


def parameter_path(number: int) -> AttributePath:
    """Where parameter P<number> lives (seed 5.10, table 20): P023 -> 64h/1/123."""
    if isinstance(number, bool) or not isinstance(number, int) or not 0 <= number <= MAX_PARAMETER:
        raise ValueError(f"P{number} is outside the WEG classes (P000-P799)")
    return AttributePath(
        WEG_CLASS_FIRST + number // 100, WEG_INSTANCE, WEG_ATTRIBUTE_OFFSET + number % 100
    )


def parameter_of(class_id: int, attribute_id: int) -> int | None:
    """The parameter number at a WEG class attribute, or None outside tables 19/20."""
    if not WEG_CLASS_FIRST <= class_id <= WEG_CLASS_LAST:
        return None
    if not WEG_ATTRIBUTE_OFFSET <= attribute_id < WEG_ATTRIBUTE_OFFSET + 100:
        return None
    return (class_id - WEG_CLASS_FIRST) * 100 + attribute_id - WEG_ATTRIBUTE_OFFSET


PARAM_TYPE_UNSIGNED = CipType.UINT  # decision: parameter values are 16-bit words
PARAM_TYPE_SIGNED = CipType.INT


def encode_parameter(value: int) -> bytes:
    """A parameter value as 2 bytes, little-endian: UINT, or INT when negative (decision)."""
    cip_type = PARAM_TYPE_SIGNED if value < 0 else PARAM_TYPE_UNSIGNED
    return encode_value(cip_type, value)


def decode_parameter(data: bytes) -> int:
    """A parameter value from its 2 bytes (UINT); other lengths are read as unsigned."""
    raw = bytes(data)
    if not 1 <= len(raw) <= 4:
        raise DataTypeDecodeError(f"parameter value of {len(raw)} bytes", raw)
    return int.from_bytes(raw, "little")


# ---------------------------------------------------------------- texts (seed 2.2, 4.1)

COMM_ERROR_TEXT: Mapping[int, str] = {
    # seed 2.2: the DeviceNet errors shown on the keypad
    33: "CAN controller not powered (check the DeviceNet supply)",
    34: "CAN controller went bus-off (check the drive's baud rate against the master's)",
    36: "network master is idle",
    37: "one or more allocated I/O connections timed out",
}

P070_TEXT: Mapping[int, str] = {
    # seed 4.1.1: P070 CAN controller state
    0: "communication not enabled",
    1: "auto-baud running",
    2: "error active (no error)",
    3: "warning",
    4: "error passive",
    5: "bus-off",
    6: "no supply",
}
P070_COMM_ERROR: Mapping[int, int] = {5: 34, 6: 33}  # P070 value -> the E-code it goes with

P081_TEXT: Mapping[int, str] = {0: "run", 1: "idle"}  # seed 4.1.2: P081 master state
P081_IDLE = 1

P313_TEXT: Mapping[int, str] = {
    # seed 4.1.3: P313 action on a communication error (only if the command is from DeviceNet)
    0: "ramp disable",
    1: "general disable",
    2: "no action",
    3: "go to local mode",
}


P313_FAILSAFE: Mapping[int, bool] = {
    # seed 4.1.3: what the drive does by itself on E37 (I/O timeout) or E36 (master idle),
    # "only if the command is enabled for DeviceNet": 0 and 1 stop the motor (ramp, or
    # general disable: it coasts); 2 does nothing and 3 hands the drive to its local
    # commands (P229), which may keep it running: not a fail-safe reaction.
    0: True,
    1: True,
    2: False,
    3: False,
}
P313_EFFECT: Mapping[int, str] = {
    0: "the drive ramps the motor to a stop",
    1: "the drive disables the motor (it coasts)",
    2: "the drive keeps the motor turning (factory value)",
    3: "the drive goes to local mode and follows its local commands (P229)",
}


def failsafe_of(
    p313: int | None, io_timeout: float | None = None
) -> tuple[bool | None, str | None]:
    """The drive's reaction to a lost master from P313 (seed 4.1.3): (``failsafe``,
    ``failsafe_text``); (None, None) while P313 is unknown or out of its range.
    ``io_timeout``: how long without I/O before the drive sees the loss (4 x EPR, E37)."""
    if p313 is None or p313 not in P313_FAILSAFE:
        return None, None if p313 is None else f"P313 = {p313}: unknown action"
    after = f" {io_timeout:g} s after the last I/O (E37)" if io_timeout is not None else ""
    text = f"P313 = {p313} ({P313_TEXT[p313]}): on a lost master{after} {P313_EFFECT[p313]}"
    return P313_FAILSAFE[p313], text


def fault_text(code: int | None) -> str | None:
    """The text of a CFW-08 error code: the seed's meaning for E33-E37, else "E<code>".

    The CFW-08 fault table is not in the seed, so other codes get no invented text.
    """
    if code is None:
        return None
    return COMM_ERROR_TEXT.get(code, f"E{code:02d}")


def value_text(table: Mapping[int, str], value: int) -> str:
    return f"{table.get(value, 'unknown')} ({value})"


# ---------------------------------------------------------------- model mapping


@dataclass(frozen=True, slots=True)
class ProfileSettings:
    """What the mapping needs to know of one drive."""

    pair: AssemblyPair = AssemblyPair.EXTENDED
    max_rpm: float = 1800.0
    weg_speed_scale: int = DEFAULT_WEG_SPEED_SCALE
    at_reference_rpm: float = DEFAULT_AT_REFERENCE_RPM

    @property
    def speed_scale(self) -> SpeedScale:
        return SpeedScale(self.max_rpm, 100.0, label=f"max_rpm = {self.max_rpm:g} rpm")


def reference_rpm(settings: ProfileSettings, desired: DesiredCommand) -> float:
    """The speed reference magnitude in rpm that ``desired`` asks for."""
    if desired.speed_rpm is not None:
        return abs(desired.speed_rpm)
    if desired.speed_pct is not None:
        return abs(desired.speed_pct) * settings.max_rpm / 100.0
    return 0.0


def _reverse(desired: DesiredCommand) -> bool:
    negative = (desired.speed_rpm or 0.0) < 0 or (desired.speed_pct or 0.0) < 0
    return (desired.direction is Direction.REVERSE) != negative


@dataclass(frozen=True, slots=True)
class _Command:
    """What every command builder needs, worked out once."""

    settings: ProfileSettings
    desired: DesiredCommand
    run: bool
    reverse: bool
    rpm: float
    reset: bool


def command_assembly(
    settings: ProfileSettings, desired: DesiredCommand, fault_reset: bool
) -> OutputAssembly:
    """The output assembly for a desired command (one reset edge when ``fault_reset``)."""
    c = _Command(
        settings=settings,
        desired=desired,
        run=desired.run and not desired.coast_stop and not desired.quick_stop,  # rule 1
        reverse=_reverse(desired),
        rpm=min(reference_rpm(settings, desired), settings.max_rpm),
        reset=fault_reset,
    )
    return _COMMAND_BUILDERS[settings.pair](c)


def _out20(c: _Command) -> OutputAssembly:
    return Out20(run_fwd=c.run and not c.reverse, fault_reset=c.reset, speed_rpm=round(c.rpm))


def _out21(c: _Command) -> OutputAssembly:
    return Out21(
        run_fwd=c.run and not c.reverse,
        run_rev=c.run and c.reverse,
        fault_reset=c.reset,
        net_ctrl=c.desired.remote,
        net_ref=c.desired.remote,
        speed_rpm=round(c.rpm),
    )


def _out100(c: _Command) -> OutputAssembly:
    d, s = c.desired, c.settings
    return Out100(
        ramp_enable=c.run,
        general_enable=not d.coast_stop,
        reverse=c.reverse,
        jog=d.jog and not d.coast_stop and not d.quick_stop,
        remote=d.remote,
        fault_reset=c.reset,
        speed_counts=rpm_to_counts(c.rpm, s.max_rpm, s.weg_speed_scale),
    )


_COMMAND_BUILDERS = {
    AssemblyPair.BASIC: _out20,
    AssemblyPair.EXTENDED: _out21,
    AssemblyPair.WEG: _out100,
}


def capabilities(settings: ProfileSettings) -> Capabilities:
    """What the hub may ask of this drive with its assembly pair."""
    pair = settings.pair
    unsupported = {
        "quick_stop": f"the CFW-08 assemblies ({pair.label}) have no quick stop",
    }
    if pair is not AssemblyPair.WEG:
        unsupported["coast_stop"] = (
            f"assembly {pair.label} has no general disable (use 100/150 for a coast stop)"
        )
        unsupported["jog"] = f"assembly {pair.label} has no JOG bit (use 100/150)"
    # A stop kind the pair lacks becomes the nearest it has (issue 32 item 4): on 100/150
    # a quick stop is a general disable (Habilita Geral = 0, table 7: the motor coasts,
    # the quickest way the drive has to take the torque off); on 20/70 and 21/71, which
    # have no general disable, both become a ramp stop (Run = 0, seed 3.1.2).
    substitutes = {"quick_stop": "coast_stop"} if pair is AssemblyPair.WEG else {}
    if pair is not AssemblyPair.WEG:
        substitutes = {"quick_stop": "run", "coast_stop": "run"}
        del unsupported["coast_stop"]
    del unsupported["quick_stop"]
    reverse_refused = None
    if pair is AssemblyPair.BASIC:
        unsupported["direction"] = "assembly 20/70 runs forward only (Run Fwd); use 21/71"
        unsupported["remote"] = "assembly 20/70 has no network control bit; use 21/71"
        # Seed table 5: Run Fwd is the only run bit, so a reverse would go out as Run Fwd = 0
        # (a ramp stop) while the state said reverse. Refused instead (issue 17 item 5).
        reverse_refused = "assembly 20/70 has no reverse (Run Fwd only); use 21/71 or 100/150"
    return Capabilities(
        speed_scale=settings.speed_scale,
        unsupported=unsupported,
        reverse_refused=reverse_refused,
        stop_substitutes=substitutes,
    )


def _speed_fields(settings: ProfileSettings, rpm: float) -> Readings:
    return {
        "speed_rpm": round(rpm, 1),
        "speed_pct": round(100.0 * rpm / settings.max_rpm, 2),
    }


def _status(faulted: bool, running: bool, at_ref: bool, stopping: bool) -> DriveStatus:
    if faulted:
        return DriveStatus.FAULTED
    if running and stopping:
        return DriveStatus.STOPPING
    if running:
        return DriveStatus.RUNNING if at_ref else DriveStatus.STARTING
    return DriveStatus.READY


def _near(settings: ProfileSettings, actual: float, ref: float) -> bool:
    return abs(abs(actual) - abs(ref)) <= settings.at_reference_rpm


def _state70(s: ProfileSettings, a: InputAssembly, desired: DesiredCommand, ref: float) -> Readings:
    if not isinstance(a, In70):
        raise TypeError(a)
    # Seed 3.1.1: Running1 is set while the motor turns clockwise; 70 has no Running2
    # (table 5), and Speed Actual is a magnitude (0-9999, table 17). A motor turning
    # with Running1 clear turns counter-clockwise (P231 = 1, or commands from the keypad
    # or terminals): running, in reverse (issue 32 item 8).
    turning = a.speed_rpm != 0
    reverse = turning and not a.running1
    running = a.running1 or turning
    rpm = -float(a.speed_rpm) if reverse else float(a.speed_rpm)
    at_ref = running and _near(s, rpm, ref)
    return {
        "status": _status(a.faulted, running, at_ref, not desired.run),
        "running": running,
        "direction": Direction.REVERSE if reverse else Direction.FORWARD,
        "at_reference": at_ref,
        "remote": True,  # 20/70 has no local/remote bit (table 5): the profile reads 29h/15
        "alarm": False,
        "fault_code": None,
        "fault_text": None,
        "values": {"running1": int(a.running1)},
        **_speed_fields(s, rpm),
    }


_STATE71_STATUS: Mapping[int, DriveStatus] = {
    DriveStateCode.NON_EXISTENT: DriveStatus.NOT_READY,
    DriveStateCode.STARTUP: DriveStatus.NOT_READY,
    DriveStateCode.NOT_READY: DriveStatus.NOT_READY,
    DriveStateCode.READY: DriveStatus.READY,
    DriveStateCode.ENABLED: DriveStatus.RUNNING,
    DriveStateCode.STOPPING: DriveStatus.STOPPING,
    DriveStateCode.FAULT_STOP: DriveStatus.FAULTED,
    DriveStateCode.FAULTED: DriveStatus.FAULTED,
}


def _state71(s: ProfileSettings, a: InputAssembly, desired: DesiredCommand, ref: float) -> Readings:
    if not isinstance(a, In71):
        raise TypeError(a)
    status = _STATE71_STATUS.get(a.drive_state, DriveStatus.NOT_READY)
    if a.faulted:
        status = DriveStatus.FAULTED
    elif status is DriveStatus.RUNNING and not a.at_reference:
        status = DriveStatus.STARTING
    reverse = a.running2 and not a.running1
    rpm = -float(a.speed_rpm) if reverse else float(a.speed_rpm)
    return {
        "status": status,
        # table 16: Running1/2 also while Stopping or Fault Stop; a motor that turns
        # (Speed Actual, a magnitude) is running whatever the bits say
        "running": a.running1 or a.running2 or a.speed_rpm != 0,
        "direction": Direction.REVERSE if reverse else Direction.FORWARD,
        "at_reference": a.at_reference,
        "remote": a.ctrl_from_net,
        # seed 3.1.1: Ctrl from Net clear = the drive does not take its commands from
        # DeviceNet (P220/P229/P230, seed 4.2): it ignores run commands (issue 32 item 6)
        "local_control": not a.ctrl_from_net,
        "alarm": a.warning,
        "fault_code": None,
        "fault_text": None,
        "values": {"drive_state": a.drive_state, "ref_from_net": int(a.ref_from_net)},
        **_speed_fields(s, rpm),
    }


def _state150(
    s: ProfileSettings, a: InputAssembly, desired: DesiredCommand, ref: float
) -> Readings:
    if not isinstance(a, In150):
        raise TypeError(a)
    magnitude = counts_to_rpm(a.speed_counts, s.max_rpm, s.weg_speed_scale)
    rpm = magnitude if a.forward else -magnitude
    # a motor that turns is running, enabled or not (a fault or general disable coasts it)
    running = a.speed_counts != 0 or (a.general_enabled and (a.ramp_enabled or a.jog))
    at_ref = running and a.ramp_enabled and _near(s, magnitude, ref)
    stopping = running and not a.ramp_enabled and not a.jog
    code = a.error_code if a.error else None
    return {
        "status": _status(a.error, running, at_ref, stopping),
        "running": running,
        "direction": Direction.FORWARD if a.forward else Direction.REVERSE,
        "at_reference": at_ref,
        "remote": a.remote,
        "alarm": a.undervoltage,
        "fault_code": code,
        "fault_text": fault_text(code),
        "values": {"logical_state": a.error_code, "undervoltage": int(a.undervoltage)},
        **_speed_fields(s, rpm),
    }


_STATE_MAPPERS = {
    AssemblyPair.BASIC: _state70,
    AssemblyPair.EXTENDED: _state71,
    AssemblyPair.WEG: _state150,
}


def state_changes(settings: ProfileSettings, data: bytes, desired: DesiredCommand) -> Readings:
    """The DriveState fields an input assembly gives (raises AssemblyDecodeError)."""
    assembly = decode_input(settings.pair.input_instance, data)
    ref = min(reference_rpm(settings, desired), settings.max_rpm)
    changes = _STATE_MAPPERS[settings.pair](settings, assembly, desired, ref)
    sign = -1.0 if _reverse(desired) else 1.0
    changes["speed_ref_rpm"] = round(sign * ref, 1)
    changes["speed_ref_pct"] = round(100.0 * sign * ref / settings.max_rpm, 2)
    changes["speed_base"] = settings.speed_scale.label
    return changes
