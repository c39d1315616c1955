"""The hub's events in the log: one line per event; a command refusal repeated by the same
client for the same reason is written once per period, with the count of those held back
(gateway/hub.py, the audit trail)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import cast

from gateway.adapter import Event, EventKind
from gateway.ratelimit import LogRateLimit


class EventLog:
    """Writes events to ``log`` (the hub's), refusals rate-limited on ``clock``."""

    def __init__(self, log: logging.Logger, clock: Callable[[], float]) -> None:
        self._log = log
        self._clock = clock
        self._refusals = LogRateLimit()

    def write(self, ev: Event) -> None:
        """One log line per event; a refusal repeated by the same client for the same
        reason is written once per period, with the count of those held back."""
        log = self._log
        if ev.kind is not EventKind.COMMAND_REFUSED:
            log.info("%s: %s: %s", ev.drive_id, ev.kind.value, ev.text)
            return
        held = self._refusals.admit((ev.drive_id, ev.text), self._clock())
        if held is None:
            log.debug("%s: %s: %s", ev.drive_id, ev.kind.value, ev.text)
        elif held:
            log.info(
                "%s: %s: %s (and %d more like it since the last line)",
                ev.drive_id,
                ev.kind.value,
                ev.text,
                held,
            )
        else:
            log.info("%s: %s: %s", ev.drive_id, ev.kind.value, ev.text)

    def flush(self) -> None:
        """The counts of refusals held back whose period has passed."""
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
