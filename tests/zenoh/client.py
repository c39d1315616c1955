"""A Zenoh client for the tests: a peer that connects to the gateway's endpoint,
listens nowhere and scouts nothing (never a bare ``zenoh.Config()``).

Zenoh runs callbacks on its own threads; they copy what arrives into an
:class:`Inbox`, read with a timeout either from a plain thread (``get``) or from
the event loop (``aget``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import queue
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import zenoh

from gateway.model import client_label

T = TypeVar("T")


def client_config(
    endpoint: str, listen: bool = False, rcvbuf: int | None = None, zid: str | None = None
) -> zenoh.Config:
    """Connect to ``endpoint`` (or, ``listen`` true, listen on it for the gateway to connect);
    ``rcvbuf``: a small TCP receive buffer, to make a slow subscriber; ``zid``: the session
    id to take (hex), as any Zenoh client may choose its own."""
    doc: dict[str, Any] = {
        "mode": "peer",
        "listen": {"endpoints": [endpoint] if listen else []},
        "connect": {"endpoints": [] if listen else [endpoint]},
        # delay: how long open() may wait for its start conditions; Zenoh sometimes misses
        # that they are met and waits all of it (500 ms by default)
        "scouting": {
            "delay": 50,
            "multicast": {"enabled": False},
            "gossip": {"enabled": False},
        },
    }
    if rcvbuf is not None:
        doc["transport"] = {"link": {"tcp": {"so_rcvbuf": rcvbuf}}}
    if zid is not None:
        doc["id"] = zid.lstrip("0") or "0"  # the same id: Zenoh's config takes no leading 0
    return zenoh.Config.from_json5(json.dumps(doc))


@dataclass(frozen=True)
class Got:
    """A sample, copied out of Zenoh on its thread."""

    key: str
    put: bool
    payload: bytes
    encoding: str
    congestion: str
    at: float

    def json(self) -> Any:
        return json.loads(self.payload)


@dataclass(frozen=True)
class Replied:
    ok: bool
    key: str | None
    payload: bytes
    encoding: str

    def json(self) -> Any:
        return json.loads(self.payload)


def _copy_sample(sample: zenoh.Sample) -> Got:
    return Got(
        key=str(sample.key_expr),
        put=sample.kind == zenoh.SampleKind.PUT,
        payload=sample.payload.to_bytes(),
        encoding=str(sample.encoding),
        congestion=str(sample.congestion_control),
        at=time.monotonic(),
    )


def _copy_reply(reply: zenoh.Reply) -> Replied:
    ok = reply.ok
    if ok is not None:
        return Replied(True, str(ok.key_expr), ok.payload.to_bytes(), str(ok.encoding))
    err = reply.err
    assert err is not None
    return Replied(False, None, err.payload.to_bytes(), str(err.encoding))


class Inbox(Generic[T]):
    """Items pushed from Zenoh threads; ``loop`` given: read them with ``aget``."""

    def __init__(self, loop: asyncio.AbstractEventLoop | None = None) -> None:
        self._loop = loop
        self._sync: queue.Queue[T] = queue.Queue()
        self._async: asyncio.Queue[T] = asyncio.Queue()

    def push(self, item: T) -> None:
        if self._loop is None:
            self._sync.put(item)
            return
        with contextlib.suppress(RuntimeError):  # the test's loop is gone
            self._loop.call_soon_threadsafe(self._async.put_nowait, item)

    def get(self, timeout: float = 5.0) -> T:
        return self._sync.get(timeout=timeout)

    async def aget(self, within: float = 5.0) -> T:
        return await asyncio.wait_for(self._async.get(), within)

    async def abatch(self, within: float = 5.0) -> list[T]:
        """Everything waiting (at least one item, waited for up to ``within``): a reader
        that keeps up with a fast publisher without one wake-up per item."""
        items = [await self.aget(within)]
        queue_ = self._async
        while not queue_.empty():
            items.append(queue_.get_nowait())
        return items

    def until(self, predicate: Callable[[T], bool], timeout: float = 5.0) -> T:
        deadline = time.monotonic() + timeout
        while True:
            item = self.get(max(0.0, deadline - time.monotonic()))
            if predicate(item):
                return item

    async def auntil(self, predicate: Callable[[T], bool], within: float = 5.0) -> T:
        async def wait() -> T:
            while True:
                item = await self._async.get()
                if predicate(item):
                    return item

        return await asyncio.wait_for(wait(), within)


class Client:
    """One Zenoh session connected to the gateway under test."""

    _id: Any = None  # a declared entity's id: puts and queries carry it (identified)
    _sn = 0

    def __init__(
        self,
        endpoint: str,
        loop: asyncio.AbstractEventLoop | None = None,
        listen: bool = False,
        rcvbuf: int | None = None,
        identified: bool = False,
        *,
        zid: str | None = None,
    ) -> None:
        self.loop = loop
        self.session = zenoh.open(client_config(endpoint, listen, rcvbuf, zid))
        # identified: puts and queries carry a source info with this session's id, so
        # the gateway tells this client from others (safety rule 3); else anonymous
        if identified:
            self._id = self.session.declare_publisher(f"_client/{self.session.zid()}").id

    @property
    def zid(self) -> str:
        return str(self.session.zid())

    @property
    def label(self) -> str:
        """The name the gateway gives this client (control_client, events)."""
        return client_label(self.zid)

    def _source_info(self) -> Any:
        if self._id is None:
            return None
        self._sn += 1
        return zenoh.SourceInfo(self._id, self._sn)

    def close(self) -> None:
        self.session.close()

    @contextmanager
    def subscribe(self, key: str) -> Iterator[Inbox[Got]]:
        inbox: Inbox[Got] = Inbox(self.loop)
        sub = self.session.declare_subscriber(key, lambda s: inbox.push(_copy_sample(s)))
        try:
            yield inbox
        finally:
            sub.undeclare()

    @contextmanager
    def liveliness(self, key: str) -> Iterator[Inbox[Got]]:
        inbox: Inbox[Got] = Inbox(self.loop)
        sub = self.session.liveliness().declare_subscriber(
            key, lambda s: inbox.push(_copy_sample(s)), history=True
        )
        try:
            yield inbox
        finally:
            sub.undeclare()

    def put(self, key: str, payload: Any) -> None:
        data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        self.session.put(
            key,
            data,
            congestion_control=zenoh.CongestionControl.BLOCK,
            source_info=self._source_info(),
        )

    def _get(self, selector: str, payload: Any, on_done: Callable[[list[Replied]], None]) -> None:
        replies: list[Replied] = []
        data = None
        if payload is not None:
            data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        # indirect=False: run on Zenoh's thread. The default starts a Python thread per
        # get, which under the soak's query rate cost CPU and left native memory behind.
        handler: zenoh.handlers.Callback[zenoh.Reply] = zenoh.handlers.Callback(
            lambda r: replies.append(_copy_reply(r)), lambda: on_done(replies), indirect=False
        )
        self.session.get(
            selector, handler, payload=data, timeout=10.0, source_info=self._source_info()
        )

    def query(self, selector: str, payload: Any = None, timeout: float = 5.0) -> list[Replied]:
        done = threading.Event()
        result: list[list[Replied]] = []

        def on_done(replies: list[Replied]) -> None:
            result.append(replies)
            done.set()

        self._get(selector, payload, on_done)
        if not done.wait(timeout):
            raise TimeoutError(f"no end of replies to {selector} in {timeout} s")
        return result[0]

    async def aquery(
        self, selector: str, payload: Any = None, within: float = 5.0
    ) -> list[Replied]:
        loop = self.loop
        assert loop is not None
        future: asyncio.Future[list[Replied]] = loop.create_future()

        def resolve(replies: list[Replied]) -> None:
            if not future.done():
                future.set_result(replies)

        def on_done(replies: list[Replied]) -> None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(resolve, replies)

        self._get(selector, payload, on_done)
        return await asyncio.wait_for(future, within)

    async def settled(self, prefix: str) -> None:
        """A round trip to the gateway: declarations made before it have reached the gateway
        (they travel on the same link, in order), so its publications now reach them."""
        await self.aquery(f"{prefix}/gateway/health")

    def one(self, selector: str, payload: Any = None) -> Replied:
        replies = self.query(selector, payload)
        assert len(replies) == 1, replies
        return replies[0]

    async def aone(self, selector: str, payload: Any = None) -> Replied:
        replies = await self.aquery(selector, payload)
        assert len(replies) == 1, replies
        return replies[0]
