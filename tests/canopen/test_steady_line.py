"""A steady CANopen line, stepped with an injected clock: the master engine with the
configuration the adapter makes of a bus (the shipped EDS, velocity mode, SYNC-driven)
against the simulated CiA 402 nodes (:class:`adapters.canopen.sim.node.SimNode`, the
canopen library's object dictionary and PDO maps), every frame delivered in process.

What a SYNC cycle carries once the drives stand still: the SYNC, one TPDO1 of every node
(transmission type 1), an RPDO1 to a node only when its data changes or every
``RPDO_REFRESH`` (CiA 301 §7.2.2: the drive holds the last RPDO), no other PDO (the
EDS's TPDO2 is valid on every SYNC until the bring-up switches it off), the heartbeats.
On the bench's CAN line the extra TPDO2 of every node filled the bus (docs/decisions/0048-canopen-unused-pdos-off.md).
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from typing import Any

import canopen

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.codec import frames as f
from adapters.canopen.master import FrameIn, Master, Send
from adapters.canopen.master.engine import RPDO_REFRESH
from adapters.canopen.sim.node import SimNode, SimNodeConfig
from gateway.config import parse

NODES = 4
SYNC_PERIOD = 0.005  # s: shorter than the line's minimum is refused; 4 nodes take ~1 ms
MAX_STEP = 0.0005  # s: the fake clock never jumps further (the nodes' timers run)


class _Wire(canopen.Network):
    """The nodes' side of an ideal bus: what they send is queued with the fake time."""

    def __init__(self, line: SteadyLine) -> None:
        super().__init__()
        self.line = line

    def send_message(self, can_id: int, data: Any, remote: bool = False) -> None:
        self.line.queue.append(f.CanFrame(can_id, bytes(data)))


class SteadyLine:
    def __init__(self, nodes: int = NODES, bitrate: int = 500_000) -> None:
        drives = [
            {
                "id": f"d{n}",
                "device": "CiA 402",
                "address": n,
                "eds": "eds/cia402-drive.eds",
                "max_rpm": 1800.0,
            }
            for n in range(1, nodes + 1)
        ]
        bus = {
            "adapter": "canopen",
            "interface": "virtual",
            "channel": "steady",
            "bitrate": bitrate,
            "sync_period": SYNC_PERIOD if nodes <= NODES else 0.015,
            "drives": drives,
        }
        config = parse(
            {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}},
            "test",
        )
        adapter = CanOpenAdapter(config.buses[0])
        self.master = Master(adapter.master_config(), adapter.node_configs)
        self.now = 0.0
        self.queue: list[f.CanFrame] = []
        self.log: list[tuple[float, f.CanFrame]] = []  # every frame on the bus
        wire = _Wire(self)
        self.sims = [
            SimNode(SimNodeConfig(node_id=n), wire, clock=lambda: self.now)
            for n in range(1, nodes + 1)
        ]
        for sim in self.sims:
            sim.power_on()

    def _deliver(self, actions: list[Any]) -> None:
        for action in actions:
            if isinstance(action, Send):
                self.queue.append(action.frame)
        while self.queue:
            frame = self.queue.pop(0)
            self.log.append((self.now, frame))
            for sim in self.sims:
                if sim.wants(frame.cob_id):
                    sim.on_frame(frame.cob_id, frame.data)
            for action in self.master.step(self.now, FrameIn(frame)):
                if isinstance(action, Send):
                    self.queue.append(action.frame)

    def run(self, seconds: float) -> None:
        end = self.now + seconds
        while self.now < end:
            times = [end, self.now + MAX_STEP]
            deadline = self.master.next_deadline()
            if deadline is not None:
                times.append(deadline)
            times += [t for t in (s.next_deadline() for s in self.sims) if t is not None]
            self.now = max(self.now, min(times))
            for sim in self.sims:
                sim.step(self.now)
            self._deliver([])
            self._deliver(self.master.step(self.now))

    def online(self) -> bool:
        return all(self.master.online(s.node_id) for s in self.sims)


def test_a_steady_line_carries_the_sync_one_tpdo1_per_node_and_rpdo1_at_the_refresh() -> None:
    line = SteadyLine()
    line.run(3.0)
    assert line.online()
    start = line.now
    line.run(1.0)
    window = [(t, fr) for t, fr in line.log if t > start]
    syncs = [t for t, fr in window if fr.cob_id == f.COB_SYNC]
    assert len(syncs) >= 0.9 / SYNC_PERIOD
    by_kind: dict[str, list[tuple[float, f.CanFrame]]] = defaultdict(list)
    for t, fr in window:
        cob = f.classify(fr.cob_id)
        by_kind[f"{cob.kind.name}{cob.pdo or ''}"].append((t, fr))
    pdo_kinds = {k for k in by_kind if k.startswith(("TPDO", "RPDO"))}
    assert pdo_kinds == {"TPDO1", "RPDO1"}  # no TPDO2 on every SYNC
    for sim in line.sims:
        node = sim.node_id
        tpdos = [t for t, fr in by_kind["TPDO1"] if fr.cob_id == f.tpdo_id(1, node)]
        assert abs(len(tpdos) - len(syncs)) <= 1  # one per SYNC
        rpdos = [(t, fr.data) for t, fr in by_kind["RPDO1"] if fr.cob_id == f.rpdo_id(1, node)]
        assert len({data for _, data in rpdos}) == 1  # the drive stands still: no change
        gaps = [b - a for (a, _), (b, _) in itertools.pairwise(rpdos)]
        # every RPDO_REFRESH, at the first SYNC after it: never more often
        assert gaps and all(RPDO_REFRESH - 1e-9 <= g <= RPDO_REFRESH + SYNC_PERIOD for g in gaps)
        assert len(rpdos) <= 1.0 / RPDO_REFRESH + 1
