"""The WEG CFW-11, CFW700 and CFW320 on Profibus DP, model-checked (docs/safety.md).

One hypothesis state machine per model: the real profile (:mod:`adapters.profibus.weg`),
the adapter's output choice before a drive is configured
(:func:`adapters.profibus.adapter.unconfigured_outputs`) and its restart when ``on_connect``
asks for new parameters, the real :class:`gateway.hub.Hub`, and the model's real simulator
(:mod:`adapters.profibus.weg.sim.drive`: state machine, P0313 reaction, motor), all on one
injected clock, one Data_Exchange every :data:`DT`. No pty: the line is the harness below,
which does what :class:`adapters.profibus.adapter.ProfibusAdapter` does per drive.

Events in random order: comm loss (the drive's DP watchdog expires: P0313 acts) and return
(Set_Prm again), power cycle, a fault and its reset at the keypad or by P0206 auto-reset,
the HMI's LOC/REM (P0220), the data profile P0741 changed at the HMI (taken by the drive
only when cyclic data stops), the hub's command watchdog, and commands from three clients
on three front ends (runs, JOGs, speeds, stops of every kind, resets, LOC/REM).

The CFW-11 is configured PROFIdrive without ``verify_mapping``, the CFW700 (V/f, where
P0684 bit 6 is ignored) PROFIdrive with ``startup_params`` P0741 = 0, the CFW320 as
manufacturer with the second ramp (P0684 bit 5); each starts at a drawn P0741 and P0313.

Invariants after every cycle:

- I1: the simulated motor does not start, speed up or reverse unless the client in control
  had a run or JOG accepted after the last stop condition (a stop, a reset, control passed,
  comm lost or back, power cycle, a trip, LOC/REM switched, the command watchdog), allowing
  :data:`GRACE` for the stop to reach the drive; while the master is away the drive follows
  its own P0313: with 0 or 4 (published ``failsafe`` false) it goes on with the command of
  the last telegram it took, even after a reset at its keypad;
- I2: a stop is never refused and the drive holds run and JOG off within :data:`GRACE`;
- I3: within :data:`BOUND` the published state shows the drive offline when it is, faulted
  when it is, running when its motor turns, ``running`` (not starting or stopping) while it
  jogs at the JOG speed, and in local control when it does not obey the network.
"""

from __future__ import annotations

import os
from collections.abc import Coroutine
from dataclasses import dataclass
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from adapters.profibus.adapter import MAX_REPARAMETERISE, unconfigured_outputs
from adapters.profibus.weg.cfw11 import Cfw11Profile
from adapters.profibus.weg.cfw320 import Cfw320Profile
from adapters.profibus.weg.cfw700 import Cfw700Profile
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim, WegSim
from adapters.profibus.weg.spec import DataProfile
from gateway.adapter import EventKind
from gateway.config import DriveConfig
from gateway.errors import CommandRejected, StopAppliedRestRefused
from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    Device,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    StopAction,
)
from tests.profibus.weg.helpers import SimChannel

SOAK = bool(os.environ.get("DRIVE_GATEWAY_SOAK"))
DT = 0.05  # s between Data_Exchanges (the line's cycle)
GRACE = 3 * DT  # s for a stop to reach the drive (I1, I2)
BOUND = 0.3  # s the published state may lag the drive (I3)
CONNECT_RETRY = 0.5  # s before on_connect is tried again (the adapter's back-off, shorter)
WATCHDOG = 1.0  # s, the hub's command watchdog
EPS = 0.5  # rpm
ID = "d"
CLIENTS = ((Source.ZENOH, "scada"), (Source.MODBUS, "10.0.0.5"), (Source.WEB, "10.0.0.9 p"))
STOP_FIELDS = {"run": False, "jog": False, "quick_stop": True, "coast_stop": True}

commands = st.builds(
    DriveCommand,
    run=st.sampled_from([None, True, False]),
    speed_rpm=st.sampled_from([None, 300.0, 900.0, -600.0]),
    quick_stop=st.sampled_from([None, None, True, False]),
    coast_stop=st.sampled_from([None, None, True, False]),
    jog=st.sampled_from([None, None, True, False]),
    fault_reset=st.booleans(),
    remote=st.sampled_from([None, None, None, True, False]),
)


def asks_less_motion(cmd: DriveCommand) -> bool:
    return any(getattr(cmd, n) is v for n, v in STOP_FIELDS.items())


