"""The Modbus register map: tables in code, rendered into docs/modbus-map.md.

Addresses are 0-based, exactly as clients send them in the PDU (no hidden +1).
Each drive with a ``modbus_unit`` is one unit id; unit 0 and
``modbus.gateway_unit`` serve the gateway's own health. Input registers hold
status; holding registers 0-3 take commands; holding ``MIRROR_OFFSET + n``
mirrors input register ``n`` (read-only) for clients that know only function 3.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from gateway.hub import DrivePolicy
from gateway.modbus.command import CommandWord, HoldingWrite
from gateway.modbus.regs import (
    BITS16,
    CODE16,
    COUNTER32,
    INT16,
    NULL_INT16,
    UINT16,
    ExceptionCode,
    Field,
    RegType,
    Value,
    WriteRefused,
    encode_block,
    to_signed16,
)
from gateway.model import (
    CommState,
    ControlMode,
    DesiredCommand,
    Device,
    Direction,
    DriveState,
    DriveStatus,
    Source,
    SpeedScale,
)

MIRROR_OFFSET = 100
"""Holding register ``MIRROR_OFFSET + n`` reads input register ``n`` (function 3)."""

# ----------------------------------------------------------------- code tables

COMM_CODES: dict[CommState, int] = {
    CommState.OFFLINE: 0,
    CommState.CONNECTING: 1,
    CommState.ONLINE: 2,
    CommState.CLEAR: 3,
}
SOURCE_CODES: dict[Source, int] = {
    Source.NONE: 0,
    Source.ZENOH: 1,
    Source.MODBUS: 2,
    Source.GATEWAY: 3,
    Source.WEB: 4,
    Source.OPCUA: 5,
}
CONTROL_CODES: dict[ControlMode, int] = {
    ControlMode.ANY: 0,
    ControlMode.ZENOH: 1,
    ControlMode.MODBUS: 2,
    ControlMode.WEB: 3,
    ControlMode.OPCUA: 4,
}
DEVICE_CODES: dict[Device, int] = {device: device.spec.code for device in Device}
"""From the device registry (gateway/devices.py)."""
UNKNOWN_DEVICE_CODE = 0


# ----------------------------------------------------------------- drive unit


@dataclass(frozen=True, slots=True)
class DriveView:
    """What a drive unit's input registers are computed from."""

    state: DriveState
    policy: DrivePolicy


@dataclass(frozen=True, slots=True)
class StatusBit:
    bit: int
    name: str
    doc: str
    test: Callable[[DriveState], bool]

    @property
    def mask(self) -> int:
        return 1 << self.bit


READY_STATUSES = frozenset(
    {DriveStatus.READY, DriveStatus.STARTING, DriveStatus.RUNNING, DriveStatus.STOPPING}
)

STATUS_BITS: tuple[StatusBit, ...] = (
    StatusBit(0, "online", "comm state is online", lambda s: s.online),
    StatusBit(
        1,
        "ready",
        "online and status is ready, starting, running or stopping (no fault)",
        lambda s: s.online and s.status in READY_STATUSES,
    ),
    StatusBit(2, "running", "the motor is running (output on and turning)", lambda s: s.running),
    StatusBit(3, "reverse", "direction is reverse", lambda s: s.direction is Direction.REVERSE),
    StatusBit(4, "at_reference", "speed is at the reference", lambda s: s.at_reference),
    StatusBit(5, "faulted", "faulted, or tripped (soft starter)", lambda s: s.faulted),
    StatusBit(6, "alarm", "an alarm (warning) is active", lambda s: s.alarm),
    StatusBit(7, "remote", "the drive takes its commands from the network", lambda s: s.remote),
    StatusBit(
        8,
        "local_control",
        "the drive ignores the network's run commands (local control): runs are refused, "
        "stops are still sent",
        lambda s: s.local_control,
    ),
    StatusBit(
        9,
        "no_failsafe",
        "the drive keeps running if the gateway is lost (its comm-loss reaction is off)",
        lambda s: s.failsafe is False,
    ),
    StatusBit(
        10,
        "doubtful",
        "frames that contradict each other were heard for this drive: its readings may be "
        "forged; runs are refused",
        lambda s: s.doubtful,
    ),
)
"""Input register 0. Bits 11-15 are reserved and read 0."""


def status_flags(state: DriveState) -> int:
    return sum(b.mask for b in STATUS_BITS if b.test(state))


def _timeout_ds(view: DriveView) -> Value:
    timeout = view.policy.command_timeout
    return 0 if timeout is None else timeout


