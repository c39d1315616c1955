"""CiA 402 (IEC 61800-7-201) drive profile facts: the power drive state machine,
controlword commands, statusword bits and option codes.

CiA 402-2 §6.2 (state machine, figure "Power drive system state machine", the
statusword table with masks 0x4F/0x6F and the controlword command table), §6.3
(quick stop option code 0x605A, abort connection option code 0x6007), §6.4 (modes of
operation 0x6060).
"""

from __future__ import annotations

from enum import Enum, IntEnum

from adapters.canopen.errors import Cia402DecodeError

# Object indexes of the drive profile (CiA 402-2 object dictionary).
ABORT_CONNECTION_OPTION = 0x6007
ERROR_CODE = 0x603F
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
VL_TARGET_VELOCITY = 0x6042  # INTEGER16, rpm (velocity mode, vl)
VL_VELOCITY_DEMAND = 0x6043
VL_VELOCITY_ACTUAL = 0x6044  # INTEGER16, rpm
QUICK_STOP_OPTION = 0x605A
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
VELOCITY_ACTUAL = 0x606C  # INTEGER32, velocity units (profile velocity)
TORQUE_ACTUAL = 0x6077  # INTEGER16, per thousand of rated torque
CURRENT_ACTUAL = 0x6078  # INTEGER16, per thousand of rated current
TARGET_VELOCITY = 0x60FF  # INTEGER32, velocity units (profile velocity)


class State(Enum):
    """The eight states of the power drive system state machine (CiA 402-2 §6.2)."""

    NOT_READY_TO_SWITCH_ON = "not_ready_to_switch_on"
    SWITCH_ON_DISABLED = "switch_on_disabled"
    READY_TO_SWITCH_ON = "ready_to_switch_on"
    SWITCHED_ON = "switched_on"
    OPERATION_ENABLED = "operation_enabled"
    QUICK_STOP_ACTIVE = "quick_stop_active"
    FAULT_REACTION_ACTIVE = "fault_reaction_active"
    FAULT = "fault"


# Statusword bits (CiA 402-2 §6.2, statusword 0x6041).
SW_READY_TO_SWITCH_ON = 0x0001
SW_SWITCHED_ON = 0x0002
SW_OPERATION_ENABLED = 0x0004
SW_FAULT = 0x0008
SW_VOLTAGE_ENABLED = 0x0010
SW_QUICK_STOP = 0x0020  # 0 = quick stop active (low active)
SW_SWITCH_ON_DISABLED = 0x0040
SW_WARNING = 0x0080
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_INTERNAL_LIMIT = 0x0800
SW_STATE_BITS = 0x006F  # bits 0-3, 5, 6

# (mask, value, state) in the order of the standard's table; the first match wins.
_STATE_PATTERNS: tuple[tuple[int, int, State], ...] = (
    (0x4F, 0x00, State.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY_TO_SWITCH_ON),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, State.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, State.FAULT),
)

_STATE_BITS: dict[State, int] = {
    State.NOT_READY_TO_SWITCH_ON: 0x00,
    State.SWITCH_ON_DISABLED: 0x40,
    State.READY_TO_SWITCH_ON: 0x21,
    State.SWITCHED_ON: 0x23,
    State.OPERATION_ENABLED: 0x27,
    State.QUICK_STOP_ACTIVE: 0x07,
    State.FAULT_REACTION_ACTIVE: 0x0F,
    State.FAULT: 0x08,
}


def decode_state(statusword: int) -> State:
    """The state a statusword reports (masks 0x4F/0x6F of the standard's table);
    :class:`Cia402DecodeError` for a pattern that matches no state."""
    if isinstance(statusword, bool) or not isinstance(statusword, int):
        raise Cia402DecodeError(f"statusword must be an int, not {statusword!r}")
    for mask, value, state in _STATE_PATTERNS:
        if statusword & mask == value:
            return state
    raise Cia402DecodeError(
        f"statusword 0x{statusword & 0xFFFF:04X} matches no CiA 402 state",
        (statusword & 0xFFFF).to_bytes(2, "little"),
    )


def statusword_bits(state: State) -> int:
    """The state's own statusword bits (bits 0-3, 5, 6 only; the rest is up to the caller)."""
    return _STATE_BITS[state]


