"""Scripted exchanges with the master engine: what it sends, what it gets back (fake clock).

``Script.sent()`` steps until the engine transmits and returns the telegram (checking the
bytes when given), confirming the write as the driver does (``Written``, ``write_lag`` late); ``Script.answer()`` feeds a reply; ``Script.silence()`` lets the wait
run out. The engine's other actions collect in ``Script.actions``.
"""

from __future__ import annotations

from typing import Any

from adapters.profibus.codec.fdl import DataTelegram, ShortAck, decode_telegram
from adapters.profibus.master import Action, FrameIn, Master, Transmit, Written

h = bytes.fromhex


class Script:
    def __init__(self, master: Master, now: float = 0.0) -> None:
        self.master = master
        self.now = now
        self.actions: list[Action] = []
        self.transmits: list[Transmit] = []
        self._waiting: list[Transmit] = []
        self.write_lag = 0.0  # how late the driver writes (a loop callback run late)
        self.written: list[float] = []  # when each telegram was written (Written.at)

    def _collect(self, actions: list[Action]) -> None:
        for a in actions:
            if isinstance(a, Transmit):
                self._waiting.append(a)
                self.transmits.append(a)
            else:
                self.actions.append(a)

    def step(self, event: Any = None) -> None:
        self._collect(self.master.step(self.now, event))

    def sent(self, wire: str | None = None, limit: float = 5.0) -> DataTelegram:
        """The next telegram the master sends (time moves on to it)."""
        end = self.now + limit
        while not self._waiting:
            self.step()
            if self._waiting:
                break
            deadline = self.master.next_deadline()
            if deadline is None or deadline > end:
                raise AssertionError("the master sent nothing")
            self.now = max(self.now, deadline)
        t = self._waiting.pop(0)
        at = max(self.now, t.not_before) + self.write_lag
        self.written.append(at)
        self._collect(self.master.step(at, Written(at)))  # the driver confirms the write
        self.now = at + self.master.bus.tx_time(len(t.data))
        if wire is not None:
            assert t.data == h(wire), f"sent {t.data.hex(' ')}, expected {wire}"
        telegram = decode_telegram(t.data)
        assert isinstance(telegram, DataTelegram)
        return telegram

    def answer(self, reply: DataTelegram | ShortAck | str, after: float = 100e-6) -> None:
        if isinstance(reply, str):
            decoded = decode_telegram(h(reply))
            assert isinstance(decoded, DataTelegram | ShortAck)
            reply = decoded
        self.now += after
        self.step(FrameIn(reply))

    def silence(self) -> None:
        """No reply: time runs to the engine's deadline."""
        deadline = self.master.next_deadline()
        assert deadline is not None
        self.now = max(self.now, deadline)
        self.step()

    def of(self, kind: type) -> list[Any]:
        return [a for a in self.actions if isinstance(a, kind)]
