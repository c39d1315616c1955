"""The CANopen line's steady fast path (docs/decisions/0098) puts on the bus what the
general path does.

The adapter with its master engine and the real hub, against simulated CiA 402 nodes
(:class:`adapters.canopen.sim.node.SimNode`), every frame delivered in process, stepped
with an injected clock in the CAN driver's order (``before_step``, the frames received,
the engine's step when due, ``after_step``, the frames sent). The same scripted scenario
(commands, a fault with its EMCY and a reset, a quick stop, a node power-cycled, a node
silent past its heartbeat, a forged second TPDO1) runs once with the fast path (a drive's
unchanged TPDO1 reported to a quiet adapter only every ``INPUTS_REFRESH``, the desired
command read when the hub says it changed) and once through the general path (every
TPDO1 handled, every command read before every cycle): every frame, its time and the
hub's view of every drive are the same.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

from adapters.can.adapter import AdapterLine
from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.codec import frames as f
from adapters.canopen.master import FrameIn, Inputs, Master
from adapters.canopen.master.engine import INPUTS_REFRESH
from adapters.canopen.sim.node import SimNode, SimNodeConfig
from gateway.config import parse
from gateway.errors import CommandRejected
from gateway.hub import Hub
from gateway.model import DriveCommand, Source
from gateway.runtime.daemon import build_hub

NODES = 3
SYNC_PERIOD = 0.01
MAX_STEP = 0.0005  # s: the fake clock never jumps further (the nodes' timers run)
WORDS = ("comm", "status", "running", "speed_rpm", "fault_code", "at_reference", "doubtful")


class GeneralPath(CanOpenAdapter):
    """The adapter without its fast path: every TPDO1 handled, every command read."""

    fast_path: ClassVar[bool] = False


class _Wire:
    """The nodes' side of an ideal bus: what they send waits for the next pass."""

    def __init__(self, line: Line) -> None:
        self.line = line

    def send_message(self, can_id: int, data: Any, remote: bool = False) -> None:
        self.line.rx.append(f.CanFrame(can_id, bytes(data)))


