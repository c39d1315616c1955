"""The Zenoh front end: the common drive model on Eclipse Zenoh (key space in
:mod:`gateway.zenoh.keys`, document in docs/zenoh-keys.md).

Threading model and delivery:

- The event loop owns the hub; every hub call of this module runs there.
- A state change is put at once, from the loop, with CongestionControl.DROP:
  such a put never waits on the network (beyond Zenoh's ``wait_before_drop``,
  1 ms by default, when a link's queue is full); on a slow link Zenoh drops it,
  so older states are overtaken by newer ones and nothing queues up.
- The last word is never lost: once a drive's state has not changed for
  :data:`SETTLE` seconds, and at least once per ``zenoh.heartbeat``, its newest
  state is put again with CongestionControl.BLOCK (a repeat has the same
  ``seq``). These puts, like every Zenoh call that may block (opening the session,
  declarations, events, diagnostics, replies, liveliness tokens, closing), are
  made by one I/O thread (:class:`gateway.zenoh.worker.Worker`): the loop hands
  over without waiting, through a latest-per-drive slot for states and
  diagnostics and an ordered queue for the rest. Handing each change to a thread
  instead would starve it of the GIL whenever the loop is busy.
- A drive's states never go backwards on the wire (``seq`` never decreases for a
  subscriber). Every put of a drive's state happens under that drive's lock, which
  also keeps the highest ``seq`` put so far: the I/O thread takes the lock for its
  BLOCK put; the loop only tries it. A change the loop could not put because the
  thread held the lock waits in that drive's queue of deferred changes (at most
  :data:`DEFER_LIMIT`, the oldest give way), and whoever holds the lock next puts
  them first, in order: the thread right after its own put (it looks again once it
  has let the lock go), or the loop before its next change. The thread may hold the
  lock for milliseconds (it must win the GIL back from a busy loop to return from
  ``put``); every change made meanwhile still gets its own put. A state older than
  one already put is never put.
- The hub's subscription calls back when a change arrives while none waits; the
  changes are taken in the loop's next turn (so those an adapter makes in one
  cycle are encoded, then put back to back) without a task, a future or an event
  per turn: the fan-out's hot path (docs/decisions/0012-zenoh-fan-out-hot-path.md).
- Every state the hub's subscription yields gets its own put (on an uncongested
  link every committed state arrives, unless the same drive changed twice in one
  turn of the loop: the subscription keeps the newest). The settle and heartbeat
  puts repeat the newest state already put, never one still waiting in the
  subscription, which could otherwise be replaced in the I/O slot before the
  thread ran and never reach the wire.
- Zenoh runs the callbacks (command puts, queries) on its own threads; they copy
  key and payload and hand over with ``loop.call_soon_threadsafe``. A query is
  answered exactly once, from the I/O thread, and then dropped.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import zenoh

from gateway.access.audit import Kind, Result
from gateway.adapter import EventKind
from gateway.errors import CommandRejected, UnknownDrive
from gateway.frontend import FrontEndCounters, RuntimeView
from gateway.hub import EventSubscription, StateSubscription
from gateway.model import CommState, DriveState, Source
from gateway.zenoh.history import HistoryQueries
from gateway.zenoh.keys import KeyKind, KeySpace, is_concrete
from gateway.zenoh.link import ANONYMOUS, Incoming, LinkSeen, Oversize, Payload, ZenohLink
from gateway.zenoh.params import ParamQueries
from gateway.zenoh.replies import Pending, Replies
from gateway.zenoh.requests import (
    Answer,
    command_accepted,
    command_refused,
    encode_json,
    encode_state,
    error_body,
    parse_command,
    too_large,
)
from gateway.zenoh.session import zenoh_config
from gateway.zenoh.worker import Worker

log = logging.getLogger(__name__)

CLOSE_TIMEOUT = 10.0  # s the I/O thread may take to flush and close the session
HEARTBEAT_SLACK = 0.001  # s; timers may fire this early
SETTLE = 0.05  # s without a change after which a drive's newest state is put with BLOCK
# heartbeats due within this share of the period go out with the one due now: the drives'
# heartbeats fall into groups instead of waking the loop once per drive (plant bench: 188
# drives, 50 wake-ups a second, each a pass over every drive)
HEARTBEAT_BATCH = 0.1
# diagnostics of this many drives, then the loop's other work: a heartbeat's diagnostics of
# 188 drives held the loop for about 12 ms in one go (plant bench: a late cycle per second)
DIAG_BATCH = 16
HANDOVER_LIMIT = 1024
"""Puts and queries handed from Zenoh's threads to the loop and not yet taken; beyond
it they are dropped (and counted in ``overflow``): a flood queues without a bound nowhere."""
_ONLINE = CommState.ONLINE  # a module constant: an Enum class attribute is slow to look up
DEFER_LIMIT = 256  # changes per drive held for a put while the I/O thread has the drive's lock


@dataclass
class ZenohCounters:
    """Requests taken from Zenoh since start (``/metrics`` reads them through ``counted``)."""

    puts: int = 0  # command puts taken on the loop
    queries: int = 0  # queries taken on the loop (state, command, params, health)
    commands_accepted: int = 0
    commands_refused: int = 0


def _drop_put(publisher: Any, drive_id: str, payload: bytes) -> None:
    """A state change with the loop's DROP publisher; a failure is only logged."""
    try:
        publisher.put(payload)
    except zenoh.ZError as exc:
        log.debug("state put of %s failed: %s", drive_id, exc)


