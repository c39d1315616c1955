"""The simulated node on a stepped clock, without a bus: the frames it sends are recorded
by a network stand-in and time moves only when the test says so (heartbeat period, TPDO
event timer and SYNC, the heartbeat consumer and RPDO deadlines, NMT states)."""

from __future__ import annotations

import struct

import canopen
import pytest

from adapters.canopen.codec.cia402 import State, decode_state
from adapters.canopen.sim import SimNode, SimNodeConfig

NODE = 5


class Recorder(canopen.Network):
    def __init__(self) -> None:
        super().__init__()
        self.sent: list[tuple[float, int, bytes]] = []
        self.now = 0.0

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        self.sent.append((self.now, can_id, bytes(data)))

    def frames(self, can_id: int) -> list[tuple[float, bytes]]:
        return [(t, d) for t, cid, d in self.sent if cid == can_id]


class Rig:
    def __init__(self, **kw: object) -> None:
        self.net = Recorder()
        self.node = SimNode(SimNodeConfig(NODE, **kw), self.net, clock=lambda: self.net.now)  # type: ignore[arg-type]
        self.node.power_on()

    def at(self, t: float) -> None:
        """Step every 1 ms up to ``t``."""
        while self.net.now < t - 1e-9:
            self.net.now = round(min(t, self.net.now + 0.001), 6)
            self.node.step(self.net.now)

    def state(self) -> State:
        return self.node.drive.state

    def frame(self, can_id: int, data: bytes) -> None:
        self.node.on_frame(can_id, data)

    def sdo_write(self, index: int, sub: int, data: bytes) -> bytes:
        n = len(data)
        request = (
            bytes([0x23 | (4 - n) << 2]) + struct.pack("<HB", index, sub) + data.ljust(4, b"\0")
        )
        self.frame(0x600 + NODE, request)
        return self.net.frames(0x580 + NODE)[-1][1]


def test_boot_up_then_heartbeat_every_period() -> None:
    r = Rig(heartbeat_ms=100)
    assert r.net.frames(0x705) == [(0.0, b"\x00")]
    r.at(0.35)
    assert r.net.frames(0x705)[1:] == [(0.1, b"\x7f"), (0.2, b"\x7f"), (0.3, b"\x7f")]


def test_heartbeat_reports_the_nmt_state_and_stopped_answers_no_sdo() -> None:
    r = Rig(heartbeat_ms=100)
    r.frame(0x000, bytes([0x01, NODE]))
    r.at(0.1)
    assert r.net.frames(0x705)[-1] == (0.1, b"\x05")
    r.frame(0x000, bytes([0x02, 0]))  # stop all
    r.at(0.2)
    assert r.net.frames(0x705)[-1] == (0.2, b"\x04")
    before = len(r.net.sent)
    r.frame(0x600 + NODE, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]))
    assert len(r.net.sent) == before


def test_event_tpdo_on_change_and_on_the_event_timer() -> None:
    r = Rig()
    r.frame(0x000, bytes([0x01, NODE]))
    r.at(0.001)
    assert len(r.net.frames(0x185)) == 1  # the first one at once
    r.at(0.099)
    assert len(r.net.frames(0x185)) == 1  # nothing changed
    r.at(0.101)
    assert [t for t, _ in r.net.frames(0x185)] == [0.001, 0.101]  # 0x1800:5 = 100 ms
    r.frame(0x205, struct.pack("<Hh", 0x06, 0))  # a change: the statusword
    r.at(0.102)
    status, _ = struct.unpack("<Hh", r.net.frames(0x185)[-1][1])
    assert decode_state(status) is State.READY_TO_SWITCH_ON


def test_sync_tpdo_and_synchronous_rpdo() -> None:
    r = Rig()
    assert r.sdo_write(0x1400, 2, b"\x01")[0] == 0x60  # RPDO1 acts on SYNC
    r.frame(0x000, bytes([0x01, NODE]))
    r.frame(0x205, struct.pack("<Hh", 0x06, 0))
    assert r.state() is State.SWITCH_ON_DISABLED  # not before the SYNC
    sent = len(r.net.frames(0x285))
    r.frame(0x080, b"")
    assert r.state() is State.READY_TO_SWITCH_ON
    assert len(r.net.frames(0x285)) == sent + 1  # TPDO2, transmission type 1


def test_heartbeat_consumer_arms_on_the_first_beat_and_fires_once() -> None:
    r = Rig()
    assert r.sdo_write(0x6007, 0, b"\x01\x00")[0] == 0x60
    assert r.sdo_write(0x1016, 1, struct.pack("<I", 0x7F << 16 | 100))[0] == 0x60
    r.at(1.0)
    assert r.state() is State.SWITCH_ON_DISABLED  # never heard: not armed
    r.frame(0x77F, b"\x05")
    r.at(1.1)
    assert r.net.frames(0x85) == []  # 100 ms: not yet
    r.at(1.102)
    assert r.state() is State.FAULT
    assert r.net.frames(0x85) == [(1.101, bytes([0x30, 0x81, 0x11, 0, 0, 0, 0, 0]))]
    r.at(2.0)
    assert len(r.net.frames(0x85)) == 1


def test_rpdo_deadline_monitoring() -> None:
    r = Rig()
    assert r.sdo_write(0x1400, 5, b"\x32\x00")[0] == 0x60  # 50 ms
    r.frame(0x000, bytes([0x01, NODE]))
    r.frame(0x205, struct.pack("<Hh", 0x06, 0))
    r.at(0.05)
    assert r.state() is State.READY_TO_SWITCH_ON
    r.at(0.052)
    assert r.state() is State.FAULT
    assert r.node.drive.error_code == 0x8250


@pytest.mark.parametrize(("sub", "value"), [(0, 9), (0, 3)])
def test_mapping_count_refused(sub: int, value: int) -> None:
    r = Rig()
    r.sdo_write(0x1A01, 0, b"\x00")
    for s in (1, 2, 3):
        r.sdo_write(0x1A01, s, struct.pack("<I", 0x606C0020))
    answer = r.sdo_write(0x1A01, sub, bytes([value]))
    assert answer[0] == 0x80
    code = struct.unpack_from("<I", answer, 4)[0]
    assert code == (0x06090031 if value == 9 else 0x06040042)


def test_silence_stops_everything_but_the_clock() -> None:
    r = Rig(heartbeat_ms=100)
    r.node.silence()
    before = len(r.net.sent)
    r.at(0.5)
    r.frame(0x600 + NODE, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]))
    assert len(r.net.sent) == before
    r.node.silence(False)
    r.at(0.6)
    assert r.net.frames(0x705)[-1] == (0.6, b"\x7f")