DRIVE_INPUTS: tuple[Field[DriveView], ...] = (
    Field(
        0,
        "status_flags",
        BITS16,
        "bits",
        "see the status bits table",
        lambda v: status_flags(v.state),
    ),
    Field(
        1,
        "status_code",
        CODE16,
        "code",
        "drive status, see the status codes table",
        lambda v: int(v.state.status),
    ),
    Field(
        2,
        "speed_rpm",
        INT16,
        "rpm",
        "speed actual, signed (negative = reverse)",
        lambda v: v.state.speed_rpm,
    ),
    Field(
        3,
        "speed_pct",
        INT16,
        "0.01 %",
        "speed actual in % of the drive's scale base",
        lambda v: v.state.speed_pct,
        100.0,
    ),
    Field(
        4,
        "speed_ref_rpm",
        INT16,
        "rpm",
        "speed reference in force in the drive, as it reports it",
        lambda v: v.state.speed_ref_rpm,
    ),
    Field(
        5,
        "speed_ref_pct",
        INT16,
        "0.01 %",
        "speed reference in force in the drive, in %",
        lambda v: v.state.speed_ref_pct,
        100.0,
    ),
    Field(6, "current_a", UINT16, "0.1 A", "motor current", lambda v: v.state.current_a, 10.0),
    Field(
        7,
        "current_pct_flc",
        UINT16,
        "0.1 %FLC",
        "motor current in % of full-load current",
        lambda v: v.state.current_pct_flc,
        10.0,
    ),
    Field(
        8,
        "motor_temp_pct",
        UINT16,
        "0.1 %",
        "motor temperature (thermal model) in %",
        lambda v: v.state.motor_temp_pct,
        10.0,
    ),
    Field(9, "power_kw", INT16, "0.1 kW", "output power, signed", lambda v: v.state.power_kw, 10.0),
    Field(
        10,
        "voltage_v",
        UINT16,
        "0.1 V",
        "output (or line) voltage as the device reports it",
        lambda v: v.state.voltage_v,
        10.0,
    ),
    Field(
        11,
        "fault_code",
        UINT16,
        "code",
        "the device's own fault code; 0xFFFF: none (no fault, or no code given)",
        lambda v: v.state.fault_code,
    ),
    Field(
        12,
        "alarm_code",
        UINT16,
        "code",
        "the device's own alarm code; 0xFFFF: none",
        lambda v: v.state.alarm_code,
    ),
    Field(
        13,
        "comm_state",
        CODE16,
        "code",
        "communication state, see the comm codes table",
        lambda v: COMM_CODES[v.state.comm],
    ),
    Field(
        14,
        "control_source",
        CODE16,
        "code",
        "who gave the command in force, see the source codes table",
        lambda v: SOURCE_CODES[v.state.control_source],
    ),
    Field(
        15,
        "control_mode",
        CODE16,
        "code",
        "the drive's `control` setting, see the control codes table",
        lambda v: CONTROL_CODES[v.policy.control],
    ),
    Field(
        16,
        "command_timeout",
        CODE16,
        "0.1 s",
        "the drive's `command_timeout` (command watchdog); 0: no watchdog",
        _timeout_ds,
        10.0,
    ),
    Field(
        17,
        "state_seq",
        COUNTER32,
        "count",
        "update counter: changes with every new state of the drive (wraps)",
        lambda v: v.state.seq,
    ),
    Field(
        19,
        "device_code",
        CODE16,
        "code",
        "device model, see the device codes table",
        lambda v: DEVICE_CODES.get(v.state.device, UNKNOWN_DEVICE_CODE),
    ),
    Field(
        20,
        "bus_address",
        CODE16,
        "address",
        "the drive's address on its fieldbus",
        lambda v: v.state.address,
    ),
)
"""Input registers of a drive unit (function 4), mirrored at holding ``MIRROR_OFFSET + n``."""


def encode_drive_inputs(view: DriveView) -> list[int]:
    return encode_block(DRIVE_INPUTS, view)


@dataclass(frozen=True, slots=True)
class HoldingView:
    """What the command holding registers read back: the hub's desired command."""

    desired: DesiredCommand
    scale: SpeedScale | None


def _desired_rpm(v: HoldingView) -> Value:
    if v.desired.speed_rpm is not None:
        return v.desired.speed_rpm
    if v.desired.speed_pct is not None and v.scale is not None:
        return v.scale.pct_to_rpm(v.desired.speed_pct)
    return None


def _desired_pct(v: HoldingView) -> Value:
    if v.desired.speed_pct is not None:
        return v.desired.speed_pct
    if v.desired.speed_rpm is not None and v.scale is not None:
        return v.scale.rpm_to_pct(v.desired.speed_rpm)
    return None


@dataclass(frozen=True, slots=True)
class HoldingField:
    """A writable holding register of a drive unit."""

    address: int
    name: str
    type: RegType
    unit: str
    doc: str
    readback: Field[HoldingView] | None  # None: reads back the last value written
    scale: float = 1.0


