"""The CFW-08 on DeviceNet, model-checked (docs/safety.md, "The model checks"; issue 32).

The real scanner engine and the simulated CFW-08 node (its DeviceNet side, its drive state
machine and motor physics, P313 on a lost master) on an ideal CAN line stepped by an
injected clock (tests/devicenet/harness.py), the real DeviceNet adapter's output and input
logic on that engine (``_refresh_outputs`` every poll interval, the scanner's actions into
the adapter's handlers; the profile's ``on_connect`` answered by the simulated node's
objects) and the real hub on the same clock. Hypothesis interleaves: a cable cut and its
return, a power cycle, bus-off and its manual recovery, faults (with or without the
drive's auto-reset P206), the keypad's reset, the drive's command source switched
between the network and its keypad (P230, seed 4.2.5), P313 and P231 changed on the
keypad, forged poll responses, time passing (the hub's command watchdog) and commands
from three clients on three front ends (runs, speeds, directions, stops, quick and coast
stops, jogs on 100/150, resets). The assembly pair (20/70, 21/71, 100/150) and P313 are
drawn per example.

Invariants:

- I1: the simulated motor is never commanded to start, to go faster or to reverse (its
  drive's reference grows in magnitude or changes sign) unless the hub holds a run or
  jog that a client gave since the last stop condition (a stop, a lost or returning
  drive, a fault, a change of control source, the watchdog). A drive that keeps its last
  command on its own while the master is away (P313 = 2, seed 4.1.3) does not count: its
  reference does not change.
- I2: a command that asks for less motion is never refused, and within the line's cycle
  bound (two poll intervals and a response timeout) the reachable drive no longer runs.
- I3: the published state does not show the drive online more than 4 x EPR plus two poll
  cycles after it became unreachable, nor stopped while its motor turns or healthy while
  it is faulted for more than three poll cycles, unless it is marked doubtful.

On the code before issue 32 (2f1a51d) this finds the stale run after a reconnect (item 1):
see docs/safety.md for the shrunk example.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from adapters.devicenet.adapter import DeviceNetAdapter, _Port
from adapters.devicenet.cfw08 import In71, In150
from adapters.devicenet.codec.explicit import Request, Response
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import PredefinedMessage, match_predefined
from adapters.devicenet.scanner import (
    ExplicitResult,
    InputData,
    LineOnline,
    NodeDown,
    NodeUp,
    Phase,
    Report,
)
from adapters.devicenet.sim import objects as sim_objects
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig, SimPhase
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
from tests.devicenet.harness import Line

SOAK = bool(os.environ.get("DRIVE_GATEWAY_SOAK"))
MAC = 5
POLL = 0.05
EPR = 0.1
RESPONSE = 0.02
WATCHDOG = 1.5  # s: the hub's command watchdog for the drive
CYCLE_BOUND = 2 * POLL + RESPONSE  # I2: a stop reaches the drive within this
OFFLINE_BOUND = 4 * EPR + 3 * POLL + 0.01  # I3: shown online at most this after a loss
READ_BOUND = 3 * POLL + 0.01  # I3: readings contradict the drive at most this long
TURNING_RPM = 50.0
CLIENTS = ((Source.ZENOH, "scada"), (Source.MODBUS, "10.0.0.5"), (Source.WEB, "10.0.0.9 op"))
STOP_FIELDS = {"run": False, "jog": False, "quick_stop": True, "coast_stop": True}
BUS = {
    "adapter": "devicenet",
    "poll_interval": POLL,
    "expected_packet_rate": EPR,
    "response_timeout": RESPONSE,
    "explicit_timeout": 0.1,
    "dupmac_timeout": 0.05,
    "retry_max": 0.3,
}

commands = st.builds(
    DriveCommand,
    run=st.sampled_from([None, True, True, False]),
    speed_rpm=st.sampled_from([None, 600.0, 1200.0]),
    direction=st.sampled_from([None, None, Direction.FORWARD, Direction.REVERSE]),
    quick_stop=st.sampled_from([None, None, None, True, False]),
    coast_stop=st.sampled_from([None, None, None, True, False]),
    jog=st.sampled_from([None, None, None, True, False]),
    fault_reset=st.sampled_from([False, False, False, True]),
)


def asks_less_motion(cmd: DriveCommand) -> bool:
    return any(getattr(cmd, n) is v for n, v in STOP_FIELDS.items())


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class CutLine(Line):
    """The harness line with the drive's cable pulled on demand: nothing it sends reaches
    the scanner and nothing addressed to it reaches it."""

    cut = False

    def _flush(self) -> None:
        if self.cut:
            self._pending = type(self._pending)(
                (sender, frame)
                for sender, frame in self._pending
                if sender is self.scanner and not _to(frame, MAC)
            )
        super()._flush()


def _to(frame: CanFrame, mac: int) -> bool:
    found = match_predefined(frame.arbitration_id)
    return found is not None and found.mac == mac


class Cfw08Model(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.clock = Clock()
        self.hub = Hub(clock=self.clock, wallclock=self.clock)
        self.events = self.hub.subscribe_events()
        self.allowed = False  # a run or jog given since the last stop condition
        self.last_ref = 0.0
        self.forging = 0
        self.since: dict[str, float | None] = {"online": None, "stopped": None, "healthy": None}

    # ------------------------------------------------------------ set-up

    @initialize(
        assembly=st.sampled_from([20, 21, 100]),
        p313=st.sampled_from([0, 1, 2, 3]),
    )
    def start(self, assembly: int, p313: int) -> None:
        self.assembly = assembly
        drive = {"id": "d", "device": "CFW-08", "address": MAC, "max_rpm": 1800}
        config = parse(
            {
                "zenoh": {"enabled": False},
                "modbus": {"enabled": False},
                "buses": {"dn": {**BUS, "drives": [{**drive, "assembly": assembly}]}},
            },
            "test.toml",
        )
        adapter = self.adapter = DeviceNetAdapter(config.buses[0], clock=self.clock)
        self.hub.add_drive(
            DriveState(id="d", device=Device.CFW08, bus="dn", address=MAC),
            DrivePolicy(command_timeout=WATCHDOG, on_command_timeout=StopAction.RAMP_STOP),
        )
        p710 = {20: 0, 21: 1, 100: 2}[assembly]
        sim = SimNodeConfig(
            MAC, p710=p710, p313=p313, ramp_time=0.5, dupmac_timeout=0.05, reset_offline=0.2
        )
        self.line = CutLine(adapter.scanner_config(), adapter.node_configs(), [sim])
        adapter.engine = self.line.scanner
        adapter._hub = self.hub
        self.hub.on_command(adapter._on_command)  # as adapter.run registers it
        adapter._request = self._request  # type: ignore[method-assign]
        adapter.publish_capabilities(adapter.drives[MAC])
        self.hub.update("d", comm=CommState.OFFLINE)
        self.line.power_on()
        self.advance(1.0)

    @property
    def node(self) -> Cfw08Node:
        return self.line.sims[MAC]

    async def _request(self, d: Any, body: Request) -> Response:
        """The profile's explicit requests, answered by the simulated node's objects."""
        return sim_objects.handle(self.node, body)

    # ------------------------------------------------------------ the line, stepped

    def advance(self, seconds: float) -> None:
        end = self.clock.t + seconds
        while self.clock.t < end - 1e-9:
            self.adapter._refresh_outputs(self.clock.t)
            if self.forging and self.reachable:
                self.line.run(POLL / 2)  # the drive's own answer first, then the forged one
                self._forge()
                self.line.run(POLL / 2)
            else:
                self.line.run(POLL)
            self.clock.t = self.line.now
            self._dispatch()
            self.hub.tick()
            self._drain_events()
            self._check_motion()
            self._check_published()

    def _forge(self) -> None:
        """A station that answers with the drive's identifier beside the drive itself: a
        faulted drive shown as running at 1500 rpm (issue 32 item 12). (One that answers
        for a drive gone silent cannot be told from it: see docs/safety.md.)"""
        self.forging -= 1
        forged = (
            In150(general_enabled=True, ramp_enabled=True, remote=True, speed_counts=6827)
            if self.assembly == 100
            else In71(running1=True, ready=True, ctrl_from_net=True, drive_state=4, speed_rpm=1500)
        ).encode()
        if self.assembly == 20:
            forged = bytes((0x04, 0)) + forged[2:]
        frame = self.node._frame(PredefinedMessage.SLAVE_POLL_RESPONSE, forged)
        self.line._pending.append((self.node, frame))

    def _dispatch(self) -> None:
        """The scanner's actions into the adapter. A bring-up ends after the inputs that
        came with it (the profile's explicit requests take longer than a poll)."""
        actions, self.line.actions = self.line.actions, []
        ups = [a for a in actions if isinstance(a, NodeUp)]
        for action in actions:
            if isinstance(action, NodeUp):
                continue
            elif isinstance(action, (NodeDown, InputData, Report, LineOnline)):
                self.adapter._handle(self.clock.t, action)
            elif not isinstance(action, ExplicitResult):
                self.adapter._handle(self.clock.t, action)  # IoConflict (issue 32)
        for up in ups:
            self._node_up(up)

    def _node_up(self, action: NodeUp) -> None:
        """The adapter's bring-up: its configure task, run to its end at once (the
        simulated node answers every explicit request in no time)."""

        async def up() -> None:
            self.adapter._handle(self.clock.t, action)
            d = self.adapter.drives[MAC]
            if d.setup is not None:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(d.setup, 0.05)

        asyncio.run(up())

    def _drain_events(self) -> None:
        for event in self.events.drain():
            if event.text.startswith(("no command from", "run command cleared")):
                self.allowed = False

    # ------------------------------------------------------------ the drive's events

    def _stop_condition(self) -> None:
        self.allowed = False

    @property
    def reachable(self) -> bool:
        """The drive answers our polls (on the line, online, its I/O allocated)."""
        return not self.line.cut and self.node.phase is SimPhase.ONLINE and self.node.allocated()

    @rule(seconds=st.sampled_from([0.1, 0.3, 0.6, 1.6]))
    def time_passes(self, seconds: float) -> None:
        self.advance(seconds)

    @rule(seconds=st.sampled_from([0.2, 0.6]))
    def cable_cut_and_back(self, seconds: float) -> None:
        if seconds >= 4 * EPR:  # a shorter cut is noticed by neither side (4 x EPR)
            self._stop_condition()
        self.line.cut = True
        self.advance(seconds)
        self.line.cut = False
        self.advance(0.3)

    @rule(off=st.sampled_from([0.1, 0.6]))
    def power_cycle(self, off: float) -> None:
        self._stop_condition()
        self.node.power_off()
        self.advance(off)
        self.line.power_on(self.node)
        self.advance(0.3)

    @rule()
    def bus_off_and_recovery(self) -> None:
        self._stop_condition()
        self.node.bus_off(self.clock.t)
        self.advance(0.6)
        for frame in self.node.recover(self.clock.t):
            self.line._pending.append((self.node, frame))
        self.advance(0.3)

    @rule(code=st.sampled_from([5, 7]), auto=st.booleans())
    def fault(self, code: int, auto: bool) -> None:
        self._stop_condition()
        self.node.drive.params[206] = 1 if auto else 0  # P206 auto-reset after 1 s
        self.node.inject_fault(code, self.clock.t)

    @rule()
    def keypad_reset(self) -> None:
        if self.node.drive.fault_code is not None:
            self._stop_condition()
        self.node.keypad_reset(self.clock.t)

    @rule(network=st.booleans())
    def command_source(self, network: bool) -> None:
        """The remote situation's commands from DeviceNet or from the keypad (P230)."""
        value = 2 if network else 0
        if self.node.drive.params[230] == value:
            return
        self._stop_condition()
        self.node.drive.params[230] = value
        # an operator's switch lasts longer than the gateway takes to see it: each input on
        # 21/71 and 100/150, the status poll (every status_interval) on 20/70 (docs/safety.md)
        self._status_poll()
        self.advance(0.2)

    def _status_poll(self) -> None:
        """What the adapter's status task does every ``status_interval``."""
        d = self.adapter.drives[MAC]
        if d.configured and self.reachable:
            port = _Port(self.adapter, d)
            with contextlib.suppress(Exception):
                asyncio.run(d.profile.poll_status(port))

    @rule(p313=st.sampled_from([0, 1, 2, 3]))
    def keypad_p313(self, p313: int) -> None:
        self.node.drive.params[313] = p313

    @rule(p231=st.sampled_from([0, 1, 2]))
    def keypad_direction_source(self, p231: int) -> None:
        """P231 (seed 4.2.6): the direction fixed by the drive, not by the network (no
        stop condition: the drive keeps running, the other way round; I1 does not count a
        reversal while P231 fixes the direction)."""
        self.node.drive.params[231] = p231

    @rule(frames=st.sampled_from([4, 12]))
    def forged_poll_responses(self, frames: int) -> None:
        self.forging = frames
        self.advance(frames * POLL)
        self.forging = 0

    # ------------------------------------------------------------ the clients

    @rule(who=st.sampled_from(CLIENTS), cmd=commands)
    def command(self, who: tuple[Source, str], cmd: DriveCommand) -> None:
        if self.assembly != 100 and cmd.jog is not None:
            cmd = DriveCommand(**{**cmd.to_json(), "jog": None})  # no JOG bit: refused
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
        stops = cmd.run is False or cmd.quick_stop or cmd.coast_stop
        if before.controller != who or stops or (accepted and cmd.fault_reset):
            self._stop_condition()
        if accepted and (after.run or after.jog) and (cmd.run or cmd.jog):
            self.allowed = True
        if asks_less_motion(cmd):
            self._check_stop_reaches_the_drive()

    def _check_stop_reaches_the_drive(self) -> None:
        d = self.adapter.drives[MAC]
        reachable = self.reachable and d.configured
        self.advance(CYCLE_BOUND)
        desired = self.hub.desired("d")
        if reachable and self.reachable and not (desired.run or desired.jog):
            drive = self.node.drive
            run, _, _ = drive._demand()
            assert not run or drive.coast_requested, (
                f"I2: a stop did not reach the drive within {CYCLE_BOUND:g} s "
                f"(drive demand {drive._demand()}, desired {desired})"
            )

    # ------------------------------------------------------------ invariants

    def _check_motion(self) -> None:
        motor = self.node.drive.motor
        ref = motor.reference if motor.enabled else 0.0
        grows = abs(ref) > abs(self.last_ref) + 1e-6
        flips = ref * self.last_ref < 0 and self.node.drive.params[231] == 2
        desired = self.hub.desired("d")
        if not (desired.run or desired.jog):
            self.allowed = False
        assert self.allowed or not (grows or flips), (
            f"I1: the motor was commanded from {self.last_ref:g} to {ref:g} rpm with no run "
            f"given since the last stop condition (desired {desired})"
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
        drive = self.node.drive
        online = state.comm is CommState.ONLINE
        away = self._since("online", online and not self.reachable)
        assert away <= OFFLINE_BOUND, f"I3: shown online {away:.2f} s after the drive was lost"
        trusted = online and not state.doubtful and self.reachable
        turning = abs(drive.motor.speed) > TURNING_RPM
        shown_still = not state.running
        stopped = self._since("stopped", trusted and turning and shown_still)
        assert stopped <= READ_BOUND, (
            f"I3: shown stopped for {stopped:.2f} s while the motor turns at "
            f"{drive.motor.speed:.0f} rpm ({state.status.label}, {state.direction.value})"
        )
        faulted = drive.fault_code is not None
        shown_healthy = state.status not in (DriveStatus.FAULTED, DriveStatus.TRIPPED)
        healthy = self._since("healthy", trusted and faulted and shown_healthy)
        assert healthy <= READ_BOUND, f"I3: shown healthy {healthy:.2f} s while faulted"

    @invariant()
    def i3_away_is_shown_away(self) -> None:
        if not hasattr(self, "line"):
            return
        state = self.hub.state("d")
        if state.comm in (CommState.OFFLINE, CommState.CONNECTING):
            assert not state.running, state

    @precondition(lambda self: hasattr(self, "line"))
    @invariant()
    def scanner_node_known(self) -> None:
        assert self.line.scanner.nodes[MAC].phase in tuple(Phase)

    def teardown(self) -> None:
        self.events.close()


Cfw08Model.TestCase.settings = settings(
    max_examples=300 if SOAK else 25,
    stateful_step_count=60 if SOAK else 30,
    deadline=None,
    derandomize=not SOAK,  # make test: a fixed set; make soak: new examples each run
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
TestCfw08Model = Cfw08Model.TestCase
