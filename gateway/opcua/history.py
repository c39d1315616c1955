"""HistoryRead of the drives' readings and events, from the gateway's history store.

The store is whatever gives :class:`ReadingHistory` (the SQLite history of the box): rows
of a drive's readings by field name between two wall-clock times, and its events. This
module answers OPC UA's ReadRawModified requests on the reading variables and ReadEvent
requests on the drive objects (one drive's events) and the Server object (every drive's)
from it (asyncua's HistoryStorageInterface): it never stores anything itself (the store is
written by the history writer, off the fieldbus path), and it reads at most
``max_values`` rows or events per request, giving a continuation point for the rest.
An event is a BaseEventType with the standard fields (:mod:`gateway.opcua.eventhistory`);
the request's where clause is not applied (the client filters what it reads).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any, Protocol

from asyncua import ua
from asyncua.server.history import HistoryStorageInterface

from gateway.opcua.eventhistory import HistoryEventLike, history_event

log = logging.getLogger(__name__)

MAX_VALUES = 10_000
"""Values per node per HistoryRead response; a longer span continues."""
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_NEVER = datetime(1601, 1, 1, tzinfo=UTC)  # OPC UA's null DateTime


class HistoryRowLike(Protocol):
    """One row of a drive's readings: wall-clock seconds and values by field name."""

    @property
    def t(self) -> float: ...

    @property
    def values(self) -> Mapping[str, float | None]: ...


class ReadingHistory(Protocol):
    """What HistoryRead needs of the history store."""

    def readings(
        self, drive_id: str, start: float, end: float, step: float | None = None
    ) -> Sequence[HistoryRowLike]: ...

    def events(
        self,
        drive_id: str | None,
        start: float,
        end: float,
        limit: int | None = None,
        newest: bool = False,
    ) -> Sequence[HistoryEventLike]: ...


def _seconds(when: datetime | None) -> float | None:
    if when is None:
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    if when <= _NEVER:
        return None
    return (when - _EPOCH).total_seconds()


def _time(seconds: float) -> datetime:
    return _EPOCH + timedelta(seconds=seconds)


@dataclass(frozen=True, slots=True)
class _Span:
    first: float
    last: float
    backwards: bool
    limit: int


class DriveHistory(HistoryStorageInterface):  # type: ignore[misc]
    """asyncua's history back end over a :class:`ReadingHistory` (read only)."""

    def __init__(
        self,
        store: ReadingHistory,
        fields: Mapping[ua.NodeId, tuple[str, str]],
        clock: Any = None,
        max_values: int = MAX_VALUES,
        sources: Mapping[ua.NodeId, str | None] | None = None,
    ) -> None:
        super().__init__(max_values)
        self.store = store
        self.fields = dict(fields)
        """Reading variable -> (drive id, drive model field)."""
        self.sources = dict(sources or {})
        """Event notifier -> its drive id (None: every drive's events, the Server)."""
        self._nodes = {d: node for node, d in self.sources.items() if d is not None}
        self._now = clock or (lambda: datetime.now(UTC).timestamp())
        self.reads = 0
        self.failures = 0

    async def init(self) -> None:
        return None

    async def new_historized_node(
        self, node_id: ua.NodeId, period: timedelta | None, count: int = 0
    ) -> None:
        return None

    async def save_node_value(self, node_id: ua.NodeId, datavalue: ua.DataValue) -> None:
        return None

    async def new_historized_event(
        self, source_id: ua.NodeId, evtypes: list[Any], period: timedelta | None, count: int = 0
    ) -> None:
        return None

    async def save_event(self, event: Any) -> None:
        return None

    async def read_event_history(
        self,
        source_id: ua.NodeId,
        start: datetime | None,
        end: datetime | None,
        nb_values: int,
        evfilter: Any,
    ) -> tuple[list[Any], datetime | None]:
        if source_id not in self.sources:
            raise ua.UaStatusCodeError(ua.StatusCodes.BadHistoryOperationUnsupported)
        drive_id = self.sources[source_id]
        span = self._span(start, end, nb_values)
        limit, last = span.limit, math.nextafter(span.last, math.inf)  # the end time within
        try:
            found = list(
                self.store.events(drive_id, span.first, last, limit, newest=span.backwards)
            )
        except Exception:
            self.failures += 1
            log.exception("OPC UA event HistoryRead of %s: the history store failed", source_id)
            raise ua.UaStatusCodeError(ua.StatusCodes.BadHistoryOperationUnsupported) from None
        self.reads += 1
        more: datetime | None = None
        if len(found) > limit:  # the next read starts at the first event left out
            more = _time(found[limit].t)
            found = found[:limit]
        return [history_event(e, self._nodes.get(e.drive_id, source_id)) for e in found], more

    async def stop(self) -> None:
        return None

    def _span(self, start: datetime | None, end: datetime | None, nb_values: int) -> _Span:
        """A request's times in seconds, oldest first (``backwards`` when the request gave
        them the other way), open ends made the epoch and now; its values per response."""
        begin, finish = _seconds(start), _seconds(end)
        backwards = begin is not None and finish is not None and finish < begin
        if backwards:
            begin, finish = finish, begin
        most = self.max_history_data_response_size
        return _Span(
            0.0 if begin is None else begin,
            self._now() if finish is None else finish,
            backwards,
            min(nb_values or most, most),
        )

    async def read_node_history(
        self, node_id: ua.NodeId, start: datetime | None, end: datetime | None, nb_values: int
    ) -> tuple[list[ua.DataValue], datetime | None]:
        where = self.fields.get(node_id)
        if where is None:
            return [], None
        drive_id, name = where
        span = self._span(start, end, nb_values)
        backwards, limit = span.backwards, span.limit
        try:
            rows = self.store.readings(drive_id, span.first, span.last)
        except Exception:
            self.failures += 1
            log.exception("OPC UA HistoryRead of %s %s: the history store failed", drive_id, name)
            raise ua.UaStatusCodeError(ua.StatusCodes.BadHistoryOperationUnsupported) from None
        self.reads += 1
        values = [_datavalue(row.t, row.values.get(name)) for row in rows]
        if backwards:
            values.reverse()
        more: datetime | None = None
        if len(values) > limit:
            more = values[limit].SourceTimestamp
            values = values[:limit]
        return values, more


def _datavalue(t: float, value: float | None) -> ua.DataValue:
    when = _time(t)
    if value is None or not math.isfinite(value):
        return ua.DataValue(
            ua.Variant(None, ua.VariantType.Null),
            StatusCode=ua.StatusCode(ua.StatusCodes.BadNoData),
            SourceTimestamp=when,
            ServerTimestamp=when,
        )
    return ua.DataValue(
        ua.Variant(float(value), ua.VariantType.Double), SourceTimestamp=when, ServerTimestamp=when
    )
