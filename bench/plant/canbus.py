"""A cross-process CAN bus for the plant benchmark: a python-can bus over a Unix socket to a
broker process that paces every frame at its CAN bit time.

Why: python-can's ``virtual`` bus works inside one process only, this kernel has no AF_CAN
(no vcan0) and ``udp_multicast`` is not allowed. The benchmark needs the gateway and the
simulated nodes in separate processes, on a line that carries frames no faster than a real
500 kbit/s bus.

- :class:`PlantCanBus` (python-can interface name :data:`INTERFACE`, channel = the broker's
  socket path): one ``SOCK_SEQPACKET`` connection to the broker, one record per frame; it
  has a ``fileno()``, so python-can's Notifier watches it with ``loop.add_reader`` as it
  does a SocketCAN socket. :func:`register` makes python-can find it (``can.Bus`` looks the
  name up in ``can.interfaces.BACKENDS``); :mod:`bench.plant.launch` calls it before it runs
  ``drive-gateway``.
- :func:`serve` (``python -m bench.plant.canbus``): the broker. Frames queue per sender in
  order (a controller's transmit FIFO); when the bus is free the lowest identifier among the
  queue heads wins (CAN arbitration) and occupies the bus for :func:`frame_bits` bit times;
  at its end the frame is delivered to every other connection. The broker waits with
  ``select`` and a 1 us timer slack (``PR_SET_TIMERSLACK``); a frame that waited starts
  at the end of the one before on the bus's own timeline (the broker's wake-up lateness
  delays a delivery, never the frames after it); the lateness of each delivery is recorded.

Bit time of a frame (ISO 11898-1, base format data frame): SOF 1, identifier 11, RTR, IDE
and r0 3, DLC 4, data 8 x n, CRC 15 -- that stretch is bit-stuffed (one stuff bit after
five equal bits; counted exactly from the frame's bits and its CRC-15) -- then CRC
delimiter 1, ACK slot and delimiter 2, EOF 7, and the 3-bit intermission before the next
frame: 47 + 8 n + stuff bits (111 to 135 for 8 data bytes).
"""

from __future__ import annotations

import argparse
import array
import contextlib
import ctypes
import functools
import json
import os
import select
import signal
import socket
import statistics
import struct
import time
from collections import deque
from typing import Any, Final

import can

from bench.plant import pin_from_env

INTERFACE: Final = "plantcan"
RECORD: Final = struct.Struct("<IBB8s")  # identifier, flags, DLC, data
EXTENDED: Final = 0x01
REMOTE: Final = 0x02
PR_SET_TIMERSLACK: Final = 29  # linux/prctl.h
CRC15_POLY: Final = 0x4599  # ISO 11898-1: x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1
TAIL_BITS: Final = 1 + 2 + 7 + 3  # CRC delimiter, ACK slot + delimiter, EOF, intermission


@functools.lru_cache(maxsize=8192)
def frame_bits(arbitration_id: int, data: bytes) -> int:
    """Bit times a base-format data frame occupies the bus, stuff bits counted exactly."""
    bits = [0]  # SOF
    bits += [(arbitration_id >> (10 - i)) & 1 for i in range(11)]
    bits += [0, 0, 0]  # RTR (data frame), IDE (base format), r0
    bits += [(len(data) >> (3 - i)) & 1 for i in range(4)]
    for byte in data:
        bits += [(byte >> (7 - i)) & 1 for i in range(8)]
    crc = 0
    for bit in bits:
        feedback = bit ^ (crc >> 14) & 1
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= CRC15_POLY
    bits += [(crc >> (14 - i)) & 1 for i in range(15)]
    stuff, run, last = 0, 0, -1
    for bit in bits:
        if bit == last:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:  # a stuff bit of the other value follows, and starts the next run
            stuff += 1
            run, last = 1, 1 - bit
    return len(bits) + stuff + TAIL_BITS