def run_now(coro: Coroutine[Any, Any, Any]) -> Any:
    """``on_connect`` on the simulator's records: nothing real is awaited (no busy reads)."""
    try:
        coro.send(None)
    except StopIteration as done:
        return done.value
    coro.close()
    raise AssertionError("on_connect waited for something: the harness has no event loop")


@dataclass(frozen=True)
class Model:
    """One WEG model as the machine sets it up."""

    profile: type[WegProfile]
    sim: type[WegSim]
    options: WegOptions
    params: dict[int, int]
    has_p0741: bool


MODELS = {
    Device.CFW11: Model(
        Cfw11Profile,
        Cfw11Sim,
        WegOptions(data_profile=DataProfile.PROFIDRIVE, verify_mapping=False),
        {},
        True,
    ),
    Device.CFW700: Model(
        Cfw700Profile,
        Cfw700Sim,
        WegOptions(data_profile=DataProfile.PROFIDRIVE, startup_params=((741, 0),)),
        {202: 0},  # V/f 60 Hz: P0684 bit 6 "not allowed", ignored
        True,
    ),
    # the second ramp (P0684 bit 5) in every telegram: it selects ramp times only (issue 36)
    Device.CFW320: Model(Cfw320Profile, Cfw320Sim, WegOptions(second_ramp=True), {}, False),
}


class Harness:
    """The adapter's part for one drive: start-up, outputs, inputs, loss (bus-free)."""

    def __init__(self, model: Model, sim: WegSim, hub: Hub) -> None:
        self.now = 0.0
        device = model.profile.device
        config = DriveConfig(id=ID, bus="pb", device=device, address=5, options=model.options)
        self.profile = model.profile(config)
        self.profile.params.clock = lambda: self.now  # records on the injected clock
        self.sim = sim
        self.hub = hub
        self.up = False  # in data exchange
        self.configured = False
        self.retry_at = 0.0
        self.restarts = 0
        self.channel = SimChannel(sim, lambda: self.now)

    def slave_up(self) -> None:
        """SlaveUp: comm connecting, then the first telegram (fresh, unconfigured)."""
        self.sim.set_prm(b"")
        self.up, self.configured = True, False
        self.retry_at = 0.0  # a new connect at once (the adapter's task per SlaveUp)
        self.hub.update(ID, comm=CommState.CONNECTING)

    def slave_down(self) -> None:
        if self.up:
            self.profile.on_comm_lost()
            self.hub.update(ID, comm=CommState.OFFLINE, running=False)
        self.up = self.configured = False

    def _connect(self) -> None:
        try:
            changes = run_now(self.profile.on_connect(self.channel, lambda *a, **k: None))
        except Exception as exc:
            if getattr(exc, "reparameterise", False) and self.restarts < MAX_REPARAMETERISE:
                self.restarts += 1
                self.slave_down()
                self.slave_up()
                return
            self.retry_at = self.now + CONNECT_RETRY
            return
        self.restarts = 0
        self.hub.set_capabilities(ID, self.profile.capabilities())
        self.configured = True
        self.hub.update(ID, **changes)

    def cycle(self, now: float) -> None:
        self.now = now
        self.sim.tick(now)
        if not self.up:
            return
        if self.configured:
            out = self.profile.outputs(self.hub.desired(ID), now)
        else:
            safe = self.hub.desired(ID).stopped(StopAction.RAMP_STOP, Source.GATEWAY)
            out = unconfigured_outputs(self.profile, safe, now)
        data = self.sim.exchange(out, now)
        if self.configured:
            self.hub.update(ID, comm=CommState.ONLINE, **self.profile.inputs(data, now))
        elif now >= self.retry_at:
            self._connect()