def _endpoints_of(config: Any) -> tuple[str, str, str]:
    """Mode, listen and connect endpoints as the session really uses them."""

    def text(key: str) -> str:
        try:
            value = config.get_json(key)
        except Exception:  # a key the config does not have
            return "?"
        if isinstance(value, dict):  # per-mode endpoints
            value = sorted({e for v in value.values() for e in v})
        return ", ".join(value) if isinstance(value, list) and value else str(value or "none")

    return text("mode"), text("listen/endpoints"), text("connect/endpoints")


class ZenohFrontEnd:
    """Serves the hub on Zenoh until cancelled; cancellation closes the session cleanly."""

    def __init__(self, runtime: RuntimeView) -> None:
        self.runtime = runtime
        self.hub = runtime.hub
        self.section = runtime.config.zenoh
        self.keys = KeySpace(self.section.prefix)
        self._drive_ids = tuple(self.hub.drive_ids())
        self._worker = Worker(f"zenoh-io {self.section.prefix}")
        self._link: ZenohLink | None = None  # touched on the I/O thread only
        self._loop: asyncio.AbstractEventLoop | None = None
        self._serving = False
        self.ready = asyncio.Event()  # set once serving (the gateway token is declared)
        self._live: set[str] = set()
        self._changes: dict[str, Any] = {}  # drive id -> DROP publisher, used on the loop
        self._changed_at: dict[str, float] = {}  # drives with a change not yet put with BLOCK
        # the hub's conflating view this front end reads (for tests that count what it took)
        self.state_subscription: StateSubscription | None = None
        self._confirmed_at: dict[str, float] = {}  # when each drive's state was put with BLOCK
        # newest (seq, payload) of each drive handed to Zenoh: written on the loop only
        self._newest: dict[str, tuple[int, bytes]] = {}
        self._put_locks = {drive_id: threading.Lock() for drive_id in self._drive_ids}
        # under each drive's lock: the highest seq put on the wire
        self._sent_seq: dict[str, int] = {}
        # (seq, payload) of changes the loop could not put while the I/O thread held the lock
        self._deferred: dict[str, collections.deque[tuple[int, bytes]]] = {
            drive_id: collections.deque(maxlen=DEFER_LIMIT) for drive_id in self._drive_ids
        }
        self._wake = asyncio.Event()
        self._handover_lock = threading.Lock()
        self._handover_waiting = 0  # puts and queries handed to the loop, not yet taken
        self.overflow = 0  # puts and queries dropped: HANDOVER_LIMIT were waiting
        self.counters = ZenohCounters()
        self._replies = Replies(self._worker)
        self._params = ParamQueries(runtime, self.keys, self._drive_ids, self._replies)
        self._history = HistoryQueries(runtime, self.keys, self._drive_ids, self._replies)
        self._handlers: dict[KeyKind, Callable[[Pending], None]] = {
            KeyKind.STATE: self._query_state,
            KeyKind.COMMAND: self._query_command,
            KeyKind.PARAM: self._params.query,
            KeyKind.HEALTH: self._query_health,
            KeyKind.HISTORY: self._history.query,
            KeyKind.AUDIT: self._query_audit,
        }

    @property
    def worker(self) -> Worker:
        return self._worker

    def counted(self) -> FrontEndCounters:
        c = self.counters
        return FrontEndCounters(
            requests={"put": c.puts, "query": c.queries},
            dropped=self.overflow,
            commands_accepted=c.commands_accepted,
            commands_refused=c.commands_refused,
        )

    # ------------------------------------------------------------ life cycle

    async def run(self) -> None:
        self._loop = asyncio.get_running_loop()
        config = zenoh_config(self.section)
        if self.section.config_file is not None:
            log.info("zenoh session config from %s (used as it is)", self.section.config_file)
        self._worker.start()
        tasks: list[asyncio.Task[None]] = []
        try:
            with (
                self.hub.subscribe_states(on_ready=self._states_waiting) as states,
                self.hub.subscribe_events() as events,
            ):
                self.state_subscription = states
                self._changes = await asyncio.wrap_future(
                    self._worker.call(partial(self._io_open, config))
                )
                self._serving = True
                self._send_batch(self.hub.states(), self._now())
                self._forward_states()  # what the subscription took meanwhile
                await asyncio.wrap_future(self._worker.call(self._io_gateway_token))
                self.ready.set()
                log.info(
                    "zenoh front end serving %s/** (mode %s, listen %s, connect %s)",
                    self.keys.prefix,
                    *_endpoints_of(config),
                )
                tasks = [
                    asyncio.create_task(self._forward_events(events), name="zenoh-events"),
                    asyncio.create_task(self._heartbeat(), name="zenoh-heartbeat"),
                ]
                done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
                for task in done:
                    task.result()
        finally:
            await self._shutdown(tasks)

    async def _shutdown(self, tasks: list[asyncio.Task[None]]) -> None:
        self._serving = False
        self.ready.clear()
        self._changes = {}
        pending_tasks = [*tasks, *self._params.tasks, *self._history.tasks]
        for task in pending_tasks:
            task.cancel()
        await asyncio.gather(*pending_tasks, return_exceptions=True)
        for drive_id in self._drive_ids:  # the last word goes out before the session closes
            newest = self._newest.get(drive_id)
            if drive_id in self._changed_at or (
                newest is not None and self.hub.state(drive_id).seq > newest[0]
            ):
                self._confirm(drive_id, 0.0, from_hub=True)
        self._replies.refuse_all("the gateway is shutting down")
        done = self._worker.stop(final=self._io_close)
        try:
            await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(done)), CLOSE_TIMEOUT)
        except TimeoutError:
            log.warning("zenoh I/O thread did not close the session in %g s", CLOSE_TIMEOUT)
            raise
        finally:
            self._worker.join(CLOSE_TIMEOUT)  # returns at once unless cancelled meanwhile
        log.info("zenoh front end stopped")

    # ------------------------------------------------------------ I/O thread jobs

    def _io_open(self, config: Any) -> dict[str, Any]:
        self._link = ZenohLink.open(
            config,
            self.keys,
            self._drive_ids,
            self._command_from_zenoh,
            self._query_from_zenoh,
            recovery_cache=self.section.recovery_cache,
            on_link=self._link_from_zenoh,
        )
        return dict(self._link.change_publishers)

    def _io_close(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            link.close()

    def _io_gateway_token(self) -> None:
        if self._link is not None:
            self._link.declare_gateway_token()

    def _io_set_live(self, drive_id: str, live: bool) -> None:
        if self._link is not None:
            self._link.set_live(drive_id, live)

    def _io_publish_state(self, drive_id: str) -> None:
        """The drive's newest state, with BLOCK, under its lock (see the module notes);
        then, once the lock is let go, whatever the loop could not put meanwhile."""
        link = self._link
        if link is None:
            return
        lock = self._put_locks[drive_id]
        with lock:
            self._catch_up(drive_id, link.publish_state, repeat=True)
        while self._behind(drive_id):  # the loop tried the lock while this thread held it
            with lock:
                self._catch_up(drive_id, link.publish_state)

    def _behind(self, drive_id: str) -> bool:
        """A change not yet put: deferred, or newer than the last put (its hand-over may
        not have reached the queue yet)."""
        newest = self._newest.get(drive_id)
        sent = self._sent_seq.get(drive_id, -1)
        return bool(self._deferred[drive_id]) or (newest is not None and newest[0] > sent)

    def _catch_up(
        self, drive_id: str, put: Callable[[str, bytes], None], *, repeat: bool = False
    ) -> None:
        """Under the drive's lock: the deferred changes newer than the last put, in order,
        then the newest state if newer still (``repeat``: also if just as new)."""
        deferred = self._deferred[drive_id]
        sent = self._sent_seq.get(drive_id, -1)
        while deferred:
            seq, payload = deferred.popleft()
            if seq > sent:
                sent = self._sent_seq[drive_id] = seq
                put(drive_id, payload)
        newest = self._newest.get(drive_id)
        if newest is not None and (newest[0] > sent or (repeat and newest[0] == sent)):
            self._sent_seq[drive_id] = newest[0]
            put(drive_id, newest[1])

    def _io_publish_diag(self, drive_id: str, payload: bytes) -> None:
        if self._link is not None:
            self._link.publish_diag(drive_id, payload)

    def _io_publish_events(self, events: Sequence[tuple[str, bytes]]) -> None:
        if self._link is not None:
            self._link.publish_events(events)

    # ------------------------------------------------------------ Zenoh threads

    def _to_loop(self, callback: Callable[..., None], *args: Any) -> bool:
        """Hand a put or query over to the loop; False when it is not taken: the
        gateway is gone, or :data:`HANDOVER_LIMIT` are already waiting for the loop
        (nothing the network sends queues without a bound; the overflow is counted)."""
        loop = self._loop
        if loop is None:
            return False
        with self._handover_lock:
            if self._handover_waiting >= HANDOVER_LIMIT:
                self.overflow += 1
                return False
            self._handover_waiting += 1
        try:
            loop.call_soon_threadsafe(self._taken, callback, args)
        except RuntimeError:  # the loop is closed: the gateway is gone
            return False
        return True

    def _taken(self, callback: Callable[..., None], args: tuple[Any, ...]) -> None:
        with self._handover_lock:
            self._handover_waiting -= 1
        callback(*args)

    def _command_from_zenoh(self, key: str, payload: Payload, client: str) -> None:
        self._to_loop(self._on_command_put, key, payload, client)

    def _link_from_zenoh(self, seen: LinkSeen) -> None:
        self._to_loop(self._on_link, seen)

    def _on_link(self, seen: LinkSeen) -> None:
        """A link opened or closed on the audit trail: the certificate's name, when the
        link authenticated with one, is the identity (what the access control matches)."""
        host = seen.remote.rpartition(":")[0] or seen.remote
        self.runtime.audit.record(
            Kind.LINK_OPEN if seen.opened else Kind.LINK_CLOSE,
            Result.SUCCESS,
            interface="zenoh",
            peer=host,
            identity=seen.auth or seen.client,
            detail=f"{seen.remote}, session {seen.client}"
            + (f", certificate {seen.auth}" if seen.auth else ", no certificate"),
        )

    def _query_from_zenoh(self, incoming: Incoming) -> None:
        if not self._to_loop(self._on_query, incoming):
            incoming.query.drop()

    # ------------------------------------------------------------ publishing (loop)

    def _send_state(self, state: DriveState, now: float) -> None:
        """A change: put it now with DROP; the newest state follows with BLOCK (settle)."""
        self._send_batch((state,), now)

    def _send_batch(self, batch: Iterable[DriveState], now: float) -> None:
        """Changes of different drives: encode them all, then put them back to back
        (Zenoh packs puts that follow each other closely into fewer transmissions).

        A state no newer than one handed over already is skipped. Hot path of the
        fan-out: every state of every drive passes here.
        """
        newest, changed_at, live = self._newest, self._changed_at, self._live
        ready: list[tuple[str, tuple[int, bytes]]] = []
        for state in batch:
            drive_id = state.id
            online = state.comm is _ONLINE
            if online is not (drive_id in live):
                self._set_live(drive_id, online)
            entry = newest.get(drive_id)
            if entry is not None and state.seq <= entry[0]:
                continue
            newest[drive_id] = entry = (state.seq, encode_state(state))
            if drive_id not in changed_at:
                self._wake.set()
            changed_at[drive_id] = now
            ready.append((drive_id, entry))
        self._put_changes(ready)

    def _put_changes(self, changes: list[tuple[str, tuple[int, bytes]]]) -> None:
        """Each drive's change (seq, payload) with DROP, under the drive's lock; deferred
        while the I/O thread holds that lock (whoever takes it next puts it, in order)."""
        publishers, locks, deferred, sent = (
            self._changes,
            self._put_locks,
            self._deferred,
            self._sent_seq,
        )
        for drive_id, (seq, payload) in changes:
            publisher = publishers.get(drive_id)
            if publisher is None:
                continue
            lock = locks[drive_id]
            if not lock.acquire(False):  # positional: a keyword costs as much again
                deferred[drive_id].append((seq, payload))
                continue
            try:
                if deferred[drive_id]:
                    self._catch_up(drive_id, partial(_drop_put, publisher))
                elif seq > sent.get(drive_id, -1):  # _catch_up's usual case, inline: the
                    sent[drive_id] = seq  # partial and the call were 5 % of a state's work
                    _drop_put(publisher, drive_id, payload)
            finally:
                lock.release()

    def _set_live(self, drive_id: str, live: bool) -> None:
        if live:
            self._live.add(drive_id)
        else:
            self._live.discard(drive_id)
        self._worker.post(partial(self._io_set_live, drive_id, live))

    def _confirm(self, drive_id: str, now: float, *, from_hub: bool = False) -> None:
        """Hand the drive's newest state put so far to the I/O thread, to be put with BLOCK.

        Not a newer state still waiting in the hub's subscription: that one is put with
        DROP when the subscription yields it (and confirmed once settled); taken here, it
        would reach Zenoh only through the I/O slot, where a newer one can replace it
        before the thread runs. ``from_hub`` (shutdown, the subscription is closed): the
        hub's newest state.
        """
        newest = self._newest.get(drive_id)
        if newest is None or from_hub:
            state = self.hub.state(drive_id)
            if newest is None or state.seq > newest[0]:
                self._newest[drive_id] = (state.seq, encode_state(state))
        self._worker.offer((KeyKind.STATE, drive_id), partial(self._io_publish_state, drive_id))
        self._confirmed_at[drive_id] = now
        self._changed_at.pop(drive_id, None)

    def _due(
        self, drive_id: str, now: float, period: float, early: float = HEARTBEAT_SLACK
    ) -> bool:
        """Settled since its last change, or a heartbeat (up to ``early`` before its time)
        since its last BLOCK put."""
        changed = self._changed_at.get(drive_id)
        if changed is not None and now - changed >= SETTLE - HEARTBEAT_SLACK:
            return True
        confirmed = self._confirmed_at.get(drive_id, -math.inf)
        return now - confirmed >= period - early

    def _now(self) -> float:
        loop = self._loop
        return loop.time() if loop is not None else time.monotonic()

    def _states_waiting(self) -> None:
        """The hub has changes for this front end: they are forwarded in the loop's next
        turn, so the changes an adapter makes in one cycle are put back to back."""
        loop = self._loop
        if loop is not None:
            loop.call_soon(self._forward_states)

    def _forward_states(self) -> None:
        states = self.state_subscription
        if not self._serving or states is None:
            return  # before serving, run() forwards them; at shutdown, the last word does
        try:
            self._send_batch(states.drain(), self._now())  # at most one state per drive
        except Exception:
            log.exception("zenoh front end: state changes could not be published")

    async def _forward_events(self, events: EventSubscription) -> None:
        while True:
            first = await events.get()
            batch = [(ev.drive_id, encode_json(ev.to_json())) for ev in (first, *events.drain())]
            await asyncio.wrap_future(self._worker.call(partial(self._io_publish_events, batch)))

    def _send_diag(self, drive_id: str, ts: float) -> None:
        try:
            figures = self.runtime.drive_diagnostics(drive_id)
        except Exception:
            log.exception("diagnostics of drive %s failed", drive_id)
            return
        body = {"id": drive_id, "bus": self.runtime.bus_of(drive_id), "ts": ts, **figures}
        payload = encode_json(body)
        self._worker.offer(
            (KeyKind.DIAG, drive_id), partial(self._io_publish_diag, drive_id, payload)
        )

    async def _heartbeat(self) -> None:
        """Settle and heartbeat puts (BLOCK) of every drive, diagnostics every heartbeat."""
        period = self.section.heartbeat
        early = max(HEARTBEAT_SLACK, HEARTBEAT_BATCH * period)
        next_diag = self._now()
        while True:
            self._wake.clear()
            now = self._now()
            for drive_id in self._drive_ids:
                if self._due(drive_id, now, period, early):
                    self._confirm(drive_id, now)
            if now >= next_diag - HEARTBEAT_SLACK:
                wall = time.time()
                for i, drive_id in enumerate(self._drive_ids, 1):
                    self._send_diag(drive_id, wall)
                    if i % DIAG_BATCH == 0:
                        await asyncio.sleep(0)  # the buses run between two batches
                next_diag = now + period
            due = min(
                [
                    next_diag,
                    *(t + SETTLE for t in self._changed_at.values()),
                    *(t + period for t in self._confirmed_at.values()),
                ]
            )
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for swallows a cancellation
            # that arrives as the wake-up fires, and the shutdown then waits on this task
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(max(0.0, due - self._now())):
                    await self._wake.wait()

    # ------------------------------------------------------------ commands (loop)

    def _on_command_put(self, key: str, payload: Payload, client: str = ANONYMOUS) -> None:
        if not self._serving:
            return
        self.counters.puts += 1
        parsed = self.keys.parse(key)
        if parsed is None or parsed.kind != KeyKind.COMMAND.value or parsed.rest:
            log.warning("zenoh command put on %s ignored: not a drive's command key", key)
            return
        self._apply_command(parsed.drive_id, payload, client)  # the hub logs a refusal

    def _apply_command(
        self, drive_id: str, payload: Payload, client: str = ANONYMOUS
    ) -> dict[str, Any]:
        """Parse and submit a command; refusals are reported on the drive's events key
        (and logged by the hub, rate-limited per client and reason)."""
        body = self._submit_command(drive_id, payload, client)
        if body.get("accepted"):
            self.counters.commands_accepted += 1
        else:
            self.counters.commands_refused += 1
        return body

    def _submit_command(self, drive_id: str, payload: Payload, client: str) -> dict[str, Any]:
        if drive_id not in self._drive_ids:
            return command_refused(f"no drive {drive_id!r}")
        try:
            if isinstance(payload, Oversize):
                raise CommandRejected(too_large(payload.size))
            cmd = parse_command(payload)
        except CommandRejected as exc:
            self.hub.event(
                drive_id,
                EventKind.COMMAND_REFUSED,
                f"command from {Source.ZENOH.value} {client} refused: {exc.reason}",
                source=Source.ZENOH.value,
                client=client,
            )
            return command_refused(exc.reason)
        try:
            self.hub.submit(drive_id, Source.ZENOH, cmd, client)  # reports its own refusals
        except CommandRejected as exc:
            self.runtime.audit.command(
                cmd, Result.FAILURE, **self._who(client), drive=drive_id, why=exc.reason
            )
            return command_refused(exc.reason)
        except UnknownDrive:
            return command_refused(f"no drive {drive_id!r}")
        if not cmd.is_empty:  # a keep-alive (``{}``) is no audited command
            self.runtime.audit.command(cmd, Result.SUCCESS, **self._who(client), drive=drive_id)
        return command_accepted()

    @staticmethod
    def _who(client: str) -> dict[str, str]:
        """Who a command is from on the audit trail: the session's label (its role is what
        the router's access control let it put: docs/operations.md, "Users and roles")."""
        return {"interface": "zenoh", "peer": client, "identity": client}

    # ------------------------------------------------------------ queries (loop)

    def _on_query(self, incoming: Incoming) -> None:
        if not self._serving:
            with contextlib.suppress(Exception):
                incoming.query.drop()
            return
        pending = self._replies.take(incoming)
        self.counters.queries += 1
        try:
            self._handlers[incoming.kind](pending)
        except Exception as exc:
            log.exception("zenoh query on %s failed", incoming.key)
            self._replies.answer(pending, [Answer.error(error_body(exc))])

    def _query_state(self, pending: Pending) -> None:
        incoming = pending.incoming
        if not incoming.targets and is_concrete(incoming.key):
            self._replies.refuse(pending, f"no drive state at {incoming.key}")
            return
        answers = [
            Answer(True, encode_state(self.hub.state(d)), self.keys.key(KeyKind.STATE, d))
            for d in incoming.targets
        ]
        self._replies.answer(pending, answers)

    def _query_command(self, pending: Pending) -> None:
        incoming = pending.incoming
        parsed = self.keys.parse(incoming.key)
        if not is_concrete(incoming.key) or parsed is None:
            self._replies.refuse(pending, "a command names one drive: <prefix>/drives/<id>/command")
            return
        body = self._apply_command(parsed.drive_id, incoming.payload, incoming.client)
        self._replies.answer(pending, [Answer.reply(incoming.key, body)])

    def _query_audit(self, pending: Pending) -> None:
        """``<prefix>/gateway/audit[?since=N]``: the newest audit records (engineers: the
        router's access control says who may ask, config/zenoh-secure.json5)."""
        since = 0
        for part in filter(None, pending.incoming.parameters.split(";")):
            name, _, value = part.partition("=")
            if name != "since" or not (value.isascii() and value.isdigit() and len(value) < 13):
                self._replies.refuse(pending, "the audit key takes since=N only")
                return
            since = int(value)
        body = {"records": self.runtime.audit.newest(since=since)}
        self._replies.answer(pending, [Answer.reply(self.keys.key(KeyKind.AUDIT), body)])

    def _query_health(self, pending: Pending) -> None:
        body = self.runtime.health()
        self._replies.answer(pending, [Answer.reply(self.keys.key(KeyKind.HEALTH), body)])
