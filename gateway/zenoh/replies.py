"""The queries the Zenoh front end has taken and not yet answered.

Each query is answered exactly once (later answers are ignored), from the I/O thread
(:mod:`gateway.zenoh.worker`), and then dropped; at shutdown, those still waiting are
refused.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from functools import partial

from gateway.zenoh.link import Incoming, ZenohLink
from gateway.zenoh.requests import Answer
from gateway.zenoh.worker import Worker, WorkerStopped


@dataclass(eq=False)
class Pending:
    """A query waiting for its answer."""

    incoming: Incoming
    answered: bool = False


class Replies:
    """The queries waiting for their answer, answered through the I/O thread."""

    def __init__(self, worker: Worker) -> None:
        self._worker = worker
        self._pending: set[Pending] = set()

    def take(self, incoming: Incoming) -> Pending:
        """A query taken on the loop, to be answered."""
        pending = Pending(incoming)
        self._pending.add(pending)
        return pending

    def answer(self, pending: Pending, answers: list[Answer]) -> None:
        """Answer a query exactly once (later calls are ignored), from the I/O thread."""
        if pending.answered:
            return
        pending.answered = True
        self._pending.discard(pending)
        query = pending.incoming.query
        try:
            self._worker.post(partial(ZenohLink.reply, query, answers))
        except WorkerStopped:
            with contextlib.suppress(Exception):
                query.drop()

    def refuse(self, pending: Pending, text: str) -> None:
        self.answer(pending, [Answer.refusal(text)])

    def refuse_all(self, text: str) -> None:
        """Every query still waiting, refused with ``text`` (shutdown)."""
        for pending in list(self._pending):
            self.refuse(pending, text)
