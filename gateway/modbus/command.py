"""The command word and how register writes become hub commands (sans-IO).

A PLC rewrites its command word cyclically with the same value. Safety rule 1
(no unintended restart) therefore needs edges, per client and per unit:

- ``run`` and ``jog`` are sent only when the bit differs from the last word the
  same client wrote for that unit (jog too: the hub clears it together with run,
  so a jog bit held at 1 must not restart the motor either);
- ``fault reset`` is sent on its 0 -> 1 edge only (rule 2);
- ``reverse``, ``quick stop`` and ``coast stop`` are levels, and so are the
  speed references: they are sent when they differ from the hub's desired
  command, so rewriting an unchanged word neither changes anything nor takes
  control from another source in ``control = "any"``.

A client the gateway has not heard from (since it started, or since it was
evicted from the bounded memory) is taken to have last written run, jog and
fault reset at 1: its first word can stop the drive but never start it or reset
a fault. After a gateway restart, a PLC still writing run=1 must write 0 and
then 1 (rule 1: "after the gateway starts, a drive runs only on a new run
command").
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any

from gateway.modbus.regs import ExceptionCode, WriteRefused
from gateway.model import DesiredCommand, Direction, DriveCommand


@dataclass(frozen=True, slots=True)
class CommandBit:
    bit: int
    name: str
    kind: str  # "edge" or "level"
    doc: str

    @property
    def mask(self) -> int:
        return 1 << self.bit


COMMAND_BITS: tuple[CommandBit, ...] = (
    CommandBit(0, "run", "edge", "1 = run, 0 = ramp stop; sent to the hub only when it changes"),
    CommandBit(1, "reverse", "level", "1 = reverse, 0 = forward"),
    CommandBit(2, "fault_reset", "edge", "a 0 -> 1 change resets a fault (once); reads back 0"),
    CommandBit(3, "quick_stop", "level", "1 = quick stop (fast ramp to zero)"),
    CommandBit(4, "coast_stop", "level", "1 = coast stop (output off)"),
    CommandBit(5, "jog", "edge", "1 = jog; like run, sent only when it changes"),
)
DEFINED_MASK = sum(b.mask for b in COMMAND_BITS)
"""Bits 6-15 are reserved: a word with any of them set is refused (exception 3)."""


@dataclass(frozen=True, slots=True)
class CommandWord:
    """Holding register 0, decoded."""

    run: bool = False
    reverse: bool = False
    fault_reset: bool = False
    quick_stop: bool = False
    coast_stop: bool = False
    jog: bool = False

    @classmethod
    def from_register(cls, raw: int) -> CommandWord:
        if not 0 <= raw <= 0xFFFF:
            raise WriteRefused(
                ExceptionCode.ILLEGAL_DATA_VALUE,
                f"command word: {raw} is not a register value (limit 0-65535)",
            )
        if raw & ~DEFINED_MASK:
            raise WriteRefused(
                ExceptionCode.ILLEGAL_DATA_VALUE,
                f"command word 0x{raw:04X} sets reserved bits (0x{raw & ~DEFINED_MASK:04X})",
            )
        return cls(**{b.name: bool(raw & b.mask) for b in COMMAND_BITS})

    def to_register(self) -> int:
        return sum(b.mask for b in COMMAND_BITS if getattr(self, b.name))

    @classmethod
    def from_desired(cls, desired: DesiredCommand) -> CommandWord:
        """What holding register 0 reads back: the hub's desired command (reset is an edge: 0)."""
        return cls(
            run=desired.run,
            reverse=desired.direction is Direction.REVERSE,
            quick_stop=desired.quick_stop,
            coast_stop=desired.coast_stop,
            jog=desired.jog,
        )


UNKNOWN_CLIENT_WORD = CommandWord(run=True, fault_reset=True, jog=True)
"""The last word assumed for a client not heard from: no start and no reset on its first word."""


