"""A CiA 402 drive on CANopen, model-checked (docs/safety.md, "The model checks"; issue 32).

The real master engine, the real CANopen adapter's wishes and handlers (``_refresh`` once
per cycle through ``_before_step``/``_after_step``, every engine action into ``_handle``)
and the real hub, all on one injected clock, against the simulated CiA 402 drive
(:class:`adapters.canopen.sim.node.SimNode`: the canopen library's object dictionary, SDO
server, PDO maps and NMT slave around the drive model with its motor physics and its
0x6007 reaction to a lost heartbeat) on an ideal in-process bus. Hypothesis interleaves:
a cable cut and its return, a power cycle, the gateway killed (SIGKILL: no leave) and
started again, drive faults, the keypad's reset, 0x6007 changed at the drive, a second
master joining (its NMT reset and SYNC), a second node sending TPDO1 with the drive's id
(forged: running at 1500 rpm), time passing (the hub's command watchdog) and commands from
three clients on three front ends (runs, speeds, directions, stops, quick and coast stops,
resets). The drive's 0x6007 is drawn per example. The CiA 402 simulator has no local mode
(its statusword's remote bit is always set) and no auto-reset: neither is drawn.

Invariants:

- I1: the simulated motor is never commanded to start, to go faster or to reverse (its
  reference grows in magnitude or changes sign) unless the hub holds a run a client gave
  since the last stop condition (a stop, a lost or returning drive, a fault, a change of
  controller, the watchdog, a gateway restart).
- I2: a command that asks for less motion is never refused, and within the line's cycle
  bound (two SYNC periods and a margin: the RPDO goes with the next cycle, a synchronous
  RPDO acts on the SYNC after it) the reachable, online drive no longer runs.
- I3: the published state does not show the drive online more than ``OFFLINE_BOUND``
  after it became unreachable (its TPDO1 stops: tpdo_loss_cycles(CYCLE) + 1 cycles), nor
  stopped while its motor turns, running while it stands, or healthy while it is faulted
  for more than ``READ_BOUND`` (3 cycles), unless it is marked doubtful.
"""

from __future__ import annotations

import os
from typing import Any

import canopen
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule

from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import State
from adapters.canopen.master import FrameIn, Master, Send
from adapters.canopen.master.engine import tpdo_loss_cycles
from adapters.canopen.sim.node import SimNode, SimNodeConfig
from gateway.config import parse
from gateway.errors import CommandRejected, StopAppliedRestRefused
from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    StopAction,
)

SOAK = bool(os.environ.get("DRIVE_GATEWAY_SOAK"))
NODE = 5
CYCLE = 0.02  # s: the SYNC period
MAX_STEP = 0.002  # s: the clock never jumps further (the simulator's timers run)
WATCHDOG = 1.5  # s: the hub's command watchdog for the drive
CYCLE_BOUND = 2 * CYCLE + 0.01  # I2
OFFLINE_BOUND = (tpdo_loss_cycles(CYCLE) + 1) * CYCLE + 0.01 + 1e-6  # I3
READ_BOUND = 3 * CYCLE + 0.01 + 1e-6  # I3
TURNING_RPM = 50.0
CLIENTS = ((Source.ZENOH, "scada"), (Source.MODBUS, "10.0.0.5"), (Source.WEB, "10.0.0.9 op"))
STOP_FIELDS = {"run": False, "quick_stop": True, "coast_stop": True}
BUS = {
    "adapter": "canopen",
    "interface": "virtual",
    "channel": "model",
    "sync_period": CYCLE,
    "sdo_timeout": 0.05,
    "retry": 0.1,
    "boot_timeout": 0.3,
    "heartbeat": 50,
}

commands = st.builds(
    DriveCommand,
    run=st.sampled_from([None, True, True, False]),
    speed_rpm=st.sampled_from([None, 600.0, 1200.0, -900.0]),
    direction=st.sampled_from([None, None, Direction.FORWARD, Direction.REVERSE]),
    quick_stop=st.sampled_from([None, None, None, True, False]),
    coast_stop=st.sampled_from([None, None, None, True, False]),
    fault_reset=st.sampled_from([False, False, False, True]),
)


