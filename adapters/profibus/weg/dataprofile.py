"""One WEG data profile (P0741) as the master speaks it: what the two have in common.

The manufacturer profile (P0741 = 1, :mod:`.manufacturer`) and PROFIdrive (P0741 = 0,
:mod:`.profidrive`) differ in the control and status words (P0684 / P0680 against STW1 /
ZSW1), in what the speed word's full scale means and so in the ratings read at connect.
:class:`~adapters.profibus.weg.profile.WegProfile` holds the one its config names
(``data_profile``); the rest is the profile's own: the cyclic parameter words, the output
memory (the reset pulse, the stop held after a quick or coast stop), the telegram sent
while the drive is not configured (a stop in both data profiles) and the checks at connect.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from adapters.profibus.weg import words as w
from adapters.profibus.weg.scales import Ratings, SpeedBase
from gateway.model import DesiredCommand, Readings

if TYPE_CHECKING:
    from adapters.profibus.weg.options import WegOptions


@dataclass(frozen=True)
class Sent:
    """What the last output telegram asked for (inputs are judged against it)."""

    run: bool = False
    forward: bool = True
    reference: int = 0  # signed raw word as sent
    remote: bool = True
    jog: bool = False


@dataclass(frozen=True)
class Order:
    """What one output telegram carries, before a data profile words it."""

    desired: DesiredCommand
    run: bool  # run as sent: off while a quick or coast stop is held
    jog: bool  # JOG as sent: the same
    reset: bool  # the fault reset pulse
    reference: int  # speed magnitude (and sign) as a raw word of the speed scale
    quick_stop_as_ramp: bool  # P0202 V/f or VVW: a quick stop is sent as a ramp stop
    zsw: w.ProfidriveStatus | None  # the last ZSW1 read (PROFIdrive: the state walked)
    second_ramp: bool = False  # P0684 bit 5 (manufacturer profile, the drive's option)


@dataclass(frozen=True)
class Heard:
    """What the profile keeps of one status word."""

    faulted: bool
    alarm: bool
    zsw: w.ProfidriveStatus | None = None  # PROFIdrive: the ZSW1 read
    status_values: dict[str, int] = field(default_factory=dict)  # manufacturer: P0680 bits


class DataProfileWords(Protocol):
    """The control, status and speed words of one data profile (P0741)."""

    def base_configured(self, options: WegOptions) -> bool:
        """True when the config gives the speed word's base (nothing read for it)."""
        ...

    def rating_params(self, ratings: Ratings) -> dict[str, int]:
        """Ratings field -> parameter, for what this profile's speed base still needs."""
        ...

    def speed_base(self, ratings: Ratings, suffix: str) -> SpeedBase | None:
        """The speed word's base from the ratings known so far (None: not yet)."""
        ...

    def control(self, order: Order) -> tuple[int, int, Sent]:
        """The control word, the reference word (signed) and what they ask for."""
        ...

    def status(
        self, word: int, speed: int, sent: Sent, near: Callable[[int], bool], changes: Readings
    ) -> Heard:
        """The status word's readings into ``changes`` (``near``: the speed is at the
        reference sent, within the band), and what the profile keeps of it."""
        ...
