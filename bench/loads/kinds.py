"""The loads of the loads benchmark: each started, brought up and ended by the benchmark.

- a :class:`ChildLoad` is one or more child processes of :mod:`bench.loads.clients`
  (WebSocket pages, the /metrics scraper, slow connections, token guessing, CPU-bound
  loops), each ended by its pid (SIGTERM, then SIGKILL after :data:`END_BOUND`);
- a :class:`FloodLoad` is a thread of this process sending CAN frames on a line's
  in-process ``virtual`` channel at a paced rate, up to a count (EMCY frames, Duplicate
  MAC ID check requests);
- :class:`NoLoad` is the reference.

Every one of them ends by itself too: a child after its ``--seconds``, a flood at its
count or at the end of its window.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from bench.loads.gateway import ROOT

READY_BOUND: Final = 40.0  # s a load may take to come up before its window opens anyway
END_BOUND: Final = 10.0  # s a child has after SIGTERM before SIGKILL
FLOOD_TICK: Final = 0.005  # s between two bursts of a flood (its rate kept over each)
FLOOD_TAIL: Final = 1.0  # s a flood's window lasts beyond its last frame (the backlog)


async def poll_until(done: Callable[[], bool], bound: float, step: float = 0.05) -> bool:
    """Wait until ``done()`` (a process's end, a line in its output: nothing this loop
    could await), at most ``bound`` s, without holding the loop; whether it is done."""
    deadline = time.monotonic() + bound
    while not done():
        if time.monotonic() >= deadline:
            return False
        await asyncio.sleep(step)
    return True


@dataclass
class Child:
    """One child process of :mod:`bench.loads.clients`, its output in files."""

    name: str
    proc: subprocess.Popen[bytes]
    out: Path
    err: Path

    def lines(self) -> list[dict[str, Any]]:
        docs = []
        with contextlib.suppress(OSError):
            for line in self.out.read_text(errors="replace").splitlines():
                with contextlib.suppress(ValueError):
                    doc = json.loads(line)
                    if isinstance(doc, dict):
                        docs.append(doc)
        return docs

    def ready(self) -> bool:
        return any("ready" in d for d in self.lines())

    def result(self) -> dict[str, Any]:
        found = [d["result"] for d in self.lines() if isinstance(d.get("result"), dict)]
        if found:
            result: dict[str, Any] = found[-1]
            return result
        tail = self.err.read_text(errors="replace")[-300:] if self.err.exists() else ""
        return {"no_result": True, "exit": self.proc.returncode, "stderr": tail}


class Children:
    """Every child process the benchmark started; each ended by its own pid."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.all: list[Child] = []

    def start(self, name: str, argv: list[str]) -> Child:
        n = len(self.all)
        out, err = self.tmp / f"{n:02d}-{name}.out", self.tmp / f"{n:02d}-{name}.err"
        with out.open("wb") as stdout, err.open("wb") as stderr:
            proc = subprocess.Popen(
                [sys.executable, "-m", "bench.loads.clients", *argv],
                cwd=ROOT,
                stdout=stdout,
                stderr=stderr,
                stdin=subprocess.DEVNULL,
            )
        child = Child(name, proc, out, err)
        self.all.append(child)
        return child

    @staticmethod
    async def end(child: Child) -> None:
        """SIGTERM by pid, SIGKILL after END_BOUND; waits without holding the loop."""
        proc = child.proc
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
        if not await poll_until(lambda: proc.poll() is not None, END_BOUND):
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await poll_until(lambda: proc.poll() is not None, END_BOUND)

    def kill_all(self) -> None:
        """The last resort (a failed run): SIGKILL each child still running, by pid."""
        for child in self.all:
            if child.proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    child.proc.kill()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    child.proc.wait(END_BOUND)


class NoLoad:
    """The reference: nothing but the gateway's own work."""

    def __init__(self, name: str = "none") -> None:
        self.name = name

    async def start(self) -> None:
        return

    async def ready(self) -> bool:
        return True

    def window(self, default: float) -> float:
        return default

    async def stop(self) -> dict[str, Any]:
        return {}


