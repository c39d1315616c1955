"""Each line on a thread and an event loop of its own, so that nothing else holds up its
timing (docs/decisions/0071-a-loop-per-line.md).

:class:`LineThread` runs one adapter's ``run`` on a new event loop in a thread of its own:
the Profibus master's request/reply timing, the DeviceNet polls and keep-alives, the
CANopen SYNC, RPDOs and heartbeats, and the line's simulator when the bus is simulated.
The daemon's loop keeps the hub and the front ends. They meet through
:class:`~gateway.runtime.lineport.LinePort` (readings out, the desired command in, neither
side waiting on the other) and three narrow calls:

- ``run`` (a coroutine on the daemon's loop) ends, or raises, as the adapter's ``run``
  did; cancelling it cancels the adapter on its loop and waits, bounded by
  :data:`LEAVE_BOUND`, for it to leave the bus cleanly (safety rule 4);
- ``read_param`` / ``write_param`` run the adapter's own on the line's loop;
- ``diagnostics`` gives the line's figures as the line last built them (every
  :data:`DIAG_PERIOD`, on its own loop, never per request from a front end), with the
  events its hand-over dropped (``events_dropped``).

It stands in the runtime's adapters for its adapter (:class:`gateway.adapter.DriveAdapter`).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import threading
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from gateway.adapter import DriveAdapter, ParamValue
from gateway.errors import DriveOffline
from gateway.hub import Hub
from gateway.runtime.lineport import LinePort

log = logging.getLogger(__name__)

DIAG_PERIOD = 0.25  # s between two builds of a line's diagnostics, on the line's loop
LEAVE_BOUND = 10.0  # s a cancelled line may take to leave its bus before it is left behind
T = TypeVar("T")


class LineThread:
    """One adapter on a thread and an event loop of its own (see the module docstring)."""

    def __init__(self, adapter: DriveAdapter, hub: Hub) -> None:
        self.adapter = adapter
        self.name = adapter.name
        self._hub = hub
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        self._diag: dict[str, Any] = {}
        self._diag_waiters: list[asyncio.Future[dict[str, Any]]] = []
        self._leaving = False
        self._requests_lock = threading.Lock()
        self._requests: set[concurrent.futures.Future[Any]] = set()
        self._closed = False
        self.port: LinePort | None = None
        self.claimed = asyncio.Event()
        """Set (on the daemon's loop) once the adapter's own ``claimed`` is set; an adapter
        without one claims nothing: set at start."""
        self.thread: threading.Thread | None = None

    # ------------------------------------------------------------ the daemon's side

    async def run(self) -> None:
        """Run the adapter on its own thread until it ends or this is cancelled."""
        main = asyncio.get_running_loop()
        port = self.port = LinePort(self._hub, main.call_soon_threadsafe)
        done: asyncio.Future[None] = main.create_future()
        self.thread = threading.Thread(
            target=self._thread_main,
            args=(main, done, port),
            name=f"line-{self.name}",
            daemon=True,
        )
        self.thread.start()
        try:
            await asyncio.shield(done)
        except asyncio.CancelledError:
            await self._leave(done)
            raise
        finally:
            port.flush()  # what the line said while leaving

    async def _leave(self, done: asyncio.Future[None]) -> None:
        """Cancel the adapter on its loop and wait, bounded, until it has left the bus."""
        self._leaving = True  # seen by the line if its task does not exist yet
        loop, task = self._loop, self._task
        if loop is not None and task is not None:
            with contextlib.suppress(RuntimeError):  # its loop closed meanwhile
                loop.call_soon_threadsafe(task.cancel)
        try:
            async with asyncio.timeout(LEAVE_BOUND):
                await asyncio.shield(done)
        except TimeoutError:
            log.error("bus %s: not off its line %g s after the stop", self.name, LEAVE_BOUND)
        except (Exception, asyncio.CancelledError):  # its own outcome: the run is over
            pass

    def diagnostics(self) -> dict[str, Any]:
        """The line's figures as its loop last built them ({} before the first build)."""
        return self._diag

    async def next_diagnostics(self) -> dict[str, Any]:
        """The line's figures of its next build (at most :data:`DIAG_PERIOD` away)."""
        waiter: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._diag_waiters.append(waiter)
        return await waiter

    def _diag_built(self, diag: dict[str, Any]) -> None:
        waiters, self._diag_waiters = self._diag_waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(diag)

    async def read_param(self, drive_id: str, number: int, subindex: int) -> ParamValue:
        return await self._on_line(lambda: self.adapter.read_param(drive_id, number, subindex))

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: ParamValue
    ) -> None:
        await self._on_line(lambda: self.adapter.write_param(drive_id, number, subindex, value))

    async def call(self, fn: Callable[[], T]) -> T:
        """``fn()`` run on the line's loop (a simulator poked by a test, a figure read)."""

        async def wrapped() -> T:
            return fn()

        return await self._on_line(wrapped)

    async def _on_line(self, make: Callable[[], Awaitable[T]]) -> T:
        async def coro() -> T:
            return await make()

        with self._requests_lock:  # the line's loop is not closed meanwhile (_close)
            loop = self._loop
            if loop is None or self._closed:
                raise DriveOffline(f"bus {self.name} is not running")
            future = asyncio.run_coroutine_threadsafe(coro(), loop)
            self._requests.add(future)
        future.add_done_callback(self._requests.discard)
        try:
            return await asyncio.wrap_future(future)
        except asyncio.CancelledError:
            current = asyncio.current_task()
            if future.cancelled() and not (current is not None and current.cancelling()):
                raise DriveOffline(f"bus {self.name} stopped during the request") from None
            future.cancel()
            raise

    # ------------------------------------------------------------ the line's side

    def _thread_main(
        self,
        main: asyncio.AbstractEventLoop,
        done: asyncio.Future[None],
        port: LinePort,
    ) -> None:
        loop = asyncio.new_event_loop()
        outcome: BaseException | None = None
        try:
            loop.run_until_complete(self._line_main(main, port))
        except BaseException as exc:  # handed to the daemon's loop, which raises it
            outcome = exc
        finally:
            self._close(loop)
        with contextlib.suppress(RuntimeError):  # the daemon's loop closed first
            main.call_soon_threadsafe(_resolve, done, outcome)

    async def _line_main(self, main: asyncio.AbstractEventLoop, port: LinePort) -> None:
        loop = asyncio.get_running_loop()
        self._loop = loop
        task = self._task = loop.create_task(self.adapter.run(port), name=f"bus-{self.name}")
        if self._leaving:  # cancelled before the task existed
            task.cancel()
        helpers = [
            loop.create_task(self._diagnostics_loop(main)),
            loop.create_task(self._watch_claimed(main, task)),
        ]
        try:
            await task
        finally:
            for helper in helpers:
                helper.cancel()
            await asyncio.gather(*helpers, return_exceptions=True)

    async def _diagnostics_loop(self, main: asyncio.AbstractEventLoop) -> None:
        while True:
            try:
                self._diag = diag = self._with_port(self.adapter.diagnostics())
            except Exception:  # an adapter between states: the last figures stay
                log.debug("bus %s: diagnostics failed", self.name, exc_info=True)
            else:
                if self._diag_waiters:
                    main.call_soon_threadsafe(self._diag_built, diag)
            await asyncio.sleep(DIAG_PERIOD)

    def _with_port(self, diag: dict[str, Any]) -> dict[str, Any]:
        """The adapter's figures and the hand-over's own: the events its outbox dropped
        (:data:`~gateway.runtime.lineport.OUTBOX_EVENTS` waiting)."""
        port = self.port
        if port is None:
            return diag
        return {**diag, "events_dropped": port.events_dropped}

    async def _watch_claimed(
        self, main: asyncio.AbstractEventLoop, task: asyncio.Task[None]
    ) -> None:
        """Tell the daemon's loop once the adapter holds its line: its own ``claimed``
        event; an adapter without one once its run took its first step without ending
        (a line refused at start is refused there)."""
        event = getattr(self.adapter, "claimed", None)
        if isinstance(event, asyncio.Event):
            await event.wait()
        else:
            await asyncio.sleep(0)  # the run task, made first, steps first
        if not task.done():
            main.call_soon_threadsafe(self.claimed.set)

    def _close(self, loop: asyncio.AbstractEventLoop) -> None:
        """Refuse new requests, cancel what is left on the line's loop, answer the requests
        that never ran (:class:`DriveOffline`), close the loop."""
        with self._requests_lock:
            self._closed = True
        for _ in range(3):  # a request queued before the refusal starts in the first round
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            if not pending:
                break
            for t in pending:
                t.cancel()
            loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
        loop.run_until_complete(loop.shutdown_asyncgens())
        loop.run_until_complete(loop.shutdown_default_executor())
        gone = DriveOffline(f"bus {self.name} stopped during the request")
        for future in list(self._requests):
            with contextlib.suppress(concurrent.futures.InvalidStateError):
                future.set_exception(gone)
        loop.close()


def _resolve(done: asyncio.Future[None], outcome: BaseException | None) -> None:
    if done.done():
        return
    if outcome is None:
        done.set_result(None)
    elif isinstance(outcome, asyncio.CancelledError):
        done.cancel()
    else:
        done.set_exception(outcome)
