"""The history queries of the Zenoh front end: ``<prefix>/drives/<id>/history?start=...;
end=...;step=...`` (docs/zenoh-keys.md), answered from the gateway's history store.

The parameters are checked on the loop (a bad one is answered at once with an error reply
naming it); the file is read on a thread of its own, never on the loop; at
most :data:`HISTORY_REQUEST_LIMIT` are under way at once, one more is refused as busy.
"""

from __future__ import annotations

import asyncio
import logging
import time
from functools import partial

from gateway.errors import HistoryError
from gateway.frontend import RuntimeView
from gateway.history.query import (
    HistoryRange,
    answer,
    off_loop,
    parse_range,
    split_parameters,
)
from gateway.history.store import HistoryStore
from gateway.zenoh.keys import KeySpace, is_concrete
from gateway.zenoh.replies import Pending, Replies
from gateway.zenoh.requests import Answer, error_body

log = logging.getLogger(__name__)

HISTORY_REQUEST_LIMIT = 8
"""History queries under way at once; one more is refused as busy."""


class HistoryQueries:
    """Serves the history queries of the drives of one front end."""

    def __init__(
        self, runtime: RuntimeView, keys: KeySpace, drive_ids: tuple[str, ...], replies: Replies
    ) -> None:
        self.runtime = runtime
        self.keys = keys
        self._drive_ids = drive_ids
        self._replies = replies
        self.tasks: set[asyncio.Task[None]] = set()

    def query(self, pending: Pending) -> None:
        incoming = pending.incoming
        parsed = self.keys.parse(incoming.key)
        if not is_concrete(incoming.key) or parsed is None or parsed.rest:
            self._replies.refuse(
                pending, f"a history query names one drive: {self.keys.prefix}/drives/<id>/history"
            )
            return
        drive_id = parsed.drive_id
        if drive_id not in self._drive_ids:
            self._replies.refuse(pending, f"no drive {drive_id!r}")
            return
        store = self.runtime.history
        if store is None:
            self._replies.refuse(pending, "this gateway keeps no history ([history] is off)")
            return
        try:
            asked = parse_range(split_parameters(incoming.parameters), time.time())
        except HistoryError as exc:
            self._replies.refuse(pending, str(exc))
            return
        if len(self.tasks) >= HISTORY_REQUEST_LIMIT:
            self._replies.refuse(
                pending, f"busy: {HISTORY_REQUEST_LIMIT} history requests are under way"
            )
            return
        task = asyncio.create_task(
            self._serve(pending, store, drive_id, asked), name="zenoh-history"
        )
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    async def _serve(
        self, pending: Pending, store: HistoryStore, drive_id: str, asked: HistoryRange
    ) -> None:
        try:
            body = await off_loop(partial(answer, store, drive_id, asked))
        except asyncio.CancelledError:
            self._replies.refuse(pending, "the gateway is shutting down")
            raise
        except HistoryError as exc:
            self._replies.refuse(pending, str(exc))
        except Exception as exc:
            log.exception("history query of %s failed", drive_id)
            self._replies.answer(pending, [Answer.error(error_body(exc))])
        else:
            self._replies.answer(pending, [Answer.reply(pending.incoming.key, body)])