def _encode(msg: can.Message) -> bytes:
    flags = (EXTENDED if msg.is_extended_id else 0) | (REMOTE if msg.is_remote_frame else 0)
    return RECORD.pack(msg.arbitration_id, flags, msg.dlc, bytes(msg.data))


class PlantCanBus(can.BusABC):
    """The bench's python-can bus: a connection to the :func:`serve` broker at ``channel``."""

    def __init__(self, channel: Any, can_filters: Any = None, **kwargs: object) -> None:
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._sock.connect(str(channel))
        except OSError as exc:
            self._sock.close()
            raise can.CanInitializationError(f"no plant CAN broker at {channel}: {exc}") from exc
        self._sock.setblocking(False)
        self.channel_info = f"plant CAN broker {channel}"
        self._channel = str(channel)
        super().__init__(channel, can_filters=can_filters, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        try:
            self._sock.send(_encode(msg))
        except BlockingIOError:
            raise can.CanOperationError("plant CAN: transmit buffer full") from None
        except OSError as exc:
            raise can.CanOperationError(f"plant CAN: {exc}") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            record = self._sock.recv(RECORD.size)
        except BlockingIOError:
            if timeout == 0:
                return None, False
            ready, _, _ = select.select([self._sock], [], [], timeout)
            if not ready:
                return None, False
            try:
                record = self._sock.recv(RECORD.size)
            except BlockingIOError:
                return None, False
        except OSError as exc:
            raise can.CanOperationError(f"plant CAN: {exc}") from exc
        if not record:
            raise can.CanOperationError("plant CAN: the broker closed the bus")
        ident, flags, dlc, data = RECORD.unpack(record)
        msg = can.Message(
            timestamp=time.time(),
            arbitration_id=ident,
            is_extended_id=bool(flags & EXTENDED),
            is_remote_frame=bool(flags & REMOTE),
            dlc=dlc,
            data=data[:dlc],
            channel=self._channel,
        )
        return msg, False

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()


def register() -> None:
    """Make ``can.Bus(interface=INTERFACE, channel=<socket path>)`` find :class:`PlantCanBus`."""
    import can.interfaces
    import can.util

    can.interfaces.BACKENDS[INTERFACE] = (__name__, "PlantCanBus")
    can.util.VALID_INTERFACES = frozenset({*can.util.VALID_INTERFACES, INTERFACE})  # type: ignore[attr-defined]


def fine_timer_slack() -> None:
    """Sleeps and select timeouts of this process wake within ~1 us (Linux prctl)."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, 1000, 0, 0, 0)


# ---------------------------------------------------------------------- the broker


class Broker:
    """The bus: arbitration, pacing, delivery (see the module docstring)."""

    def __init__(self, path: str, bitrate: int) -> None:
        self.t_bit = 1.0 / bitrate
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.listener.bind(path)
        self.listener.listen(16)
        self.listener.setblocking(False)
        self.clients: list[socket.socket] = []
        # per sender: (identifier, record, bit times, arrival time)
        self.queues: dict[socket.socket, deque[tuple[int, bytes, int, float]]] = {}
        self.current: tuple[socket.socket, bytes, float, int] | None = None
        self.busy_until = 0.0
        self.ends = array.array("d")  # end time of each frame carried
        self.bits = array.array("H")  # its bit times
        self.lateness: deque[float] = deque(maxlen=200_000)
        self.dropped = 0  # deliveries refused by a full receiver
        self.stop = False

    def run(self) -> None:
        while not self.stop:
            now = time.monotonic()
            if self.current is not None and now >= self.current[2]:
                self._deliver(now)
            if self.current is None:
                self._arbitrate()
            timeout = None if self.current is None else max(0.0, self.current[2] - now)
            try:
                ready, _, _ = select.select([self.listener, *self.clients], [], [], timeout)
            except InterruptedError:
                continue
            for sock in ready:
                if sock is self.listener:
                    self._accept()
                else:
                    self._read(sock)

    def _accept(self) -> None:
        with contextlib.suppress(BlockingIOError):
            conn, _ = self.listener.accept()
            conn.setblocking(False)
            with contextlib.suppress(OSError):
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self.clients.append(conn)
            self.queues[conn] = deque()

    def _read(self, sock: socket.socket) -> None:
        while True:
            try:
                record = sock.recv(RECORD.size)
            except BlockingIOError:
                return
            except OSError:
                record = b""
            if not record:
                self._drop(sock)
                return
            ident, _, dlc, data = RECORD.unpack(record)
            bits = frame_bits(ident, data[:dlc])
            self.queues[sock].append((ident, record, bits, time.monotonic()))

    def _drop(self, sock: socket.socket) -> None:
        if sock in self.queues:
            del self.queues[sock]
            self.clients.remove(sock)
        if self.current is not None and self.current[0] is sock:
            self.current = None
        sock.close()

    def _arbitrate(self) -> None:
        heads = [(q[0][0], sock) for sock, q in self.queues.items() if q]
        if not heads:
            return
        _, sender = min(heads, key=lambda h: h[0])
        _, record, bits, arrived = self.queues[sender].popleft()
        # a frame waiting while the bus was busy starts at the end of the one before (back
        # to back, 3-bit intermission included), however late this loop noticed that end
        start = max(arrived, self.busy_until)
        end = start + bits * self.t_bit
        self.busy_until = end
        self.current = (sender, record, end, bits)

    def _deliver(self, now: float) -> None:
        if self.current is None:
            return
        sender, record, end, bits = self.current
        self.current = None
        for sock in list(self.clients):
            if sock is sender:
                continue
            try:
                sock.send(record)
            except BlockingIOError:
                self.dropped += 1
            except OSError:
                self._drop(sock)
        self.ends.append(end)
        self.bits.append(bits)
        self.lateness.append(time.monotonic() - end)

    def summary(self) -> dict[str, Any]:
        late = sorted(self.lateness)

        def pct(p: float) -> float:
            return late[min(len(late) - 1, int(p * len(late)))] if late else 0.0

        return {
            "frames": len(self.ends),
            "dropped": self.dropped,
            "lateness_us": {
                "p50": round(pct(0.5) * 1e6, 1),
                "p99": round(pct(0.99) * 1e6, 1),
                "max": round(late[-1] * 1e6, 1) if late else 0.0,
                "mean": round(statistics.fmean(late) * 1e6, 1) if late else 0.0,
            },
        }


def bits_between(ends: array.array[float], bits: array.array[int], t0: float, t1: float) -> int:
    """Bit times of the frames that ended within [t0, t1)."""
    return sum(b for e, b in zip(ends, bits, strict=True) if t0 <= e < t1)


def serve(path: str, bitrate: int, out: str) -> None:
    """Run the broker until SIGTERM; then write the frame log (``out``.ends/.bits, .json)."""
    fine_timer_slack()
    broker = Broker(path, bitrate)

    def stop(*_: object) -> None:
        broker.stop = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        broker.run()
    finally:
        with open(out + ".ends", "wb") as ends:
            broker.ends.tofile(ends)
        with open(out + ".bits", "wb") as bits:
            broker.bits.tofile(bits)
        with open(out + ".json", "w") as summary:
            json.dump(broker.summary(), summary)
        with contextlib.suppress(OSError):
            os.unlink(path)


def load_log(out: str) -> tuple[array.array[float], array.array[int]]:
    ends, bits = array.array("d"), array.array("H")
    with open(out + ".ends", "rb") as f:
        ends.frombytes(f.read())
    with open(out + ".bits", "rb") as f:
        bits.frombytes(f.read())
    return ends, bits


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.canbus")
    parser.add_argument("--path", required=True, help="Unix socket path of the bus")
    parser.add_argument("--bitrate", type=int, default=500_000)
    parser.add_argument("--out", required=True, help="prefix of the frame log files")
    args = parser.parse_args()
    pin_from_env()
    serve(args.path, args.bitrate, args.out)


if __name__ == "__main__":
    main()