DRIVE_HOLDINGS: tuple[HoldingField, ...] = (
    HoldingField(
        0,
        "command",
        BITS16,
        "bits",
        "command word, see the command bits table",
        Field(
            0,
            "command",
            BITS16,
            "bits",
            "",
            lambda v: CommandWord.from_desired(v.desired).to_register(),
        ),
    ),
    HoldingField(
        1,
        "speed_ref_rpm",
        INT16,
        "rpm",
        "speed reference (direction: command bit 1); 0x8000: not given",
        Field(1, "speed_ref_rpm", INT16, "rpm", "", _desired_rpm),
    ),
    HoldingField(
        2,
        "speed_ref_pct",
        INT16,
        "0.01 %",
        "speed reference in % of the drive's scale base; 0x8000: not given",
        Field(2, "speed_ref_pct", INT16, "0.01 %", "", _desired_pct, 100.0),
        100.0,
    ),
    HoldingField(
        3,
        "keepalive",
        UINT16,
        "any",
        "command watchdog keep-alive: any value; a write feeds the watchdog while Modbus "
        "has control (it never takes control)",
        None,
    ),
)
"""Holding registers 0-3 of a drive unit (functions 3, 6, 16, 22, 23)."""

WRITABLE_HOLDINGS = frozenset(h.address for h in DRIVE_HOLDINGS)


def encode_holding_readback(view: HoldingView) -> list[int]:
    """Holding registers 0-2 as read: the hub's desired command."""
    out: list[int] = []
    for h in DRIVE_HOLDINGS:
        if h.readback is not None:
            out.extend(h.readback.encode(view))
    return out


def _speed_value(raw: int, scale: float) -> float | None:
    if raw == NULL_INT16:
        return None
    return to_signed16(raw) / scale


def decode_holding_write(
    address: int, values: Sequence[int], scale: SpeedScale | None
) -> HoldingWrite:
    """Validate a write to a drive unit's holding registers; all or nothing.

    Raises :class:`WriteRefused` with exception 2 (an address that is not a
    writable register) or 3 (a value out of range).
    """
    regs: dict[int, int] = {}
    for i, raw in enumerate(values):
        addr = address + i
        if addr not in WRITABLE_HOLDINGS:
            raise WriteRefused(
                ExceptionCode.ILLEGAL_DATA_ADDRESS, f"holding register {addr} is not writable"
            )
        if not 0 <= raw <= 0xFFFF:
            raise WriteRefused(
                ExceptionCode.ILLEGAL_DATA_VALUE,
                f"holding register {addr}: {raw} is not a register value (limit 0-65535)",
            )
        regs[addr] = raw
    word = CommandWord.from_register(regs[0]) if 0 in regs else None
    rpm = _speed_value(regs[1], 1.0) if 1 in regs else None
    pct = _speed_value(regs[2], 100.0) if 2 in regs else None
    if rpm is not None and pct is not None:
        raise WriteRefused(
            ExceptionCode.ILLEGAL_DATA_VALUE,
            "give the speed in rpm or in %, not both (write 0x8000 to the other one)",
        )
    _check_speed(rpm, pct, scale)
    return HoldingWrite(
        word=word,
        speed_rpm=rpm,
        speed_pct=pct,
        keepalive=regs.get(3),
        command=any(a in regs for a in (0, 1, 2)),
    )


def _check_speed(rpm: float | None, pct: float | None, scale: SpeedScale | None) -> None:
    if scale is None:
        return  # not known (offline) or no speed (soft starter): the hub decides
    if rpm is not None and abs(rpm) > scale.max_rpm + 1e-9:
        raise WriteRefused(
            ExceptionCode.ILLEGAL_DATA_VALUE,
            f"holding register 1 (speed_rpm): speed {rpm:g} rpm is beyond the drive's scale"
            f" (limit ±{scale.max_rpm:g} rpm)",
        )
    if pct is not None and abs(pct) > scale.max_pct + 1e-9:
        raise WriteRefused(
            ExceptionCode.ILLEGAL_DATA_VALUE,
            f"holding register 2 (speed_pct): speed {pct:g} % is beyond the drive's scale"
            f" (limit ±{scale.max_pct:g} %)",
        )


# ----------------------------------------------------------------- functions

READ_FUNCTIONS = frozenset({3, 4})
WRITE_FUNCTIONS = frozenset({6, 16, 22, 23})
BIT_FUNCTIONS = frozenset({1, 2, 5, 15})
SERVED_FUNCTIONS = READ_FUNCTIONS | WRITE_FUNCTIONS | BIT_FUNCTIONS
"""Function codes answered from the map (bit functions always with exception 2)."""

FUNCTION_NAMES: dict[int, str] = {
    1: "read coils",
    2: "read discrete inputs",
    3: "read holding registers",
    4: "read input registers",
    5: "write single coil",
    6: "write single register",
    15: "write multiple coils",
    16: "write multiple registers",
    22: "mask write register",
    23: "read/write multiple registers",
}
