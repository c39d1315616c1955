"""A simulated line on CAN: the link factory the composition root gives a CAN adapter for
``simulate = true`` (the production adapter never imports a simulator).

The adapter opens its link on the configured in-process channel (``interface =
"virtual"``); once it is open, :meth:`SimulatedLine.start` runs the bus's simulated
drives on the same channel (the bus's runner; its start is awaited at most
:data:`SIM_START_BOUND` s, and what broke it is raised), and :meth:`SimulatedLine.stop`
ends them after the adapter has left the line.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Final, Generic, Protocol, TypeVar

from adapters.link.can import CanConfig, CanLinks, FrameT

SIM_START_BOUND: Final = 2.0  # s


class Runner(Protocol):
    """A bus's simulated drives on a channel."""

    started: asyncio.Event
    """Set once the drives are on the line."""

    async def run(self) -> None:
        """Run them until cancelled (or told to stop)."""
        ...


RunnerT = TypeVar("RunnerT", bound=Runner)


class SimulatedLine(CanLinks[FrameT], Generic[FrameT, RunnerT]):
    """The bus's drives simulated on its in-process channel (see the module docstring); a
    bus gives its link (``link``) and its runner (:meth:`new_runner`)."""

    def __init__(self, kind: str, name: str, config: CanConfig) -> None:
        """``kind``: the bus (names the runner's task); ``name``: the bus's name."""
        self.kind = kind
        self.name = name
        self.config = config
        self.runner: RunnerT | None = None
        """The simulated drives while the line runs (tests inject faults through it)."""
        self._task: asyncio.Task[None] | None = None

    def new_runner(self) -> RunnerT:
        """The runner of the bus's drives on :attr:`config`'s channel."""
        raise NotImplementedError

    async def start(self) -> None:
        runner = self.runner = self.new_runner()
        task = self._task = asyncio.create_task(runner.run(), name=f"{self.kind}-sim-{self.name}")
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(SIM_START_BOUND):
                await runner.started.wait()
        if task.done():
            task.result()  # raises what broke the simulator

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            await self.end(task)

    async def end(self, task: asyncio.Task[None]) -> None:
        """End the runner's task (default: cancelled)."""
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task


async def until_watched(
    watchers: list[Callable[[], None]],
    predicate: Callable[[], bool],
    loop: asyncio.AbstractEventLoop,
) -> None:
    """Until ``predicate()`` holds, checked on ``loop`` (the caller's) each time a pass of
    a simulator's loop, on another loop or thread, calls the ``watchers``."""
    passed = asyncio.Event()  # of ``loop``: set there only

    def wake() -> None:
        with contextlib.suppress(RuntimeError):  # the caller's loop closed meanwhile
            loop.call_soon_threadsafe(passed.set)

    watchers.append(wake)
    try:
        while True:
            passed.clear()  # before the check: a pass after it wakes the wait below
            if predicate():
                return
            await passed.wait()
    finally:
        watchers.remove(wake)
