"""The input words 3..N of a WEG telegram: the parameters the drive is programmed to send
(P0742.. / P742..), read into the drive model where it has a field for them.

Current, power, present alarm and fault (P0003, P0010, P0048, P0049 / P0947) in both data
profiles, and frame 20's PROFIdrive scales (P0760-P0763, CFW-11); any other parameter is
published as a ``DriveState.values`` entry named after it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from adapters.profibus.weg import words as w
from adapters.profibus.weg.scales import Ratings
from adapters.profibus.weg.spec import ModelSpec, scaled
from gateway.model import Readings


@dataclass
class Mapped:
    """What the mapped words of one input telegram said."""

    fault: int | None = None
    alarm: int | None = None
    namur: int = 0
    values: dict[str, float | int] = field(default_factory=dict)


def read_mapped(
    spec: ModelSpec,
    ratings: Ratings,
    params: tuple[int, ...],
    words: Sequence[int],
    changes: Readings,
) -> Mapped:
    """The mapped words (``params``: the parameter each carries, 0 = none) into
    ``changes``, and what they said of codes and values."""
    m = Mapped()
    for param, word in zip(params, words, strict=True):
        if not param:
            continue
        handler = _KNOWN.get(param)
        if handler is None:
            m.values[spec.pname(param)] = scaled(param, word)
        else:
            handler(spec, ratings, word, changes, m)
    return m


def _current(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0003 motor current, one decimal (P0742 description: 4.7 A is sent as 47)."""
    amps = word / 10.0
    changes["current_a"] = amps
    if ratings.rated_current_a:
        changes["current_pct_flc"] = round(100.0 * amps / ratings.rated_current_a, 2)


def _alarm_word(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0048 present alarm (Table 3.2 bit 7 note)."""
    m.alarm = word


def _fault_word(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0049 present fault (Table 3.2 bit 15 note) / P0947 fault number."""
    if word:
        m.fault = word


def _power(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0010 output power, kW with one decimal (P0761 description)."""
    changes["power_kw"] = word / 10.0


def _pd_current(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0760: 4000h = 100 % of the motor rated current P0401."""
    pct = 100.0 * word / w.PROFIDRIVE_PERCENT_BASE
    changes["current_pct_flc"] = round(pct, 2)
    if ratings.rated_current_a:
        changes["current_a"] = round(pct * ratings.rated_current_a / 100.0, 2)


def _pd_power(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0761 = (P0010 / P0404) x 4000h."""
    if ratings.rated_power_kw:
        frac = word / w.PROFIDRIVE_PERCENT_BASE
        changes["power_kw"] = round(frac * ratings.rated_power_kw, 3)
    else:
        m.values["power_pct"] = round(100.0 * word / w.PROFIDRIVE_PERCENT_BASE, 2)


def _pd_torque(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0762: 4000h = 100 % of the output torque."""
    m.values["torque_pct"] = round(100.0 * word / w.PROFIDRIVE_PERCENT_BASE, 2)


def _namur(spec: ModelSpec, ratings: Ratings, word: int, changes: Readings, m: Mapped) -> None:
    """P0763 VIK-NAMUR status (Table 3.7): fault categories."""
    m.namur = word
    m.values[spec.pname(763)] = word


_Handler = Callable[[ModelSpec, Ratings, int, Readings, Mapped], None]

_KNOWN: Final[Mapping[int, _Handler]] = {
    3: _current,
    10: _power,
    48: _alarm_word,
    49: _fault_word,
    947: _fault_word,
    760: _pd_current,
    761: _pd_power,
    762: _pd_torque,
    763: _namur,
}
