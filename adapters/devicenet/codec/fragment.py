"""The DeviceNet fragmentation protocol, sans-IO: explicit (acknowledged) and I/O (not).

Fact sheet 2.8:
- explicit: header b7 = 1; byte 1 = fragment type (b7-6: 0 first, 1 middle,
  2 last, 3 ack) + count (b5-0); up to 6 payload bytes. The count starts at 0 and
  increases modulo 64 (◐). The receiver acknowledges every fragment with
  ``[hdr, 0xC0|count, status]`` (0 = OK); the sender waits for each ack ([BRB]
  waits 1 s). A duplicate fragment is acknowledged again. The reassembled message
  is the header with the frag bit cleared, then all payloads.
- I/O (◐): byte 0 is the fragment byte, up to 7 data bytes follow, no acks.

Both reassemblers yield either the exact message sent or a typed error: a
fragment that is not the next one expected discards the partial message
(:class:`FragmentOutOfSequence`), a first fragment always restarts, an identical
repeat of the last accepted fragment is acknowledged again and ignored, and
:meth:`ExplicitReassembler.tick` discards a partial message older than the
timeout (:class:`ReassemblyTimeout`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import IntEnum

from adapters.devicenet.codec.validate import check_bytes
from adapters.devicenet.errors import (
    FragmentAckError,
    FragmentAckTimeout,
    FragmentDecodeError,
    FragmentOutOfSequence,
    ReassembledTooLong,
    ReassemblyTimeout,
)
from gateway.errors import FrameEncodeError, require_int

log = logging.getLogger(__name__)

FRAG_BIT = 0x80  # explicit header byte b7 (fact sheet 2.4, 2.8)
HEADER_MASK = 0x7F  # explicit header byte b6-0: XID and MAC
COUNT_MODULO = 64  # 6-bit fragment count (fact sheet 2.8)
COUNT_MASK = 0x3F
TYPE_SHIFT = 6
EXPLICIT_FRAGMENT_PAYLOAD = 6  # fact sheet 2.8
IO_FRAGMENT_PAYLOAD = 7  # fact sheet 2.8 (◐)
UNFRAGMENTED_MAX = 8  # one CAN frame (fact sheet 2.4, 2.13)
ACK_SUCCESS = 0  # ack status 0 = OK (fact sheet 2.8)
DEFAULT_ACK_TIMEOUT = 1.0  # s, [BRB] (fact sheet 2.8)
DEFAULT_REASSEMBLY_TIMEOUT = 1.0  # s, decision: the sender's ack wait
DEFAULT_MAX_MESSAGE = 1024  # bytes, decision: bound on a reassembled message


class FragmentType(IntEnum):
    """Fragment byte b7-6 (fact sheet 2.8)."""

    FIRST = 0
    MIDDLE = 1
    LAST = 2
    ACK = 3


def _fragment_byte(kind: FragmentType, count: int) -> int:
    return (int(kind) << TYPE_SHIFT) | count


# ---------------------------------------------------------------- frames


@dataclass(frozen=True, slots=True)
class ExplicitFragment:
    """One explicit fragment: ``[header|0x80, type<<6|count, payload (0-6)]``.

    ``header`` is byte 0 without the frag bit (XID and MAC, opaque here).
    """

    header: int
    kind: FragmentType
    count: int
    payload: bytes = b""

    def __post_init__(self) -> None:
        require_int("header", self.header, 0, HEADER_MASK)
        require_int("fragment type", self.kind, FragmentType.FIRST, FragmentType.LAST)
        require_int("fragment count", self.count, 0, COUNT_MASK)
        payload = check_bytes("fragment payload", self.payload, EXPLICIT_FRAGMENT_PAYLOAD)
        object.__setattr__(self, "kind", FragmentType(self.kind))
        object.__setattr__(self, "payload", payload)

    def encode(self) -> bytes:
        return bytes((FRAG_BIT | self.header, _fragment_byte(self.kind, self.count))) + self.payload

    def ack(self, status: int = ACK_SUCCESS) -> FragmentAck:
        """The acknowledge the receiver sends for this fragment."""
        return FragmentAck(self.header, self.count, status)


@dataclass(frozen=True, slots=True)
class FragmentAck:
    """An acknowledge: ``[header|0x80, 0xC0|count, status]`` (fact sheet 2.8)."""

    header: int
    count: int
    status: int = ACK_SUCCESS

    def __post_init__(self) -> None:
        require_int("header", self.header, 0, HEADER_MASK)
        require_int("fragment count", self.count, 0, COUNT_MASK)
        require_int("ack status", self.status, 0, 0xFF)

    def encode(self) -> bytes:
        return bytes(
            (FRAG_BIT | self.header, _fragment_byte(FragmentType.ACK, self.count), self.status)
        )


@dataclass(frozen=True, slots=True)
class Unfragmented:
    """An explicit frame with the frag bit clear: the whole message."""

    message: bytes


ExplicitFrame = Unfragmented | ExplicitFragment | FragmentAck

ACK_LENGTH = 3  # fact sheet 2.8


def decode_explicit_frame(data: bytes) -> ExplicitFrame:
    """Sort a frame of an explicit connection: whole message, fragment, or ack."""
    raw = bytes(data)
    if not raw:
        raise FragmentDecodeError("empty explicit frame", raw)
    if not raw[0] & FRAG_BIT:
        return Unfragmented(raw)
    if len(raw) < 2:
        raise FragmentDecodeError("fragment without a fragment byte", raw)
    header, kind, count = (
        raw[0] & HEADER_MASK,
        FragmentType(raw[1] >> TYPE_SHIFT),
        raw[1] & COUNT_MASK,
    )
    if kind is FragmentType.ACK:
        if len(raw) != ACK_LENGTH:
            raise FragmentDecodeError(f"ack of {len(raw)} bytes ({ACK_LENGTH} expected)", raw)
        return FragmentAck(header, count, raw[2])
    return ExplicitFragment(header, kind, count, raw[2:])


@dataclass(frozen=True, slots=True)
class IoFragment:
    """One I/O fragment: ``[type<<6|count, data (0-7)]`` (fact sheet 2.8, ◐)."""

    kind: FragmentType
    count: int
    payload: bytes = b""

    def __post_init__(self) -> None:
        require_int("fragment type", self.kind, FragmentType.FIRST, FragmentType.LAST)
        require_int("fragment count", self.count, 0, COUNT_MASK)
        payload = check_bytes("fragment payload", self.payload, IO_FRAGMENT_PAYLOAD)
        object.__setattr__(self, "kind", FragmentType(self.kind))
        object.__setattr__(self, "payload", payload)

    def encode(self) -> bytes:
        return bytes((_fragment_byte(self.kind, self.count),)) + self.payload

    @classmethod
    def decode(cls, data: bytes) -> IoFragment:
        raw = bytes(data)
        if not raw:
            raise FragmentDecodeError("empty I/O fragment", raw)
        kind = FragmentType(raw[0] >> TYPE_SHIFT)
        if kind is FragmentType.ACK:
            raise FragmentDecodeError("I/O fragments are never acknowledged", raw)
        return cls(kind, raw[0] & COUNT_MASK, raw[1:])


# ---------------------------------------------------------------- fragmenters


def _split(body: bytes, size: int) -> list[tuple[FragmentType, int, bytes]]:
    chunks = [body[i : i + size] for i in range(0, len(body), size)]
    last = len(chunks) - 1
    return [
        (
            FragmentType.FIRST
            if i == 0
            else FragmentType.LAST
            if i == last
            else FragmentType.MIDDLE,
            i % COUNT_MODULO,
            chunk,
        )
        for i, chunk in enumerate(chunks)
    ]


def fragment_explicit(message: bytes) -> list[ExplicitFragment]:
    """The fragments of an explicit message longer than 8 bytes (fact sheet 2.8).

    ``message`` is the encoded message (header with the frag bit clear, body).
    """
    raw = check_bytes("explicit message", message)
    if len(raw) <= UNFRAGMENTED_MAX:
        raise FrameEncodeError(f"a message of {len(raw)} bytes fits one frame: send it whole")
    if raw[0] & FRAG_BIT:
        raise FrameEncodeError("explicit message header has the frag bit set")
    return [
        ExplicitFragment(raw[0], kind, count, chunk)
        for kind, count, chunk in _split(raw[1:], EXPLICIT_FRAGMENT_PAYLOAD)
    ]


def explicit_payloads(message: bytes) -> list[bytes]:
    """The CAN data of each frame that carries ``message``: itself if it fits, else fragments."""
    raw = check_bytes("explicit message", message)
    if not raw:
        raise FrameEncodeError("empty explicit message")
    if len(raw) <= UNFRAGMENTED_MAX:
        return [raw]
    return [fragment.encode() for fragment in fragment_explicit(raw)]


def fragment_io(data: bytes) -> list[bytes]:
    """The CAN data of each frame that carries I/O ``data`` (fact sheet 2.8, ◐).

    Data of at most 8 bytes goes unfragmented, as one frame (decision: same rule as
    explicit messages); longer data goes as first/middle/last fragments of 7 bytes.
    """
    raw = check_bytes("I/O data", data)
    if len(raw) <= UNFRAGMENTED_MAX:
        return [raw]
    return [
        IoFragment(kind, count, chunk).encode()
        for kind, count, chunk in _split(raw, IO_FRAGMENT_PAYLOAD)
    ]


# ---------------------------------------------------------------- reassembly


@dataclass(frozen=True, slots=True)
class ReassemblyStep:
    """What one fragment gave: the ack to send (explicit only), a complete message or not.

    ``duplicate`` is set when the fragment repeated the last one accepted: it is
    acknowledged again and otherwise ignored. ``restarted`` is set when a first
    fragment discarded a partial message.
    """

    message: bytes | None = None
    ack: FragmentAck | None = None
    duplicate: bool = False
    restarted: bool = False


class _Core:
    """Sequence checking shared by both reassemblers; ``key`` is the explicit header."""

    def __init__(self, timeout: float, max_length: int) -> None:
        if timeout <= 0 or max_length <= 0:
            raise ValueError("timeout and max_length must be positive")
        self.timeout = timeout
        self.max_length = max_length
        self._parts: list[bytes] | None = None
        self._length = 0
        self._key: int | None = None
        self._expected = 0
        self._last_accepted: tuple[int | None, FragmentType, int, bytes] | None = None
        self._last_time = 0.0

    @property
    def in_progress(self) -> bool:
        return self._parts is not None

    @property
    def deadline(self) -> float | None:
        return self._last_time + self.timeout if self._parts is not None else None

    def partial(self) -> bytes:
        return b"".join(self._parts or ())

    def reset(self) -> None:
        self._parts, self._length, self._last_accepted = None, 0, None

    def tick(self, now: float) -> None:
        deadline = self.deadline
        if deadline is not None and now >= deadline:
            partial = self.partial()
            self.reset()
            raise ReassemblyTimeout(
                f"no fragment for {self.timeout:g} s: partial message discarded", partial
            )

    def feed(
        self,
        now: float,
        key: int | None,
        kind: FragmentType,
        count: int,
        payload: bytes,
        *,
        raw: bytes,
    ) -> tuple[bytes | None, bool, bool]:
        """Returns (complete payload, duplicate, restarted) or raises."""
        if self._parts is not None and now >= self._last_time + self.timeout:
            log.debug("partial message timed out before a new fragment; discarded")
            self.reset()
        this = (key, kind, count, payload)
        if this == self._last_accepted:
            return None, True, False
        restarted = kind is FragmentType.FIRST and self._parts is not None
        parts = self._accept(key, kind, count, raw)
        self._length += len(payload)
        if self._length > self.max_length:
            self.reset()
            raise ReassembledTooLong(f"fragmented message over {self.max_length} bytes", raw)
        parts.append(payload)
        self._expected = (count + 1) % COUNT_MODULO
        self._last_accepted = this
        self._last_time = now
        if kind is not FragmentType.LAST:
            return None, False, restarted
        self._parts, self._length = None, 0
        return b"".join(parts), False, restarted

    def _accept(self, key: int | None, kind: FragmentType, count: int, raw: bytes) -> list[bytes]:
        """The parts list this fragment extends, or FragmentOutOfSequence."""
        if kind is FragmentType.FIRST:
            # A first fragment always starts a new message, whatever its count (decision).
            self._parts, self._length, self._key, self._expected = [], 0, key, count
            return self._parts
        parts = self._parts
        if parts is None:
            self.reset()
            raise FragmentOutOfSequence(
                f"{kind.name.lower()} fragment {count} without a first fragment",
                raw,
                received=count,
            )
        if key != self._key or count != self._expected:
            expected = self._expected
            self.reset()
            raise FragmentOutOfSequence(
                f"fragment {count} where {expected} was expected: partial message discarded",
                raw,
                expected=expected,
                received=count,
            )
        return parts


class ExplicitReassembler:
    """Receiver of one explicit connection's fragments (fact sheet 2.8).

    Feed it the :class:`ExplicitFragment` frames :func:`decode_explicit_frame`
    returns; send back every ``step.ack``. Call :meth:`tick` from the engine's timer.
    """

    def __init__(
        self,
        *,
        timeout: float = DEFAULT_REASSEMBLY_TIMEOUT,
        max_length: int = DEFAULT_MAX_MESSAGE,
    ) -> None:
        self._core = _Core(timeout, max_length)

    @property
    def in_progress(self) -> bool:
        return self._core.in_progress

    @property
    def deadline(self) -> float | None:
        """When the partial message times out, or None if none is in progress."""
        return self._core.deadline

    def feed(self, now: float, fragment: ExplicitFragment) -> ReassemblyStep:
        """Take one fragment; raises FragmentOutOfSequence or ReassembledTooLong."""
        body, duplicate, restarted = self._core.feed(
            now,
            fragment.header,
            fragment.kind,
            fragment.count,
            fragment.payload,
            raw=fragment.encode(),
        )
        message = None if body is None else bytes((fragment.header,)) + body
        return ReassemblyStep(message, fragment.ack(), duplicate, restarted)

    def tick(self, now: float) -> None:
        """Raise :class:`ReassemblyTimeout` (once) when the partial message expired."""
        self._core.tick(now)

    def reset(self) -> None:
        """Forget any partial message (connection closed)."""
        self._core.reset()


class IoReassembler:
    """Receiver of a fragmented I/O connection (no acks; fact sheet 2.8, ◐).

    Route a connection's frames here only when its consumed size exceeds 8 bytes:
    every frame is then a fragment.
    """

    def __init__(
        self,
        *,
        timeout: float = DEFAULT_REASSEMBLY_TIMEOUT,
        max_length: int = DEFAULT_MAX_MESSAGE,
    ) -> None:
        self._core = _Core(timeout, max_length)

    @property
    def in_progress(self) -> bool:
        return self._core.in_progress

    @property
    def deadline(self) -> float | None:
        return self._core.deadline

    def feed(self, now: float, data: bytes) -> ReassemblyStep:
        """Take one frame's data; raises a FragmentationError subclass on bad input."""
        fragment = IoFragment.decode(data)
        message, duplicate, restarted = self._core.feed(
            now, None, fragment.kind, fragment.count, fragment.payload, raw=bytes(data)
        )
        return ReassemblyStep(message, None, duplicate, restarted)

    def tick(self, now: float) -> None:
        self._core.tick(now)

    def reset(self) -> None:
        self._core.reset()


