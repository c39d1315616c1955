"""The master's side of the CiA 402 state machine: which controlword moves a drive
from the state its statusword shows toward the state the gateway wants.

CiA 402-2 §6.2: the master commands transitions with the controlword (Shutdown 2/6/8,
Switch on 3, Enable operation 4, Disable operation 5, Disable voltage 7/9/10/12,
Quick stop 7/10/11, Fault reset 15 on the 0 -> 1 edge of bit 7). A pure function of
the state and the wish, so every cycle sends the word for where the drive is now; the
fault reset edge is the engine's (one pulse, never repeated).

Safety (docs/architecture.md, safety rules 1, 2): a quick stop releases through Disable voltage
(transition 12), never transition 16 (it would restart the drive without a new run
command); a drive leaves FAULT only on the gateway's reset edge or its own means.
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.canopen.codec.cia402 import Cw, State

# vl mode (0x6060 = 2): controlword bits 4-6 must be set for the ramp function
# generator to follow the target (CiA 402-2 §10.2, rfg enable, unlock, use reference).
VL_OPERATION_BITS = 0x70


@dataclass(frozen=True, slots=True)
class Want:
    """What the gateway wants of one drive.

    ``run``: operation enabled (else switched on, the drive ramps down per 0x605C);
    ``quick_stop``: latched quick stop (transition 11, then held); ``coast``: latched
    disable voltage (the motor coasts). ``target``: the raw target velocity.
    """

    run: bool = False
    quick_stop: bool = False
    coast: bool = False
    target: int = 0


STOPPED = Want()


def controlword(state: State | None, want: Want, *, mode_bits: int = 0) -> int:
    """The controlword to send now (without the fault reset bit: see the engine).

    ``state`` None: not known yet (no statusword): Disable voltage, which never starts
    anything. ``mode_bits``: the mode's operation bits added to Enable operation (vl's
    0x70).
    """
    if state is None or want.coast:
        return int(Cw.DISABLE_VOLTAGE)
    if want.quick_stop:
        if state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
            return int(Cw.QUICK_STOP)  # 11, then held in QUICK_STOP_ACTIVE
        return int(Cw.DISABLE_VOLTAGE)  # 7, 10 or stays: never toward operation
    if state is State.QUICK_STOP_ACTIVE:
        return int(Cw.DISABLE_VOLTAGE)  # 12 (not 16: a run needs a new command)
    if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
        return int(Cw.DISABLE_VOLTAGE)  # waits for the reset edge
    if state in (State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED):
        return int(Cw.SHUTDOWN)  # 2
    if state is State.READY_TO_SWITCH_ON:
        return int(Cw.SWITCH_ON)  # 3
    if want.run:
        return int(Cw.ENABLE_OPERATION) | mode_bits  # 4, or held in OPERATION_ENABLED
    return int(Cw.DISABLE_OPERATION)  # 5 from OPERATION_ENABLED, held in SWITCHED_ON


def target(state: State | None, want: Want) -> int:
    """The target velocity to send: the wanted one while running, else 0."""
    if state is State.OPERATION_ENABLED and want.run and not (want.quick_stop or want.coast):
        return want.target
    return 0