class Cw(IntEnum):
    """Controlword (0x6040) commands, bits 0-3 and 7 (CiA 402-2 §6.2 command table).

    ``DISABLE_OPERATION`` has the bits of ``SWITCH_ON`` (the state tells them apart);
    ``FAULT_RESET_BIT`` acts on its 0 -> 1 edge only; ``HALT_BIT`` is bit 8.
    """

    DISABLE_VOLTAGE = 0x00
    QUICK_STOP = 0x02
    SHUTDOWN = 0x06
    SWITCH_ON = 0x07
    DISABLE_OPERATION = 0x07
    ENABLE_OPERATION = 0x0F
    FAULT_RESET_BIT = 0x80
    HALT_BIT = 0x100


# The command table's masks (bits that matter, value they must have).
CW_MASK_SHUTDOWN = (0x87, 0x06)
CW_MASK_SWITCH_ON = (0x8F, 0x07)
CW_MASK_DISABLE_VOLTAGE = (0x82, 0x00)
CW_MASK_QUICK_STOP = (0x86, 0x02)
CW_MASK_DISABLE_OPERATION = (0x8F, 0x07)
CW_MASK_ENABLE_OPERATION = (0x8F, 0x0F)


class DeviceCommand(Enum):
    """A controlword's meaning to the drive (CiA 402-2 command table)."""

    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch_on"  # also "disable operation" from OPERATION_ENABLED
    DISABLE_VOLTAGE = "disable_voltage"
    QUICK_STOP = "quick_stop"
    ENABLE_OPERATION = "enable_operation"
    FAULT_RESET = "fault_reset"  # bit 7 set: acts on its rising edge only


_COMMAND_MASKS: tuple[tuple[tuple[int, int], DeviceCommand], ...] = (
    (CW_MASK_DISABLE_VOLTAGE, DeviceCommand.DISABLE_VOLTAGE),
    (CW_MASK_QUICK_STOP, DeviceCommand.QUICK_STOP),
    (CW_MASK_SHUTDOWN, DeviceCommand.SHUTDOWN),
    (CW_MASK_SWITCH_ON, DeviceCommand.SWITCH_ON),
    (CW_MASK_ENABLE_OPERATION, DeviceCommand.ENABLE_OPERATION),
)


def device_command(controlword: int) -> DeviceCommand | None:
    """Which of the standard's commands a controlword is, by the table's masks.

    Bit 7 set is ``FAULT_RESET`` (the caller sees the edge by comparing with the word
    before). None only for a word the table leaves undefined (bits 0-3 all matched
    by no row; with the masks above every word with bit 7 clear matches one row, so
    None marks a word that is not a 16-bit unsigned).
    """
    if isinstance(controlword, bool) or not isinstance(controlword, int):
        return None
    if not 0 <= controlword <= 0xFFFF:
        return None
    if controlword & Cw.FAULT_RESET_BIT:
        return DeviceCommand.FAULT_RESET
    for (mask, value), command in _COMMAND_MASKS:
        if controlword & mask == value:
            return command
    return None


def controlword(command: DeviceCommand, *, halt: bool = False, extra: int = 0) -> int:
    """The controlword for ``command`` (fault reset sets bit 7; the master must send a
    word without it first so the drive sees the edge), with bit 8 for ``halt`` and
    ``extra`` mode-specific bits 4-6."""
    base = {
        DeviceCommand.SHUTDOWN: Cw.SHUTDOWN,
        DeviceCommand.SWITCH_ON: Cw.SWITCH_ON,
        DeviceCommand.DISABLE_VOLTAGE: Cw.DISABLE_VOLTAGE,
        DeviceCommand.QUICK_STOP: Cw.QUICK_STOP,
        DeviceCommand.ENABLE_OPERATION: Cw.ENABLE_OPERATION,
        DeviceCommand.FAULT_RESET: Cw.FAULT_RESET_BIT,
    }[command]
    return int(base) | (Cw.HALT_BIT if halt else 0) | (extra & 0x70)