# ---------------------------------------------------------------- sender


class ExplicitSender:
    """Sender of one explicit message, fragment by fragment, each waiting for its ack.

    ``start(now)`` gives the first frame's data; a message of at most 8 bytes is
    then done (nothing is acknowledged). Otherwise feed each :class:`FragmentAck`
    to :meth:`on_ack`, which gives the next frame's data; acks for other fragments
    are ignored. :meth:`tick` raises :class:`FragmentAckTimeout` when the ack is
    late. No retransmission (decision): the engine repeats the whole request.
    """

    def __init__(self, message: bytes, *, ack_timeout: float = DEFAULT_ACK_TIMEOUT) -> None:
        raw = check_bytes("explicit message", message)
        self._payloads = explicit_payloads(raw)
        self._fragments = fragment_explicit(raw) if len(raw) > UNFRAGMENTED_MAX else []
        self.ack_timeout = ack_timeout
        self._next = 0
        self._deadline: float | None = None
        self._failed = False

    @property
    def fragmented(self) -> bool:
        return bool(self._fragments)

    @property
    def failed(self) -> bool:
        """Whether the transfer ended on a bad ack status or an ack timeout."""
        return self._failed

    @property
    def done(self) -> bool:
        return self._next >= len(self._payloads) and self._deadline is None

    @property
    def deadline(self) -> float | None:
        """When the awaited ack times out, or None if none is awaited."""
        return self._deadline

    def start(self, now: float) -> bytes:
        if self._next:
            raise FrameEncodeError("sender already started")
        return self._send(now)

    def _send(self, now: float) -> bytes:
        payload = self._payloads[self._next]
        self._next += 1
        self._deadline = now + self.ack_timeout if self._fragments else None
        return payload

    def on_ack(self, now: float, ack: FragmentAck) -> bytes | None:
        """The next frame's data, or None (done, or an ack for another fragment)."""
        if self._deadline is None or not self._fragments:
            return None
        awaited = self._fragments[self._next - 1]
        if (ack.header, ack.count) != (awaited.header, awaited.count):
            return None
        if ack.status != ACK_SUCCESS:
            self._abort()
            raise FragmentAckError(
                f"fragment {ack.count} acknowledged with status {ack.status}",
                ack.encode(),
                status=ack.status,
            )
        if self._next >= len(self._payloads):
            self._deadline = None
            return None
        return self._send(now)

    def tick(self, now: float) -> None:
        if self._deadline is not None and now >= self._deadline:
            count = self._fragments[self._next - 1].count
            self._abort()
            raise FragmentAckTimeout(f"no ack for fragment {count} within {self.ack_timeout:g} s")

    def _abort(self) -> None:
        self._deadline = None
        self._next = len(self._payloads)
        self._failed = True
