"""One CAN adapter: what the DeviceNet and CANopen adapters share, as template methods
with public hooks each bus fills in.

:class:`CanAdapter` holds a line's drives and runs its engine on the shared CAN driver
loop (:mod:`adapters.link.candriver`) in the event loop's thread. Its template methods:

* :meth:`CanAdapter.run`: every drive offline with its capabilities published, the link
  opened, the line started (a simulated line starts its devices), the driver run until
  cancelled; then, bounded, the bus's clean leave while the link is open
  (:meth:`~CanAdapter.leave`), the adapter's own work ended (:meth:`~CanAdapter.stop_work`),
  the jobs waiting for an answer cancelled, the line stopped, every drive offline,
  stopped, not at reference.
* :meth:`CanAdapter.diagnostics`: the line (configured interface, channel and bit rate,
  the bus's own entries, the link's figures) and each drive (the engine's view of its
  node, then the adapter's own entries, which win on a shared key).
* the driver's side (:class:`AdapterLine`): the link's events as the engine's, its
  :class:`~adapters.can.events.Send` actions as frames (``isinstance``), every other action
  to the adapter's handler for its type (:meth:`~CanAdapter.handlers`), the engine's
  receive hold, and the pass hooks (:meth:`~CanAdapter.before_step`,
  :meth:`~CanAdapter.after_step`, :meth:`~CanAdapter.wake_at`,
  :meth:`~CanAdapter.received`).
* a job that waits for its node's answer (an SDO transfer, an explicit request):
  :meth:`CanAdapter.exchange`, bounded, its answer delivered by :meth:`CanAdapter.answered`.

A bus's adapter gives its parts (:class:`BusSpec`: its options, the configured
interface's line, the answer of its engine to a job), its drive record (a :class:`Drive`,
:meth:`~CanAdapter.new_drive`), its engine (:meth:`~CanAdapter.make_engine`), a handler
for each of its engine's actions (a method marked :func:`handles`) and the hooks it needs;
the hooks with a body are optional.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import FunctionType
from typing import Any, ClassVar, Generic, Protocol, TypeVar

from adapters.can.events import (
    BadFrame,
    BusErrorIn,
    FrameIn,
    LinkDown,
    NodeUnavailable,
    Send,
    TxFailed,
)
from adapters.can.frame import CanFrame
from adapters.link.can import CanConfig, CanEvent, CanLink, CanLinks
from adapters.link.candriver import CanDriver
from adapters.link.canline import CanLine, LinkEvents
from adapters.link.config import missing_options, unsimulated
from adapters.link.engine import Engine
from gateway.adapter import HubPort
from gateway.config import BusConfig, DriveConfig
from gateway.errors import AdapterError, DriveOffline, GatewayTimeout
from gateway.model import CommState, Device
from gateway.schema import Table

EventT = TypeVar("EventT")
ActionT = TypeVar("ActionT")
EventT_contra = TypeVar("EventT_contra", contravariant=True)
ActionT_co = TypeVar("ActionT_co", covariant=True)
FrameT = TypeVar("FrameT", bound=CanFrame)


class CanEngine(Engine[EventT_contra, ActionT_co], Protocol[EventT_contra, ActionT_co]):
    """What the adapter needs of its engine beyond stepping it."""

    def hold_until(self, now: float) -> float | None:
        """Until when received frames may wait (the driver's receive hold), or None."""
        ...

    def node_diagnostics(self, address: int) -> Mapping[str, Any]:
        """The engine's view of one node."""
        ...


class CanBusOptions(Protocol):
    """The bus keys every CAN line has."""

    @property
    def interface(self) -> str: ...

    @property
    def channel(self) -> str: ...

    @property
    def bitrate(self) -> int: ...

    @property
    def simulate(self) -> bool: ...


@dataclass(slots=True)
class Drive:
    """A configured drive of the line as the adapter keeps it; a bus's adapter adds the
    state of its drives' connections."""

    cfg: DriveConfig

    @property
    def id(self) -> str:
        return self.cfg.id


class Answer(Protocol):
    """The engine's answer to a job: it carries the job's token."""

    @property
    def token(self) -> int: ...


LINK_EVENTS: LinkEvents[Any, Any] = LinkEvents(FrameIn, BusErrorIn, BadFrame, LinkDown, TxFailed)
"""The link's events as every engine's on CAN (:mod:`adapters.can.events`): the
constructors the line glue of :mod:`adapters.link.canline` makes them with."""

EngineT = TypeVar("EngineT", bound=CanEngine[Any, Any])
DriveT = TypeVar("DriveT", bound=Drive)
OptionsT = TypeVar("OptionsT", bound=CanBusOptions)
AnswerT = TypeVar("AnswerT", bound=Answer)
HandlerT = TypeVar("HandlerT", bound=Callable[..., None])


@dataclass(frozen=True, slots=True)
class BusSpec:
    """What a bus brings to the CAN adapter."""

    options: type[CanBusOptions]
    """The bus's options class (what ``parse`` gives)."""
    parse: Callable[[Table], CanBusOptions]
    """The bus table's reader."""
    real_line: Callable[[CanConfig], CanLinks[Any]]
    """The configured interface's line factory."""
    answer: type[Answer]
    """The engine's answer to a job of :meth:`CanAdapter.exchange`."""


_HANDLES: dict[object, tuple[type, ...]] = {}


def handles(*kinds: type) -> Callable[[HandlerT], HandlerT]:
    """Marks a method of a :class:`CanAdapter` as the handler of the engine's actions of
    ``kinds`` (called with the time and the action)."""

    def mark(handler: HandlerT) -> HandlerT:
        _HANDLES[handler] = kinds
        return handler

    return mark


class CanAdapter(Generic[FrameT, EventT, ActionT, EngineT, DriveT, OptionsT, AnswerT]):
    """One line on CAN mastered by the gateway (see the module docstring)."""

    spec: ClassVar[BusSpec]
    devices: ClassVar[frozenset[Device]]
    address_range: ClassVar[tuple[int, int]]
    _handled: ClassVar[dict[type, str]] = {}
    """Action type -> the name of its handler (the methods marked :func:`handles`)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        handled = dict(cls._handled)
        for name, value in vars(cls).items():
            if isinstance(value, FunctionType):
                handled.update(dict.fromkeys(_HANDLES.get(value, ()), name))
        cls._handled = handled

    @classmethod
    def parse_bus_options(cls, table: Table) -> Any:
        return cls.spec.parse(table)

    def __init__(
        self,
        bus: BusConfig,
        *,
        links: CanLinks[FrameT] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``links``: the line, as the composition root chose it (a simulated line for
        ``simulate = true``); None: the configured interface and channel."""
        spec = self.spec
        self.bus = bus
        self.name = bus.name
        self.options: OptionsT = bus.options
        if not isinstance(bus.options, spec.options):
            raise missing_options(bus.name)
        o = self.options
        self.links: CanLinks[FrameT] | None = links
        """None for ``simulate = true`` without a simulated line: refused when it runs."""
        if links is None and not o.simulate:
            self.links = spec.real_line(CanConfig(o.interface, o.channel, o.bitrate))
        self.clock = clock
        self.drives: dict[int, DriveT] = {}
        self._by_id: dict[str, DriveT] = {}
        for cfg in bus.drives:
            drive = self.new_drive(cfg)
            self.drives[cfg.address] = drive
            self._by_id[cfg.id] = drive
        self.engine: EngineT | None = None
        self.link: CanLink[FrameT] | None = None
        self._driver: CanDriver[FrameT, EventT, ActionT] | None = None
        self._hub: HubPort | None = None
        self._pending: dict[int, asyncio.Future[AnswerT]] = {}
        self.claimed = asyncio.Event()
        """Set once the engine holds the line (the daemon's READY); never set when another
        master holds it."""
        self._handlers: dict[type, Callable[[float, Any], None]] = {
            kind: getattr(self, name) for kind, name in self._handled.items()
        }
        self._handlers[spec.answer] = self.answered
        self.setup()

    # ------------------------------------------------------------ hooks

    def new_drive(self, cfg: DriveConfig) -> DriveT:
        """The adapter's record of a configured drive; an AdapterError for one the line
        cannot have (the gateway's own address)."""
        raise NotImplementedError

    def setup(self) -> None:
        """The bus's own state, once the drives are known (the end of the constructor)."""
        return

    def make_engine(self) -> EngineT:
        """The engine of a new run (and the adapter's per-run state reset)."""
        raise NotImplementedError

    def publish_capabilities(self, d: DriveT) -> None:
        """Give the hub the drive's capabilities (when it has them)."""
        raise NotImplementedError

    async def leave(self, engine: EngineT, driver: CanDriver[FrameT, EventT, ActionT]) -> None:
        """Leave the line cleanly, bounded in time (the link is open; the driver's loop
        has ended)."""
        return

    async def stop_work(self) -> None:
        """End the adapter's own tasks (after the leave, before the jobs are cancelled)."""
        return

    def drive_left(self, d: DriveT) -> None:
        """The run ended: forget what the drive's connection held."""
        return

    def before_step(self, now: float) -> None:
        """Each driver pass, before the engine's step (the hub's commands in)."""
        return

    def after_step(self, now: float) -> None:
        """Each driver pass, after the engine's step, before the frames go out."""
        return

    def wake_at(self) -> float | None:
        """When the adapter wants a pass without a frame (None: only the engine decides)."""
        return None

    def received(self, now: float, event: CanEvent[FrameT]) -> None:
        """A link event, after the engine stepped it."""
        return

    def line_diagnostics(self, engine: EngineT | None) -> dict[str, Any]:
        """The bus's own entries of the line's diagnostics (the engine's figures)."""
        return {}

    def drive_diagnostics(self, d: DriveT) -> dict[str, Any]:
        """The adapter's entries of a drive's diagnostics."""
        return {}

    # ------------------------------------------------------------ run

    async def run(self, hub: HubPort) -> None:
        links = self.links
        if links is None:
            raise unsimulated(self.name)
        self._hub = hub
        for d in self.drives.values():
            hub.update(d.id, comm=CommState.OFFLINE)
            self.publish_capabilities(d)
        link = links.link()
        engine = self.make_engine()
        async with link:
            self.link, self.engine = link, engine
            line: AdapterLine[FrameT, EventT, ActionT] = AdapterLine(self)
            driver = self._driver = CanDriver(engine, link, line, self.clock)
            try:
                await links.start()
                await driver.run()
            finally:
                try:
                    if link.is_open:
                        await self.leave(engine, driver)
                    await self.stop_work()
                    self._stop_pending()
                finally:
                    await links.stop()  # a simulated line's devices, after the leave
                for d in self.drives.values():
                    self.drive_left(d)
                    hub.update(d.id, comm=CommState.OFFLINE, running=False, at_reference=False)
                self.link = self.engine = self._driver = None

    def _stop_pending(self) -> None:
        for fut in self._pending.values():
            fut.cancel()
        self._pending.clear()

    def _hub_port(self) -> HubPort:
        if self._hub is None:
            raise AdapterError("the adapter is not running")
        return self._hub

    def _handle(self, now: float, action: ActionT) -> None:
        self._handlers[type(action)](now, action)

    def _drive(self, drive_id: str) -> DriveT:
        d = self._by_id.get(drive_id)
        if d is None:
            raise DriveOffline(f"drive {drive_id} is not on bus {self.name}")
        return d

    # ------------------------------------------------------------ jobs

    async def exchange(
        self, d: DriveT, submit: Callable[[EngineT], int], bound: float, what: str
    ) -> AnswerT:
        """A job for the drive's node (``submit`` queues it on the engine and gives its
        token) and its answer, within ``bound`` s (a GatewayTimeout naming ``what`` does
        not come); DriveOffline when the line is not running or the node not online."""
        engine, link = self.engine, self.link
        if engine is None or link is None:
            raise DriveOffline(f"drive {d.id}: bus {self.name} is not running")
        try:
            token = submit(engine)
        except NodeUnavailable as exc:
            raise DriveOffline(f"drive {d.id} is not online ({exc})") from None
        fut: asyncio.Future[AnswerT] = asyncio.get_running_loop().create_future()
        self._pending[token] = fut
        link.wake()
        try:
            async with asyncio.timeout(bound):  # not wait_for: it can swallow a cancellation
                return await fut
        except TimeoutError:
            raise GatewayTimeout(f"drive {d.id}: no {what} within {bound:g} s") from None
        finally:
            self._pending.pop(token, None)

    def answered(self, now: float, action: AnswerT) -> None:
        """The handler of the engine's answer to a job of :meth:`exchange`
        (:attr:`BusSpec.answer`)."""
        fut = self._pending.pop(action.token, None)
        if fut is not None and not fut.done():
            fut.set_result(action)

    # ------------------------------------------------------------ diagnostics

    def diagnostics(self) -> dict[str, Any]:
        o = self.options
        engine, link = self.engine, self.link
        line: dict[str, Any] = {
            "interface": o.interface,
            "channel": o.channel,
            "bitrate_expected": o.bitrate,
            "simulated": o.simulate,
            "running": engine is not None,
            **self.line_diagnostics(engine),
        }
        if link is not None:
            line.update(link.diagnostics())
        drives: dict[str, Any] = {}
        for d in self.drives.values():
            entry = {} if engine is None else dict(engine.node_diagnostics(d.cfg.address))
            entry.update(self.drive_diagnostics(d))
            drives[d.id] = entry
        line["drives"] = drives
        return line


class AdapterLine(CanLine[FrameT, EventT, ActionT]):
    """An adapter's line as the CAN driver loop sees it (:mod:`adapters.link.candriver`):
    the link's events as the engine's (:data:`LINK_EVENTS`), its
    frames, its other actions to the adapter's handlers, the engine's receive hold and the
    adapter's pass hooks."""

    def __init__(self, adapter: CanAdapter[FrameT, EventT, ActionT, Any, Any, Any, Any]) -> None:
        super().__init__(LINK_EVENTS)
        self.adapter = adapter

    # every action passes here: no call before the handler's
    def frame(self, action: ActionT) -> FrameT | None:
        return action.frame if isinstance(action, Send) else None

    def handle(self, now: float, action: ActionT) -> None:
        self.adapter._handlers[type(action)](now, action)

    def before_step(self, now: float) -> None:
        self.adapter.before_step(now)

    def after_step(self, now: float) -> None:
        self.adapter.after_step(now)

    def wake_at(self) -> float | None:
        return self.adapter.wake_at()

    def received(self, now: float, event: CanEvent[FrameT]) -> None:
        self.adapter.received(now, event)

    def hold_until(self, now: float) -> float | None:
        engine = self.adapter.engine
        return None if engine is None else engine.hold_until(now)
