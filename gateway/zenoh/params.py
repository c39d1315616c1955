"""The parameter queries of the Zenoh front end: one parameter read or written
(``<prefix>/drives/<id>/params/<number>``), or a drive's parameter backup document
(``<prefix>/drives/<id>/params``, gateway.paramsbackup); docs/zenoh-keys.md.

Each is served in a task of its own, on the event loop, and answered exactly once
(:class:`gateway.zenoh.replies.Replies`); at most :data:`PARAM_REQUEST_LIMIT` are under
way at once.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from gateway import paramsbackup
from gateway.access.audit import Kind, Result
from gateway.adapter import ParamValue
from gateway.errors import GatewayError
from gateway.frontend import RuntimeView
from gateway.zenoh.keys import KeySpace, is_concrete
from gateway.zenoh.link import Oversize
from gateway.zenoh.replies import Pending, Replies
from gateway.zenoh.requests import (
    Answer,
    BackupRequest,
    BadRequest,
    ParamRequest,
    error_body,
    param_result,
    parse_backup_request,
    parse_param_request,
    too_large,
)

log = logging.getLogger(__name__)

PARAM_TIMEOUT = 8.0  # s; below Zenoh's default query timeout (10 s), so a client gets an answer
PARAM_REQUEST_LIMIT = 64
"""Parameter requests under way at once; one more is refused as busy."""


class ParamQueries:
    """Serves the parameter queries of the drives of one front end."""

    def __init__(
        self, runtime: RuntimeView, keys: KeySpace, drive_ids: tuple[str, ...], replies: Replies
    ) -> None:
        self.runtime = runtime
        self.hub = runtime.hub
        self.keys = keys
        self._drive_ids = drive_ids
        self._replies = replies
        self.tasks: set[asyncio.Task[None]] = set()
        """The requests under way (cancelled at shutdown)."""

    def query(self, pending: Pending) -> None:
        """A query on a drive's parameters: served in a task, or refused at once."""
        incoming = pending.incoming
        parsed = self.keys.parse(incoming.key)
        if not is_concrete(incoming.key) or parsed is None:
            self._replies.refuse(pending, "a parameter query names one drive and one parameter")
            return
        if len(self.tasks) >= PARAM_REQUEST_LIMIT:
            self._replies.refuse(
                pending, f"busy: {PARAM_REQUEST_LIMIT} parameter requests are under way"
            )
            return
        if not parsed.rest:  # <prefix>/drives/<id>/params: the whole backup document
            self._backup(pending, parsed.drive_id)
            return
        try:
            payload = incoming.payload
            if isinstance(payload, Oversize):
                raise BadRequest(too_large(payload.size))
            req = parse_param_request(parsed.rest, payload)
        except BadRequest as exc:
            self._replies.refuse(pending, exc.text)
            return
        if parsed.drive_id not in self._drive_ids:
            self._replies.refuse(pending, f"no drive {parsed.drive_id!r}")
            return
        task = asyncio.create_task(
            self._serve_param(pending, parsed.drive_id, req), name=f"zenoh-param-{parsed.drive_id}"
        )
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    def _audit(self, kind: Kind, pending: Pending, detail: str, failure: str | None) -> None:
        """A parameter write or backup, as the audit trail keeps it (the client is the
        session's label; the role is the router's access control, docs/operations.md)."""
        self.runtime.audit.record(
            kind,
            Result.SUCCESS if failure is None else Result.FAILURE,
            interface="zenoh",
            peer=pending.incoming.client,
            identity=pending.incoming.client,
            detail=detail if failure is None else f"{detail}: {failure}",
        )

    async def _serve_param(self, pending: Pending, drive_id: str, req: ParamRequest) -> None:
        failure = "the gateway is shutting down"
        try:
            failure = await self._answer_param(pending, drive_id, req) or ""
        finally:
            if req.value is not None:
                where = f"{req.number}" if req.subindex is None else f"{req.number}/{req.subindex}"
                detail = f"drive {drive_id} parameter {where} = {req.value!r}"
                self._audit(Kind.PARAM_WRITE, pending, detail, failure or None)

    async def _answer_param(self, pending: Pending, drive_id: str, req: ParamRequest) -> str | None:
        """Serve one parameter request; why it failed, or None."""
        key = pending.incoming.key
        info = self.hub.capabilities(drive_id).params.get(req.number)
        try:
            if req.value is not None:
                await asyncio.wait_for(
                    self.hub.write_param(drive_id, req.number, req.value, req.subindex),
                    PARAM_TIMEOUT,
                )
                body = param_result(req, req.value, info)
            else:
                value = await asyncio.wait_for(
                    self.hub.read_param(drive_id, req.number, req.subindex), PARAM_TIMEOUT
                )
                body = param_result(req, value, info)
        except asyncio.CancelledError:
            self._replies.refuse(pending, "the gateway is shutting down")
            raise
        except GatewayError as exc:
            self._replies.answer(pending, [Answer.error(error_body(exc))])
            return str(exc) or type(exc).__name__
        except TimeoutError:
            self._replies.refuse(pending, f"no answer from drive {drive_id} in {PARAM_TIMEOUT:g} s")
            return f"no answer in {PARAM_TIMEOUT:g} s"
        except Exception as exc:
            log.exception("parameter request %s failed", key)
            self._replies.answer(pending, [Answer.error(error_body(exc))])
            return type(exc).__name__
        self._replies.answer(pending, [Answer.reply(key, body)])
        return None

    def _backup(self, pending: Pending, drive_id: str) -> None:
        """``<prefix>/drives/<id>/params``: the drive's parameter backup document
        (gateway.paramsbackup); ``?numbers=1-20,100`` chooses the parameters, ``?describe``
        answers the identity, the table and ``writable_params`` without reading them."""
        if drive_id not in self._drive_ids:
            self._replies.refuse(pending, f"no drive {drive_id!r}")
            return
        try:
            request = parse_backup_request(pending.incoming.parameters)
        except (BadRequest, paramsbackup.BackupError) as exc:
            self._replies.refuse(pending, str(exc))
            return
        task = asyncio.create_task(
            self._serve_backup(pending, drive_id, request), name=f"zenoh-backup-{drive_id}"
        )
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    async def _serve_backup(self, pending: Pending, drive_id: str, request: BackupRequest) -> None:
        hub = self.hub
        table = hub.capabilities(drive_id).params

        async def read(number: int, subindex: int) -> ParamValue:
            return await asyncio.wait_for(hub.read_param(drive_id, number, subindex), PARAM_TIMEOUT)

        try:
            state = hub.state(drive_id).to_json()
            diag = self.runtime.drive_diagnostics(drive_id)
            drive = await paramsbackup.identify(state, diag, table, read)
            gateway = f"{self.runtime.config.gateway.name} {self.runtime.version}"
            if request.describe:
                body: dict[str, Any] = {
                    "gateway": gateway,
                    "drive": drive.to_json(),
                    "state": state,
                    "table": paramsbackup.table_to_json(table),
                    "writable": sorted(hub.policy(drive_id).writable_params),
                    "writable_entries": paramsbackup.entries_to_json(
                        hub.policy(drive_id).writable_entries
                    ),
                }
            else:
                backup = await paramsbackup.take(
                    drive,
                    table,
                    request.numbers,
                    read,
                    gateway=gateway,
                    entries=hub.policy(drive_id).writable_entries,
                )
                body = backup.to_json()
        except asyncio.CancelledError:
            self._replies.refuse(pending, "the gateway is shutting down")
            raise
        except paramsbackup.BackupError as exc:
            self._replies.refuse(pending, str(exc))
            self._audit(Kind.BACKUP, pending, f"drive {drive_id}", str(exc))
        except Exception as exc:
            log.exception("parameter backup of %s failed", drive_id)
            self._replies.answer(pending, [Answer.error(error_body(exc))])
            self._audit(Kind.BACKUP, pending, f"drive {drive_id}", type(exc).__name__)
        else:
            self._replies.answer(pending, [Answer.reply(pending.incoming.key, body)])
            self._audit(Kind.BACKUP, pending, f"drive {drive_id}", None)