@dataclass(frozen=True, slots=True)
class HoldingWrite:
    """A validated write to the command holding registers of one drive.

    ``speed_rpm`` / ``speed_pct`` None: not written, or written as the null
    (0x8000, "not given"). ``command`` is True when registers 0-2 were written
    (the write is a command: arbitration and online checks apply).
    """

    word: CommandWord | None = None
    speed_rpm: float | None = None
    speed_pct: float | None = None
    keepalive: int | None = None
    command: bool = False


def build_command(last: CommandWord, write: HoldingWrite, desired: DesiredCommand) -> DriveCommand:
    """The partial hub command for ``write``, given the client's ``last`` word."""
    fields: dict[str, Any] = {}
    word = write.word
    if word is not None:
        if word.run != last.run:
            fields["run"] = word.run
        if word.jog != last.jog:
            fields["jog"] = word.jog
        if word.fault_reset and not last.fault_reset:
            fields["fault_reset"] = True
        direction = Direction.REVERSE if word.reverse else Direction.FORWARD
        if direction is not desired.direction:
            fields["direction"] = direction
        if word.quick_stop != desired.quick_stop:
            fields["quick_stop"] = word.quick_stop
        if word.coast_stop != desired.coast_stop:
            fields["coast_stop"] = word.coast_stop
    if write.speed_rpm is not None and write.speed_rpm != desired.speed_rpm:
        fields["speed_rpm"] = write.speed_rpm
    if write.speed_pct is not None and write.speed_pct != desired.speed_pct:
        fields["speed_pct"] = write.speed_pct
    return DriveCommand(**fields)


class ClientMemory:
    """The last command word each client wrote for each unit.

    A client is its peer address (not the TCP connection): a PLC that reconnects
    is the same client, so reconnecting does not turn a held run bit into an edge.
    The words of a client with a connection open are never evicted: they are
    bounded by ``modbus.max_connections`` (and the unit count) instead, so no
    number of other addresses can make a connected PLC's run edge disappear
    (issue 17). The words of clients with no connection open are kept too, the
    oldest dropped first beyond ``limit``.
    """

    def __init__(self, limit: int = 4096) -> None:
        self._limit = limit
        self._words: dict[tuple[str, int], CommandWord] = {}
        self._units: dict[str, set[int]] = {}
        self._open: collections.Counter[str] = collections.Counter()
        self._idle: collections.OrderedDict[tuple[str, int], None] = collections.OrderedDict()

    def last(self, client: str, unit: int) -> CommandWord:
        return self._words.get((client, unit), UNKNOWN_CLIENT_WORD)

    def remember(self, client: str, unit: int, word: CommandWord) -> None:
        key = (client, unit)
        self._words[key] = word
        self._units.setdefault(client, set()).add(unit)
        if not self._open[client]:
            self._idle[key] = None
            self._idle.move_to_end(key)
            self._evict()

    def connected(self, client: str) -> None:
        """A connection from ``client`` is open: its words are kept while it lasts."""
        self._open[client] += 1
        for unit in self._units.get(client, ()):
            self._idle.pop((client, unit), None)

    def disconnected(self, client: str) -> None:
        """A connection from ``client`` closed; with its last, its words may age out."""
        self._open[client] -= 1
        if self._open[client] > 0:
            return
        del self._open[client]
        for unit in self._units.get(client, ()):
            self._idle[client, unit] = None
        self._evict()

    def peer(self, client: str, opened: bool) -> None:
        """The server's hook: :meth:`connected` or :meth:`disconnected`."""
        (self.connected if opened else self.disconnected)(client)

    def _evict(self) -> None:
        while len(self._idle) > self._limit:
            (client, unit), _ = self._idle.popitem(last=False)
            del self._words[client, unit]
            units = self._units[client]
            units.discard(unit)
            if not units:
                del self._units[client]

    def __len__(self) -> int:
        return len(self._words)
