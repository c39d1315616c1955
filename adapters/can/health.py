"""The health of a CAN line from the conditions its error frames report, sans-IO: the
controller's fault confinement states (ISO 11898-1: error active, warning, passive,
bus-off), worst first. The conditions are the link's (:mod:`adapters.link.canerror`)."""

from __future__ import annotations

from enum import Enum

from adapters.link.canerror import LineCondition


class LineHealth(Enum):
    """The line as the scanner sees it, worst condition first."""

    BUS_OFF = "bus-off"
    ERROR_PASSIVE = "error passive"
    ERROR_WARNING = "error warning"
    OK = "ok"


def health_after(current: LineHealth, conditions: frozenset[LineCondition]) -> LineHealth:
    """The line health after an error frame: a restart or a return to error active
    clears it, otherwise the worst condition wins."""
    if LineCondition.BUS_OFF in conditions:
        return LineHealth.BUS_OFF
    if conditions & {LineCondition.RESTARTED, LineCondition.ERROR_ACTIVE}:
        return LineHealth.OK
    if LineCondition.ERROR_PASSIVE in conditions:
        return LineHealth.ERROR_PASSIVE if current is not LineHealth.BUS_OFF else current
    if LineCondition.ERROR_WARNING in conditions and current is LineHealth.OK:
        return LineHealth.ERROR_WARNING
    return current