class WegModel(RuleBasedStateMachine):
    device: Device

    def __init__(self) -> None:
        super().__init__()
        self.now = 0.0
        self.hub = Hub(clock=lambda: self.now, wallclock=lambda: self.now)
        self.hub.add_drive(
            DriveState(id=ID, device=self.device, bus="pb", address=5),
            DrivePolicy(command_timeout=WATCHDOG, on_command_timeout=StopAction.RAMP_STOP),
        )
        self.events = self.hub.subscribe_events()
        self.model = MODELS[self.device]
        self.run_ok = False  # a run or JOG accepted after the last stop condition
        self.held_ok = False  # run_ok when the master went away (the drive may go on)
        self.last_stop = -1.0
        self.stop_due: float | None = None  # a stop accepted: the drive holds it from then
        self.since: dict[str, float] = {}
        self.prev_speed = 0.0
        self.prev_remote: bool | None = None

    @initialize(
        p0741=st.sampled_from([0, 1]),
        p0313=st.sampled_from([0, 1, 2, 4, 5]),
        p0206=st.sampled_from([0, 2]),
    )
    def power_up(self, p0741: int, p0313: int, p0206: int) -> None:
        params = {**sp.NETWORK_SOURCES, 100: 20, 101: 20, 313: p0313, 206: p0206}
        params.update(self.model.params)
        if self.model.has_p0741:
            params[741] = p0741
        self.sim = self.model.sim(address=5, params=params)
        self.line = Harness(self.model, self.sim, self.hub)
        self.line.slave_up()
        self._cycles(1)

    # ------------------------------------------------------------ time

    def _stop_condition(self) -> None:
        self.run_ok = False
        self.last_stop = self.now

    def _cycles(self, n: int) -> None:
        for _ in range(n):
            self.now = round(self.now + DT, 6)
            self.line.cycle(self.now)
            self.hub.tick()
            if any(
                e.kind is EventKind.SAFETY and e.text.startswith("no command from")
                for e in self.events.drain()
            ):
                self._stop_condition()
            remote = self.sim.commands.remote()
            if self.prev_remote is not None and remote != self.prev_remote:
                self._stop_condition()  # LOC/REM switched (HMI, P0313 or the network)
            self.prev_remote = remote
            self._check_motion()
            self._check_state()

    @rule(n=st.sampled_from([1, 4, 20]))
    def time_passes(self, n: int) -> None:
        self._cycles(n)

    # ------------------------------------------------------------ the drive's events

    @precondition(lambda self: self.line.up)
    @rule()
    def comm_lost(self) -> None:
        # P0313 = 0 or 4 (failsafe false, published): the drive goes on with the command of
        # the last telegram it took, a level: after a trip even once its keypad resets it
        self.held_ok = self.run_ok or self.sim.net.run or self.sim.net.jog
        self.sim.comm_lost(self.now)  # the drive's DP watchdog: P0313 acts
        self.line.slave_down()
        self._stop_condition()
        self._cycles(1)

    @precondition(lambda self: not self.line.up)
    @rule()
    def comm_back(self) -> None:
        self.line.slave_up()
        self._stop_condition()
        self._cycles(1)

    @rule()
    def power_cycle(self) -> None:
        self.sim.power_cycle(self.now)
        self.line.slave_down()
        self.held_ok = False
        self._stop_condition()
        self._cycles(1)
        self.line.slave_up()
        self._cycles(1)

    @rule(code=st.sampled_from([21, 70]))
    def trip(self, code: int) -> None:
        self.sim.inject_fault(code, self.now)
        self._stop_condition()
        self._cycles(1)

    @rule()
    def keypad_reset(self) -> None:
        self.sim.keypad_reset(self.now)
        self._cycles(1)

    @rule(local=st.booleans())
    def hmi_loc_rem(self, local: bool) -> None:
        self.sim.values[220] = sp.SRC_LOCREM_ALWAYS_LOCAL if local else sp.SRC_LOCREM_NET_REM
        self._cycles(1)

    @precondition(lambda self: self.model.has_p0741)
    @rule(p0741=st.sampled_from([0, 1]))
    def hmi_data_profile(self, p0741: int) -> None:
        self.sim.values[741] = p0741  # in force only once cyclic data stops
        self._cycles(1)

    # ------------------------------------------------------------ the clients

    @rule(who=st.sampled_from(CLIENTS), cmd=commands)
    def command(self, who: tuple[Source, str], cmd: DriveCommand) -> None:
        before = self.hub.desired(ID)
        try:
            self.hub.submit(ID, who[0], cmd, who[1])
        except StopAppliedRestRefused:
            assert asks_less_motion(cmd)
        except CommandRejected as exc:
            assert not asks_less_motion(cmd), f"I2: a stop was refused: {exc.reason}"
            self._cycles(1)
            return
        after = self.hub.desired(ID)
        took_control = before.controller != after.controller and before.source is not Source.NONE
        latched = (before.quick_stop, before.coast_stop) != (after.quick_stop, after.coast_stop)
        stop = asks_less_motion(cmd) or cmd.fault_reset or latched or took_control
        if (cmd.run or cmd.jog) and (after.run or after.jog):
            self.run_ok = True
            self.stop_due = None
        elif stop:
            self._stop_condition()
        if asks_less_motion(cmd) and not after.run and not after.jog:
            self.stop_due = self.now + GRACE
        self._cycles(1)

    @rule(who=st.sampled_from(CLIENTS), speed=st.sampled_from([600.0, -900.0]), jog=st.booleans())
    def start(self, who: tuple[Source, str], speed: float, jog: bool) -> None:
        """A run (or JOG) at a speed: the command the other rules need to see motion."""
        cmd = DriveCommand(jog=True) if jog else DriveCommand(run=True, speed_rpm=speed)
        self.command(who, cmd)
        self._cycles(10)

    @rule(who=st.sampled_from(CLIENTS))
    def keepalive(self, who: tuple[Source, str]) -> None:
        self.hub.refresh(ID, who[0], who[1])
        self._cycles(1)

    # ------------------------------------------------------------ invariants

    def _permitted(self) -> bool:
        if self.now - self.last_stop <= GRACE:
            return True  # the stop is on its way
        if not self.sim.commands.remote():
            # in local (the HMI, P0313 = 3 or 4) the drive follows its local sources, not the
            # network: its motion is the local operator's (local_control shown, I3)
            return True
        if not self.line.up:
            # the drive keeps the last telegram it took, a level: P0313 = 0 goes on with it,
            # and after any trip a reset at the drive (keypad, auto-reset) while the master is
            # away applies it again (docs/safety.md, WEG rows: the gateway sends nothing then)
            return self.held_ok
        return self.run_ok

    def _check_motion(self) -> None:
        speed = self.sim.motor.speed
        before, self.prev_speed = self.prev_speed, speed
        faster = abs(speed) > abs(before) + EPS
        reversed_ = speed * before < 0 or (before == 0.0 and abs(speed) > EPS)
        if (faster or reversed_) and not self._permitted():
            raise AssertionError(
                f"I1: the motor went from {before:.1f} to {speed:.1f} rpm with no run "
                f"since the last stop condition at {self.last_stop:.2f} s (now {self.now:.2f} s, "
                f"drive {self.sim.net}, profile {self.sim.data_profile.value})"
            )
        if self.stop_due is not None and self.now >= self.stop_due and self.line.up:
            assert not self.sim.net.run and not self.sim.net.jog, (
                f"I2: a stop accepted at {self.stop_due - GRACE:.2f} s has not reached the "
                f"drive at {self.now:.2f} s: {self.sim.net}"
            )

    def _lasting(self, name: str, condition: bool) -> bool:
        """True when ``condition`` has held for longer than BOUND."""
        if not condition:
            self.since.pop(name, None)
            return False
        start = self.since.setdefault(name, self.now)
        return self.now - start > BOUND

    def _check_state(self) -> None:
        state = self.hub.state(ID)
        live = self.line.up and self.line.configured
        if self._lasting("away", not self.line.up):
            assert state.comm is not CommState.ONLINE, "I3: shown online while away"
        if self._lasting("faulted", live and self.sim.fault != 0):
            assert state.faulted, f"I3: F{self.sim.fault:03d} for {BOUND} s, shown {state.status}"
        turning = abs(self.sim.motor.speed) > 5.0
        if self._lasting("turning", live and turning):
            shown = state.running or abs(state.speed_rpm or 0.0) >= 5.0 or state.faulted
            assert shown, f"I3: the motor turns at {self.sim.motor.speed:.0f} rpm, shown {state}"
        jogging = live and self.sim.net.jog and abs(abs(self.sim.motor.speed) - sp.JOG_RPM) < 1
        if self._lasting("jogging", jogging and not self.sim.fault):
            assert state.status is DriveStatus.RUNNING, f"I3: jogging, shown {state.status}"
        local = live and not self.sim.commands.remote()
        if self._lasting("local", local):
            assert state.local_control, "I3: the drive is in local, not shown"

    @invariant()
    def offline_shows_no_speed(self) -> None:
        state = self.hub.state(ID)
        if state.comm in (CommState.OFFLINE, CommState.CONNECTING):
            assert not state.running and state.speed_rpm is None, state

    def teardown(self) -> None:
        self.events.close()


def machine(device: Device) -> Any:
    cls: Any = type(f"{device.name.title()}Model", (WegModel,), {"device": device})
    cls.TestCase.settings = settings(
        max_examples=300 if SOAK else 30,
        stateful_step_count=80 if SOAK else 40,
        deadline=None,
        derandomize=not SOAK,  # make test: a fixed set; make soak: new examples each run
        suppress_health_check=[HealthCheck.too_slow],
    )
    return cls


TestCfw11Model = machine(Device.CFW11).TestCase
TestCfw700Model = machine(Device.CFW700).TestCase
TestCfw320Model = machine(Device.CFW320).TestCase