def asks_less_motion(cmd: DriveCommand) -> bool:
    return any(getattr(cmd, n) is v for n, v in STOP_FIELDS.items())


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class _Wire(canopen.Network):
    """The simulated node's side of the bus: what it sends is queued."""

    def __init__(self, model: CanOpenModel) -> None:
        super().__init__()
        self.model = model

    def send_message(self, can_id: int, data: Any, remote: bool = False) -> None:
        if not self.model.cut:
            self.model.from_node.append(f.CanFrame(can_id, bytes(data)))


class CanOpenModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.clock = Clock()
        self.hub = Hub(clock=self.clock, wallclock=self.clock)
        self.events = self.hub.subscribe_events()
        self.allowed = False  # a run given since the last stop condition
        self.last_ref = 0.0
        self.cut = False
        self.killed = False  # the gateway's process is gone (SIGKILL)
        self.from_node: list[f.CanFrame] = []
        self.since: dict[str, float | None] = {
            "online": None,
            "stopped": None,
            "running": None,
            "healthy": None,
        }

    # ------------------------------------------------------------ set-up

    @initialize(option=st.sampled_from([0, 1, 2, 3]))
    def start(self, option: int) -> None:
        drive = {
            "id": "d",
            "device": "CiA 402",
            "address": NODE,
            "eds": "eds/cia402-drive.eds",
            "max_rpm": 1800.0,
            "heartbeat": 50,
            "comm_loss_option": option,
        }
        config = parse(
            {
                "zenoh": {"enabled": False},
                "modbus": {"enabled": False},
                "buses": {"co": {**BUS, "drives": [drive]}},
            },
            "test.toml",
        )
        self.bus = config.buses[0]
        self.hub.add_drive(
            DriveState(id="d", device=Device.CIA402, bus="co", address=NODE),
            DrivePolicy(command_timeout=WATCHDOG, on_command_timeout=StopAction.RAMP_STOP),
        )
        self.sim = SimNode(
            SimNodeConfig(node_id=NODE, ramp_time=0.5, quick_stop_time=0.2),
            _Wire(self),
            clock=self.clock,
        )
        self.sim.power_on()
        self._gateway_start()
        self.advance(1.2)

    def _gateway_start(self) -> None:
        adapter = self.adapter = CanOpenAdapter(self.bus, clock=self.clock)
        self.engine = Master(adapter.master_config(), adapter.node_configs)
        adapter.engine, adapter._hub = self.engine, self.hub
        d = adapter.drives[NODE]
        self.hub.set_capabilities("d", adapter._capabilities(d))
        self.hub.update("d", comm=CommState.OFFLINE)

    # ------------------------------------------------------------ the line, stepped

    def _to_node(self, frame: f.CanFrame) -> None:
        if not self.cut and self.sim.wants(frame.cob_id):
            self.sim.on_frame(frame.cob_id, frame.data)

    def _act(self, actions: list[Any]) -> None:
        for action in actions:
            if isinstance(action, Send):
                self._to_node(action.frame)
            else:
                self.adapter._handle(self.clock.t, action)

    def _pass(self, now: float) -> None:
        """One driver pass (adapters.link.candriver's order): the adapter's refresh, the
        frames received stepped, the engine's step, the frames out delivered."""
        self.adapter.before_step(now)
        while self.from_node:
            frame = self.from_node.pop(0)
            self._act(self.engine.step(now, FrameIn(frame)))
        deadline = self.engine.next_deadline()
        if deadline is None or now >= deadline:
            self._act(self.engine.step(now))
        self.adapter.after_step(now)

    def advance(self, seconds: float) -> None:
        end = self.clock.t + seconds
        passed_at = None
        while self.clock.t < end - 1e-9 or passed_at is None:
            now = self.clock.t
            times = [end, now + MAX_STEP]
            if not self.killed:
                times += [t for t in (self.engine.next_deadline(), self.adapter.wake_at()) if t]
            sim_due = self.sim.next_deadline()
            if sim_due is not None:
                times.append(sim_due)
            if passed_at == now:  # a deadline already stepped at this time: the next one
                times = [t for t in times if t > now]
            self.clock.t = max(now, min(times))
            passed_at = self.clock.t
            self.sim.step(self.clock.t)
            if self.killed:
                self.from_node.clear()
            else:
                self._pass(self.clock.t)
            self.hub.tick()
            self._drain_events()
            self._check_motion()
            self._check_published()

    def _drain_events(self) -> None:
        for event in self.events.drain():
            if event.text.startswith(("no command from", "run command cleared")):
                self.allowed = False

    # ------------------------------------------------------------ the drive's events

    def _stop_condition(self) -> None:
        self.allowed = False

    @property
    def reachable(self) -> bool:
        return not self.cut and self.sim.powered

    @rule(seconds=st.sampled_from([0.05, 0.2, 0.6, 1.6]))
    def time_passes(self, seconds: float) -> None:
        self.advance(seconds)

    @rule(seconds=st.sampled_from([0.1, 0.5]))
    def cable_cut_and_back(self, seconds: float) -> None:
        self._stop_condition()
        self.cut = True
        self.advance(seconds)
        self.cut = False
        self.advance(0.6)

    @rule(off=st.sampled_from([0.05, 0.5]))
    def power_cycle(self, off: float) -> None:
        self._stop_condition()
        self.sim.power_off()
        self.advance(off)
        self.sim.power_on()
        self.advance(0.6)

    @rule(down=st.sampled_from([0.05, 0.5]))
    def gateway_sigkill_and_restart(self, down: float) -> None:
        """No leave: the drive reacts per its 0x6007 when the heartbeat stops."""
        self._stop_condition()
        self.hub.update("d", comm=CommState.OFFLINE)
        self.killed = True  # nothing sent, nothing stepped
        self.advance(down)
        self.killed = False
        self._gateway_start()
        self.advance(1.2)

    @rule(code=st.sampled_from([0x2310, 0x4310]))
    def fault(self, code: int) -> None:
        self._stop_condition()
        with self.sim.lock:
            self.sim._emcy(self.sim.drive.inject_fault(self.clock.t, code))

    @rule()
    def keypad_reset(self) -> None:
        if self.sim.drive.state is State.FAULT:
            self._stop_condition()
        with self.sim.lock:
            self.sim._emcy(self.sim.drive.keypad_reset(self.clock.t))

    @rule(option=st.sampled_from([0, 1, 2, 3]))
    def keypad_0x6007(self, option: int) -> None:
        """The drive's reaction to a lost master changed at the drive (a parameter)."""
        self.sim.drive.abort_connection_option = option

    @rule()
    def second_master_joins(self) -> None:
        """Another master's NMT reset of all nodes and its SYNC (issue 32 item 12)."""
        self._stop_condition()
        for frame in (f.encode_nmt(f.NmtCommand.RESET_NODE, 0), f.encode_sync()):
            self._to_node(frame)
            self._act(self.engine.step(self.clock.t, FrameIn(frame)))
        self.advance(0.6)

    @rule(frames=st.sampled_from([1, 5]))
    def forged_tpdo1(self, frames: int) -> None:
        """A second node sends TPDO1 with the drive's id: running at 1500 rpm."""
        running = bytes.fromhex("2702dc05") + bytes(4)
        for _ in range(frames):
            self.advance(CYCLE / 2)
            frame = f.CanFrame(f.tpdo_id(1, NODE), running)
            self._act(self.engine.step(self.clock.t, FrameIn(frame)))
            self.advance(CYCLE / 2)

    # ------------------------------------------------------------ the clients

    @rule(who=st.sampled_from(CLIENTS), cmd=commands)
    def command(self, who: tuple[Source, str], cmd: DriveCommand) -> None:
        before = self.hub.desired("d")
        try:
            self.hub.submit("d", who[0], cmd, who[1])
        except StopAppliedRestRefused:
            accepted = False
        except CommandRejected as exc:
            assert not asks_less_motion(cmd), f"I2: a stop was refused: {exc.reason}"
            return
        else:
            accepted = True
        after = self.hub.desired("d")
        if before.controller != who or asks_less_motion(cmd) or cmd.fault_reset:
            self._stop_condition()
        if accepted and after.run and cmd.run:
            self.allowed = True
        if asks_less_motion(cmd):
            self._check_stop_reaches_the_drive()

    def _check_stop_reaches_the_drive(self) -> None:
        online = self.hub.state("d").comm is CommState.ONLINE
        reachable = self.reachable and online
        self.advance(CYCLE_BOUND)
        desired = self.hub.desired("d")
        if reachable and self.reachable and not desired.run:
            state = self.sim.drive.state
            assert state is not State.OPERATION_ENABLED or self.sim.drive.motor.reference == 0, (
                f"I2: a stop did not reach the drive within {CYCLE_BOUND:g} s "
                f"(drive {state.value}, reference {self.sim.drive.motor.reference:g})"
            )

    # ------------------------------------------------------------ invariants

    def _check_motion(self) -> None:
        motor = self.sim.drive.motor
        ref = motor.reference if motor.enabled and self.sim.powered else 0.0
        grows = abs(ref) > abs(self.last_ref) + 1e-6
        flips = ref * self.last_ref < 0
        if not self.hub.desired("d").run:
            self.allowed = False
        assert self.allowed or not (grows or flips), (
            f"I1: the motor was commanded from {self.last_ref:g} to {ref:g} rpm with no run "
            f"given since the last stop condition (desired {self.hub.desired('d')})"
        )
        self.last_ref = ref

    def _since(self, name: str, condition: bool) -> float:
        if not condition:
            self.since[name] = None
            return 0.0
        started = self.since[name]
        if started is None:
            self.since[name] = started = self.clock.t
        return self.clock.t - started

    def _check_published(self) -> None:
        state = self.hub.state("d")
        drive = self.sim.drive
        online = state.comm is CommState.ONLINE
        away = self._since("online", online and not self.reachable)
        assert away <= OFFLINE_BOUND, f"I3: shown online {away:.2f} s after the drive was lost"
        trusted = online and not getattr(state, "doubtful", False) and self.reachable
        turning = abs(drive.motor.speed) > TURNING_RPM
        stopped = self._since("stopped", trusted and turning and not state.running)
        assert stopped <= READ_BOUND, (
            f"I3: shown stopped for {stopped:.2f} s while the motor turns at "
            f"{drive.motor.speed:.0f} rpm"
        )
        still = drive.motor.speed == 0.0 and drive.state is not State.OPERATION_ENABLED
        running = self._since("running", trusted and still and state.running)
        assert running <= READ_BOUND, (
            f"I3: shown running at {state.speed_rpm} rpm for {running:.2f} s while the motor "
            f"stands ({drive.state.value})"
        )
        faulted = drive.state in (State.FAULT, State.FAULT_REACTION_ACTIVE)
        healthy = self._since(
            "healthy", trusted and faulted and state.status is not DriveStatus.FAULTED
        )
        assert healthy <= READ_BOUND, f"I3: shown healthy {healthy:.2f} s while faulted"

    @invariant()
    def published_state_follows_the_drive(self) -> None:
        if hasattr(self, "sim"):
            self._check_published()


CanOpenModel.TestCase.settings = settings(
    max_examples=2000 if SOAK else 20,
    stateful_step_count=60 if SOAK else 20,
    deadline=None,
    derandomize=not SOAK,  # make test: a fixed set; make soak: new examples each run
    suppress_health_check=[HealthCheck.too_slow],
)
TestCanOpenModel = CanOpenModel.TestCase
