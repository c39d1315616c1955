"""One WEG data profile (P0741) as the simulated drive speaks it: what the two share.

The drive takes the control and reference words of the data profile in force (P0741 as
taken at Set_Prm or when cyclic data stopped: :mod:`.manufacturer` or :mod:`.profidrive`)
and answers with that profile's status and speed words. The rest is the drive's own
(:mod:`.drive`): command sources, motor, faults, the reaction to a lost master (P0313),
parameters and records. Both status words are live parameters in either data profile
(P0680, P0968).
"""

from __future__ import annotations

from enum import Enum
from typing import Protocol

from adapters.profibus.weg import words as w
from adapters.profibus.weg.sim.commands import Commands, NetCommand, Panel
from adapters.profibus.weg.spec import ModelSpec
from gateway.sim import Motor


class PdState(Enum):
    """The simulator's PROFIdrive switching-on state (fact sheet 1.11: S1-S4)."""

    S1 = "switching on inhibited"
    S2 = "ready to switch on"
    S3 = "switched on"
    S4 = "operation"


class PdStop(Enum):
    OFF1 = "ramp stop, then ready to switch on"
    OFF3 = "quick stop, then switching on inhibited"


class SimDrive(Protocol):
    """The simulated drive as its data profile's words and its P0313 reactions see it."""

    values: dict[int, int]
    net: NetCommand
    panel: Panel
    stw1: w.ProfidriveControl
    pd_state: PdState
    pd_stop: PdStop | None
    motor: Motor
    fault: int
    alarm: int
    undervoltage: bool
    config_mode: bool
    fire_mode: bool
    pid_automatic: bool

    @property
    def spec(self) -> ModelSpec: ...

    @property
    def running(self) -> bool: ...

    @property
    def commands(self) -> Commands: ...

    def general_enabled(self, remote: bool) -> bool: ...

    def param(self, number: int, subindex: int = 0) -> int: ...


class SimDataWords(Protocol):
    """The control, status and speed words of one data profile, on the drive's side."""

    def fault_reset(self, drive: SimDrive, word: int) -> bool:
        """The control word's fault reset bit (a rising edge resets the fault)."""
        ...

    def take(self, drive: SimDrive, word: int, reference: int) -> None:
        """The control word and the (signed) reference word received."""
        ...

    def status(self, drive: SimDrive) -> int:
        """The status word."""
        ...

    def speed(self, drive: SimDrive) -> int:
        """The speed word (unsigned, as sent)."""
        ...

    def executes_quick_stop(self, drive: SimDrive) -> bool:
        """The quick stop bit acts, on a model that has it."""
        ...

    def after_reset(self, net: NetCommand) -> NetCommand:
        """The network's command once a fault is reset."""
        ...
