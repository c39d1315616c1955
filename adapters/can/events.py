"""What an engine on CAN takes from its link and gives it, whatever its protocol: the link
events and the frame to send.

The link (:mod:`adapters.link.can`) reports a data frame, a SocketCAN error frame, a frame
the bus cannot carry and a receive failure; the driver loop reports a failed send. Each
engine steps these as its events (:class:`FrameIn`, :class:`BusErrorIn`,
:class:`BadFrame`, :class:`LinkDown`, :class:`TxFailed`) beside its own, and asks for a
frame on the line with :class:`Send`. Sans-IO: the engines import this module; the
adapter gives the constructors to the link's line glue
(:data:`adapters.can.adapter.LINK_EVENTS`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Generic, TypeAlias, TypeVar

from adapters.can.frame import CanFrame
from adapters.link.canerror import LineCondition
from gateway.errors import GatewayError

FrameT_co = TypeVar("FrameT_co", bound=CanFrame, covariant=True)


@dataclass(frozen=True, slots=True)
class FrameIn(Generic[FrameT_co]):
    """A data frame from the bus."""

    frame: FrameT_co


@dataclass(frozen=True, slots=True)
class BadFrame:
    """A frame the link could not turn into the bus's frame (extended id, too long...), or
    a receive failure on a link still up."""

    reason: str


@dataclass(frozen=True, slots=True)
class BusErrorIn:
    """A SocketCAN error frame, decoded by :mod:`adapters.link.canerror`."""

    conditions: frozenset[LineCondition]


@dataclass(frozen=True, slots=True)
class TxFailed:
    """The link could not send (transmit buffer full, interface down): back off.
    ``dropped``: the frames not sent (the one that failed and those after it)."""

    reason: str
    dropped: int = 1


@dataclass(frozen=True, slots=True)
class LinkDown:
    """The CAN interface is down (SocketCAN ENETDOWN on a send or a receive): every
    connection on the line is gone."""

    reason: str


LinkEvent: TypeAlias = FrameIn[FrameT_co] | BadFrame | BusErrorIn | TxFailed | LinkDown
"""An engine's events from its link (the rest of its events are its own)."""


@dataclass(frozen=True, slots=True)
class Send(Generic[FrameT_co]):
    """An action: the frame goes out on the line."""

    frame: FrameT_co


class NodeUnavailable(GatewayError):
    """A job (an SDO transfer, an explicit request) for a node that is not online."""
