"""The protocol engine as the driver loops see it: sans-IO, stepped with an injected clock.

An engine is a state machine. ``step(now, event)`` hands it one event (bytes decoded into
a frame, a write confirmed, ``None`` for "time passed") at the time ``now`` and returns the
actions it wants done (frames to send, reports for the adapter); ``next_deadline()`` is the
time it wants stepping again without an event (a reply timeout, the next poll), ``None``
when nothing is due. The engine never reads a clock and never does I/O: the driver loop of
its medium (:mod:`.stream`, :mod:`.candriver`) does both and steps it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, TypeVar

EventT_contra = TypeVar("EventT_contra", contravariant=True)
ActionT_co = TypeVar("ActionT_co", covariant=True)


class Engine(Protocol[EventT_contra, ActionT_co]):
    """A protocol engine (see the module docstring)."""

    def step(self, now: float, event: EventT_contra | None = None) -> Sequence[ActionT_co]:
        """Take ``event`` (``None``: time passed) at ``now``; the actions to do, in order."""
        ...

    def next_deadline(self) -> float | None:
        """When to step again without an event; ``None``: nothing is due."""
        ...
