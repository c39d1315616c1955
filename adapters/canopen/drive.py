"""CiA 402 drives in the common drive model (gateway/model.py).

Statusword (CiA 402-2 §6.2): the state (masks 0x4F/0x6F), bit 7 warning -> alarm, bit 9
remote, bit 10 target reached -> at reference. Velocity actual (0x6044 rpm in vl,
0x606C velocity units in pv, / ``speed_scale`` per rpm), % of ``max_rpm``. Current
actual 0x6078 and torque actual 0x6077 are per mille of the rated value (0x6075 rated
current in mA). A fault's code is the EMCY error code or 0x603F, its text from the
CiA 301/402 tables (adapters/canopen/codec/codes.py).
"""

from __future__ import annotations

import functools

from adapters.canopen.codec import cia402
from adapters.canopen.codec.cia402 import State
from adapters.canopen.codec.codes import emcy_text
from adapters.canopen.master.control import Want
from adapters.canopen.options import DriveOptions, Mode
from gateway.model import DesiredCommand, Direction, DriveStatus, Readings

MOVING_RPM = 1.0  # |speed| above which a drive that is not enabled is still stopping


def speed_ref_rpm(desired: DesiredCommand, opts: DriveOptions) -> float:
    """The signed speed reference the command asks for, in rpm, within +-max_rpm: reverse
    when the direction is reverse or the speed negative, not both (as on every bus)."""
    if desired.speed_rpm is not None:
        rpm = abs(desired.speed_rpm)
    elif desired.speed_pct is not None:
        rpm = abs(desired.speed_pct) * opts.max_rpm / 100.0
    else:
        rpm = 0.0
    rpm = min(rpm, opts.max_rpm)
    negative = (desired.speed_rpm or 0.0) < 0 or (desired.speed_pct or 0.0) < 0
    return -rpm if (desired.direction is Direction.REVERSE) != negative else rpm


def want(desired: DesiredCommand, opts: DriveOptions) -> Want:
    """The engine's wish for a drive from the gateway's desired command."""
    raw = round(speed_ref_rpm(desired, opts) * opts.speed_scale)
    return Want(
        run=desired.run,
        quick_stop=desired.quick_stop,
        coast=desired.coast_stop,
        target=raw,
    )


@functools.lru_cache(maxsize=64)
def speed_base(mode: Mode, max_rpm: float, speed_scale: float) -> str:
    """What 100 % speed is, with its value and the object the speed is written to:
    ``"100 % = max_rpm 1800 rpm; 0x6042 in rpm"`` (vl), ``"100 % = max_rpm 1500 rpm;
    0x60FF = rpm x 10"`` (pv with ``speed_scale = 10``). Made once per drive's settings,
    not per TPDO1."""
    target = "0x6042" if mode is Mode.VELOCITY else "0x60FF"
    unit = "in rpm" if speed_scale == 1.0 else f"= rpm x {speed_scale:g}"
    return f"100 % = max_rpm {max_rpm:g} rpm; {target} {unit}"


def status_of(state: State | None, speed_rpm: float) -> DriveStatus:
    if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
        return DriveStatus.FAULTED
    if state is State.OPERATION_ENABLED:
        return DriveStatus.RUNNING
    if state is State.QUICK_STOP_ACTIVE:
        return DriveStatus.STOPPING
    if state in (State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
        return DriveStatus.STOPPING if abs(speed_rpm) > MOVING_RPM else DriveStatus.READY
    return DriveStatus.NOT_READY


def readings(
    statusword: int,
    values: tuple[int, ...],
    desired: DesiredCommand,
    opts: DriveOptions,
    fault_code: int | None,
) -> Readings:
    """The model's readings from TPDO1 (statusword, actual velocity, then the extras)."""
    try:
        state: State | None = cia402.decode_state(statusword)
    except ValueError:
        state = None
    speed_rpm = values[0] / opts.speed_scale if values else 0.0
    ref = speed_ref_rpm(desired, opts)
    running = state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE) or (
        abs(speed_rpm) > MOVING_RPM
    )
    if speed_rpm > MOVING_RPM:
        direction = Direction.FORWARD
    elif speed_rpm < -MOVING_RPM:
        direction = Direction.REVERSE
    else:
        direction = Direction.REVERSE if ref < 0 else Direction.FORWARD
    faulted = state in (State.FAULT, State.FAULT_REACTION_ACTIVE)
    out: Readings = {
        "status": status_of(state, speed_rpm),
        "running": running,
        "direction": direction,
        "at_reference": state is State.OPERATION_ENABLED
        and bool(statusword & cia402.SW_TARGET_REACHED),
        "remote": bool(statusword & cia402.SW_REMOTE),
        "alarm": bool(statusword & cia402.SW_WARNING),
        "speed_rpm": round(speed_rpm, 2),
        "speed_pct": round(100.0 * speed_rpm / opts.max_rpm, 2),
        "speed_ref_rpm": round(ref, 2) if desired.run else 0.0,
        "speed_ref_pct": round(100.0 * ref / opts.max_rpm, 2) if desired.run else 0.0,
        "fault_code": fault_code if faulted else None,
        "fault_text": emcy_text(fault_code) if faulted and fault_code is not None else None,
        "speed_base": speed_base(opts.mode, opts.max_rpm, opts.speed_scale),
    }
    extras = dict(zip((v.index for v in opts.extras), values[1:], strict=False))
    current = extras.get(cia402.CURRENT_ACTUAL)
    if current is not None and opts.rated_current is not None:
        out["current_a"] = round(current / 1000.0 * opts.rated_current, 2)
    named: dict[str, float | int] = {"statusword": statusword}
    if current is not None:
        named["current_permille"] = current
    torque = extras.get(cia402.TORQUE_ACTUAL)
    if torque is not None:
        named["torque_permille"] = torque
    out["values"] = named
    return out