class ChildLoad(NoLoad):
    """Child processes of :mod:`bench.loads.clients`, one per argv."""

    def __init__(self, name: str, children: Children, argvs: list[list[str]]) -> None:
        super().__init__(name)
        self.children = children
        self.argvs = argvs
        self.started: list[Child] = []

    async def start(self) -> None:
        self.started = [self.children.start(self.name, argv) for argv in self.argvs]

    async def ready(self) -> bool:
        """Until each child said it is up or has ended (bounded by READY_BOUND)."""
        await poll_until(
            lambda: all(c.ready() or c.proc.poll() is not None for c in self.started),
            READY_BOUND,
            0.1,
        )
        return all(c.ready() and c.proc.poll() is None for c in self.started)

    async def stop(self) -> dict[str, Any]:
        await asyncio.gather(*(Children.end(c) for c in self.started))
        results = [c.result() for c in self.started]
        return results[0] if len(results) == 1 else {"processes": results}


Frame = Callable[[random.Random], tuple[int, bytes]]
"""A flood's next frame: (11-bit identifier, data)."""


@dataclass
class FloodLoad(NoLoad):
    """CAN frames on an in-process ``virtual`` channel from a thread, ``rate`` a second up
    to ``count`` or the end of the window (see the module docstring)."""

    name: str
    channel: str
    frame: Frame
    count: int
    rate: float
    _stop: threading.Event = field(default_factory=threading.Event)
    _out: dict[str, Any] = field(default_factory=dict)
    _thread: threading.Thread | None = None

    def window(self, default: float) -> float:
        return min(default, self.count / self.rate + FLOOD_TAIL)

    async def ready(self) -> bool:
        self._thread = threading.Thread(target=self._run, name=f"flood-{self.name}", daemon=True)
        self._thread.start()
        return True

    async def stop(self) -> dict[str, Any]:
        self._stop.set()
        thread = self._thread
        if thread is not None:
            await poll_until(lambda: not thread.is_alive(), END_BOUND, 0.02)
        return dict(self._out)

    def _run(self) -> None:
        import can

        # an unbounded receive queue, emptied every tick: a ``virtual`` bus puts each frame
        # into every other bus's queue and waits while one is full, so a bounded queue
        # nobody reads would hold every other sender on the channel (the line, its drives)
        bus = can.Bus(interface="virtual", channel=self.channel)
        rng = random.Random(0x10AD)
        sent = 0
        start = time.monotonic()
        try:
            while sent < self.count and not self._stop.is_set():
                due = min(self.count, int((time.monotonic() - start) * self.rate) + 1)
                for _ in range(due - sent):
                    arbitration_id, data = self.frame(rng)
                    bus.send(
                        can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)
                    )
                    sent += 1
                _drain(bus)
                time.sleep(FLOOD_TICK)
        except Exception as exc:  # reported with the figures
            self._out["error"] = f"{type(exc).__name__}: {exc}"
        finally:
            bus.shutdown()
            seconds = time.monotonic() - start
            self._out.update(sent=sent, seconds=round(seconds, 3), asked=self.count)
            self._out["frames_per_s"] = round(sent / max(seconds, 1e-9), 1)


def _drain(bus: Any) -> None:
    """Everything the channel carried to the flood's own bus (it reads none of it)."""
    while bus.recv(0) is not None:
        pass


def emcy_frame(node: int) -> Frame:
    """EMCY frames of CANopen node ``node`` (CiA 301 §7.2.7), 8 random data bytes each."""
    from adapters.canopen.codec.frames import emcy_id

    cob = emcy_id(node)

    def frame(rng: random.Random) -> tuple[int, bytes]:
        return cob, rng.randbytes(8)

    return frame


def dupmac_frame(mac: int) -> Frame:
    """Duplicate MAC ID check requests for ``mac`` (another station claiming it), each with
    a random vendor and serial number."""
    from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind

    def frame(rng: random.Random) -> tuple[int, bytes]:
        check = DupMacCheck(mac, DupMacKind.REQUEST, 0, rng.getrandbits(16), rng.getrandbits(32))
        can_frame = check.to_frame()
        return can_frame.arbitration_id, can_frame.data

    return frame