# The drive-side transitions of CiA 402-2 §6.2 (number, from, command, to). Transitions
# 0, 1 (power-up), 13 (fault) and 14 (fault reaction done) are the drive's own.
TRANSITIONS: tuple[tuple[int, State, DeviceCommand, State], ...] = (
    (2, State.SWITCH_ON_DISABLED, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),
    (3, State.READY_TO_SWITCH_ON, DeviceCommand.SWITCH_ON, State.SWITCHED_ON),
    (3, State.READY_TO_SWITCH_ON, DeviceCommand.ENABLE_OPERATION, State.SWITCHED_ON),
    (4, State.SWITCHED_ON, DeviceCommand.ENABLE_OPERATION, State.OPERATION_ENABLED),
    (5, State.OPERATION_ENABLED, DeviceCommand.SWITCH_ON, State.SWITCHED_ON),
    (6, State.SWITCHED_ON, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),
    (7, State.READY_TO_SWITCH_ON, DeviceCommand.QUICK_STOP, State.SWITCH_ON_DISABLED),
    (7, State.READY_TO_SWITCH_ON, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
    (8, State.OPERATION_ENABLED, DeviceCommand.SHUTDOWN, State.READY_TO_SWITCH_ON),
    (9, State.OPERATION_ENABLED, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
    (10, State.SWITCHED_ON, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
    (10, State.SWITCHED_ON, DeviceCommand.QUICK_STOP, State.SWITCH_ON_DISABLED),
    (11, State.OPERATION_ENABLED, DeviceCommand.QUICK_STOP, State.QUICK_STOP_ACTIVE),
    (12, State.QUICK_STOP_ACTIVE, DeviceCommand.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
    (15, State.FAULT, DeviceCommand.FAULT_RESET, State.SWITCH_ON_DISABLED),
    (16, State.QUICK_STOP_ACTIVE, DeviceCommand.ENABLE_OPERATION, State.OPERATION_ENABLED),
)
# Transition 3 with ENABLE_OPERATION: the table's "switch on + enable operation" (0x0F)
# from READY_TO_SWITCH_ON goes through SWITCHED_ON and on to OPERATION_ENABLED (4).


def next_state(state: State, command: DeviceCommand) -> State | None:
    """The state a drive goes to on ``command`` (one transition), or None when the
    command does not move it. Transition 12 after a finished quick stop with options
    1-4 and transition 16 only with options 5-8 are the drive's to decide
    (see :func:`quick_stop_stays`)."""
    for _number, from_state, cmd, to_state in TRANSITIONS:
        if from_state is state and cmd is command:
            return to_state
    return None


# Quick stop option code 0x605A (CiA 402-2 §6.3.3).
QUICK_STOP_OPTIONS: dict[int, str] = {
    0: "disable drive function (coast)",
    1: "slow down on slow down ramp, then switch on disabled",
    2: "slow down on quick stop ramp, then switch on disabled",
    3: "slow down on current limit, then switch on disabled",
    4: "slow down on voltage limit, then switch on disabled",
    5: "slow down on slow down ramp, stay in quick stop active",
    6: "slow down on quick stop ramp, stay in quick stop active",
    7: "slow down on current limit, stay in quick stop active",
    8: "slow down on voltage limit, stay in quick stop active",
}

# Abort connection option code 0x6007 (CiA 402-2 §6.3.1): the drive's reaction to a
# lost connection (heartbeat or node guarding error, bus off, NMT stop).
ABORT_CONNECTION_OPTIONS: dict[int, str] = {
    0: "no action",
    1: "fault signal",
    2: "disable voltage command",
    3: "quick stop command",
}

# Modes of operation 0x6060 (CiA 402-2 §6.4).
MODE_PROFILE_POSITION = 1
MODE_VELOCITY = 2
MODE_PROFILE_VELOCITY = 3
MODE_PROFILE_TORQUE = 4
MODES_OF_OPERATION_TEXT: dict[int, str] = {
    1: "profile position",
    2: "velocity (vl)",
    3: "profile velocity",
    4: "profile torque",
    6: "homing",
    7: "interpolated position",
    8: "cyclic synchronous position",
    9: "cyclic synchronous velocity",
    10: "cyclic synchronous torque",
}


def quick_stop_option_text(code: int) -> str:
    """The text of a 0x605A value (negative values are the manufacturer's)."""
    if code < 0:
        return f"manufacturer specific ({code})"
    return QUICK_STOP_OPTIONS.get(code, f"reserved ({code})")


def quick_stop_stays(code: int) -> bool:
    """True when option ``code`` keeps the drive in QUICK_STOP_ACTIVE after stopping
    (5-8, where transition 16 is possible); False when it goes on to switch on disabled."""
    return 5 <= code <= 8


def abort_connection_option_text(code: int) -> str:
    """The text of a 0x6007 value (negative values are the manufacturer's)."""
    if code < 0:
        return f"manufacturer specific ({code})"
    return ABORT_CONNECTION_OPTIONS.get(code, f"reserved ({code})")
