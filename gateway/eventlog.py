"""The hub's events on their way out: folded, then written to the log and delivered.

A burst of identical events (the same kind and text as the event before it of the same
drive) is one event with a count: the first is written and delivered at once; the repeats
within :data:`~gateway.ratelimit.FOLD_WINDOW` are counted and neither written nor
delivered; when the window is over (:meth:`EventLog.flush`, on the hub's tick) or when the
drive's next event differs (just before it), one event like the last repeat says how many
there were (``repeats`` in its data, docs/zenoh-keys.md). An event that differs from the
drive's event before it (a new fault, another code, the same fault again after a comm
change) is never held back, and the order of each drive's events is kept. The table of
runs (one per drive) is bounded: the oldest run is dropped, its count told first.

In the log, one line per event delivered; a command refusal repeated by the same client
for the same reason is written once per period, with the count of those held back
(gateway/hub.py, the audit trail).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import cast

from gateway.adapter import Event, EventKind
from gateway.ratelimit import FOLD_MAX_KEYS, FOLD_WINDOW, LogRateLimit, RunFold, Told

REPEATS = "repeats"
"""The data key of an event that tells how many like it were held back since the last one
of its drive delivered."""


def _nowhere(ev: Event) -> None:
    """Events delivered to no one (a log only)."""


class EventLog:
    """Folds events (see the module docstring), writes them to ``log`` (the hub's) and
    hands each one delivered to ``deliver``; the time comes from ``clock``."""

    def __init__(
        self,
        log: logging.Logger,
        clock: Callable[[], float],
        deliver: Callable[[Event], None] = _nowhere,
        *,
        window: float = FOLD_WINDOW,
        max_keys: int = FOLD_MAX_KEYS,
    ) -> None:
        self._log = log
        self._clock = clock
        self._deliver = deliver
        self._refusals = LogRateLimit()
        self._fold: RunFold[Event] = RunFold(window, max_keys)

    @property
    def folded(self) -> int:
        """Events held back as repeats, in all."""
        return self._fold.folded

    @property
    def runs(self) -> int:
        """Runs remembered (one per drive): bounded by ``max_keys``."""
        return len(self._fold)

    def offer(self, ev: Event) -> None:
        """Write and deliver ``ev`` now, after the count of any run it ends; or hold it
        back as a repeat of the drive's event before it (counted)."""
        for told in self._fold.offer(ev.drive_id, (ev.kind, ev.text), ev, self._clock()):
            self._let_through(told)

    def flush(self) -> None:
        """The counts of the runs whose window is over, and of the refusals held back
        whose period has passed."""
        for told in self._fold.flush(self._clock()):
            self._let_through(told)
        for key, held in self._refusals.flush(self._clock()):
            drive_id, text = cast(tuple[str, str], key)
            self._log.info(
                "%s: %s: %s: %d more like it in the last %g s",
                drive_id,
                EventKind.COMMAND_REFUSED.value,
                text,
                held,
                self._refusals.period,
            )

    def _let_through(self, told: Told[Event]) -> None:
        """Write and deliver an event; one that tells repeats carries their count."""
        ev, repeats = told.item, told.repeats
        if repeats:
            ev = replace(ev, data={**ev.data, REPEATS: repeats})
        self.write(ev, repeats)
        self._deliver(ev)

    def write(self, ev: Event, repeats: int = 0) -> None:
        """One log line per event (``repeats``: it tells that many held back since the
        last line of its run); a refusal repeated by the same client for the same reason
        is written once per period, with the count of those held back."""
        log = self._log
        if ev.kind is EventKind.COMMAND_REFUSED:
            held = self._refusals.admit((ev.drive_id, ev.text), self._clock(), repeats or 1)
            if held is None:
                log.debug("%s: %s: %s", ev.drive_id, ev.kind.value, ev.text)
                return
            if not repeats and held:
                log.info(_AND_MORE, ev.drive_id, ev.kind.value, ev.text, held)
                return
            repeats += held
        if repeats:
            log.info(_MORE, ev.drive_id, ev.kind.value, ev.text, repeats)
        else:
            log.info("%s: %s: %s", ev.drive_id, ev.kind.value, ev.text)


_AND_MORE = "%s: %s: %s (and %d more like it since the last line)"
_MORE = "%s: %s: %s (%d more like it since the last line)"