@dataclass
class Line:
    adapter_class: type[CanOpenAdapter]
    nodes: int = NODES
    now: float = 0.0
    rx: list[f.CanFrame] = field(default_factory=list)
    log: list[tuple[float, int, bytes]] = field(default_factory=list)
    inputs: Counter[int] = field(default_factory=Counter)
    refused: list[tuple[float, str, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        drives = [
            {
                "id": f"d{n}",
                "device": "CiA 402",
                "address": n,
                "eds": "eds/cia402-drive.eds",
                "max_rpm": 1800.0,
            }
            for n in range(1, self.nodes + 1)
        ]
        bus = {
            "adapter": "canopen",
            "interface": "virtual",
            "channel": "fast-path",
            "bitrate": 500_000,
            "sync_period": SYNC_PERIOD,
            "drives": drives,
        }
        config = parse(
            {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}},
            "test",
        )
        self.hub = build_hub(config, Hub(clock=lambda: self.now, wallclock=lambda: self.now))
        adapter = self.adapter_class(config.buses[0], clock=lambda: self.now)
        self.adapter = adapter
        self.master: Master = adapter.make_engine()
        adapter._hub, adapter.engine = self.hub, self.master
        for d in adapter.drives.values():
            adapter.publish_capabilities(d)
        if adapter.fast_path:
            self.hub.on_command(adapter._on_command)
        self.line = AdapterLine(adapter)
        wire = _Wire(self)
        self.sims = [
            SimNode(SimNodeConfig(node_id=n, ramp_time=0.5), wire, clock=lambda: self.now)  # type: ignore[arg-type]
            for n in range(1, self.nodes + 1)
        ]
        for sim in self.sims:
            sim.power_on()

    def _act(self, actions: list[Any]) -> None:
        for action in actions:
            frame = self.line.frame(action)
            if frame is None:
                if isinstance(action, Inputs):
                    self.inputs[action.node] += 1
                self.line.handle(self.now, action)
                continue
            self.log.append((round(self.now, 9), frame.arbitration_id, frame.data))
            for sim in self.sims:
                if sim.wants(frame.arbitration_id):
                    sim.on_frame(frame.arbitration_id, frame.data)

    def run(self, seconds: float) -> None:
        """Driver passes until ``seconds`` more have passed."""
        end = self.now + seconds
        master, line = self.master, self.line
        while self.now < end:
            line.before_step(self.now)
            received, self.rx = self.rx, []
            for frame in received:
                self._act(master.step(self.now, FrameIn(frame)))
            deadline = master.next_deadline()
            if deadline is None or self.now >= deadline:
                self._act(master.step(self.now))
            line.after_step(self.now)
            times = [end, self.now + MAX_STEP]
            times += [t for t in (master.next_deadline(), line.wake_at()) if t is not None]
            # (a node's expired watch keeps its deadline: only those ahead count)
            times += [t for t in (s.next_deadline() for s in self.sims) if t and t > self.now]
            self.now = max(self.now, min(times))
            for sim in self.sims:
                sim.step(self.now)

    def submit(self, drive_id: str, **command: Any) -> None:
        """A command as a client gives it; a refusal is kept (compared between paths)."""
        try:
            self.hub.submit(drive_id, Source.MODBUS, DriveCommand(**command))
        except CommandRejected as exc:
            self.refused.append((round(self.now, 9), drive_id, str(exc)))

    def view(self) -> list[tuple[Any, ...]]:
        return [tuple(getattr(s, w) for w in WORDS) for s in self.hub.states()]


Step = Callable[[Line], None]

SCENARIO: list[tuple[float, Step]] = [
    (0.0, lambda line: None),  # the bring-up of every node
    (0.3, lambda line: line.submit("d1", run=True, speed_rpm=600.0)),
    (0.25, lambda line: line.submit("d2", run=True, speed_rpm=-300.0)),
    (0.4, lambda line: line.submit("d1", speed_rpm=900.0)),
    (0.2, lambda line: line.sims[2].inject_fault(0x2310)),  # EMCY, then FAULT
    (0.3, lambda line: line.submit("d3", fault_reset=True)),
    (0.3, lambda line: line.submit("d1", quick_stop=True)),
    (0.4, lambda line: line.submit("d1", quick_stop=False)),
    (0.2, lambda line: line.submit("d1", run=True, speed_rpm=300.0)),
    (0.3, lambda line: line.sims[1].power_cycle()),  # boot-up: lost, brought up again
    (0.2, lambda line: line.sims[0].silence(True)),  # its heartbeat stops: lost
    (0.5, lambda line: line.sims[0].silence(False)),
    (0.1, lambda line: line.rx.append(f.CanFrame(f.tpdo_id(1, 3), bytes(8)))),  # forged
    (0.5, lambda line: line.submit("d2", run=True, speed_rpm=600.0)),
    (0.3, lambda line: line.submit("d3", run=True, speed_rpm=1200.0)),
    (0.3, lambda line: line.submit("d2", run=False)),
    (0.2, lambda line: line.submit("d3", coast_stop=True)),
    (0.5, lambda line: None),
]


def scripted(adapter_class: type[CanOpenAdapter]) -> Line:
    line = Line(adapter_class)
    line.run(3.0)  # the bring-up
    assert all(line.master.online(n) for n in range(1, NODES + 1))
    for wait, step in SCENARIO:
        line.run(wait)
        step(line)
    line.run(1.0)
    return line


def test_the_fast_path_puts_the_general_paths_frames_on_the_bus() -> None:
    fast = scripted(CanOpenAdapter)
    general = scripted(GeneralPath)
    assert len(fast.log) > 1000
    assert fast.log == general.log
    assert fast.view() == general.view()
    assert fast.refused == general.refused
    # the scenario did what it says: drives ran, one faulted, a node was lost twice
    lost = {n: fast.master.nodes[n].figures["lost"] for n in range(1, NODES + 1)}
    assert lost[1] >= 1 and lost[2] >= 1
    assert fast.master.nodes[3].figures["emcy_rx"] >= 1
    assert fast.master.nodes[3].figures["conflicts"] >= 1
    # and the fast path handed the adapter far fewer TPDO1s for it
    assert sum(fast.inputs.values()) < sum(general.inputs.values()) / 2


def test_at_rest_the_adapter_sees_a_nodes_tpdo1_about_every_refresh() -> None:
    line = Line(CanOpenAdapter)
    line.run(3.0)
    assert all(line.master.online(n) for n in range(1, NODES + 1))
    line.run(1.0)  # the drives come to rest
    line.inputs.clear()
    syncs = line.master.figures["syncs_tx"]
    span = 10 * INPUTS_REFRESH
    line.run(span)
    cycles = line.master.figures["syncs_tx"] - syncs
    assert cycles >= 0.9 * span / SYNC_PERIOD
    expected = span / INPUTS_REFRESH
    for node in range(1, NODES + 1):
        assert line.master.nodes[node].quiet
        # every INPUTS_REFRESH (a TPDO1 comes per SYNC: at the first one after it)
        assert expected * 0.8 <= line.inputs[node] <= expected + 1, line.inputs


def test_a_command_unquiets_the_node_and_its_rpdo1_goes_with_the_next_cycle() -> None:
    line = Line(CanOpenAdapter)
    line.run(4.0)
    assert line.master.nodes[1].quiet
    line.submit("d1", run=True, speed_rpm=600.0)
    assert not line.master.nodes[1].quiet
    start = line.now
    line.run(2 * SYNC_PERIOD)
    rpdos = [(t, data) for t, cob, data in line.log if t >= start and cob == f.rpdo_id(1, 1)]
    assert rpdos, "no RPDO1 in the next cycles"
    controlword = int.from_bytes(rpdos[0][1][:2], "little")
    assert controlword & 0x0F == 0x0F  # Enable operation
