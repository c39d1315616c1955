"""Safety rule 1 across a line's hand-over to the hub, model-checked (docs/safety.md, "The
model checks"; gateway/runtime/lineport.py).

A line runs on a loop of its own: what it reports reaches the hub only when the hub's loop
applies it (``flush``), and the line reads the hub's desired command whenever it likes. A
hypothesis state machine interleaves the line's reports (comm lost and back, a fault begun
and ended, local control, plain readings), the hub's loop applying them late, and partial
commands from three clients. The reference model counts the stop conditions *as the line
reports them* (each opens an epoch) and remembers which client last had a run accepted in
which epoch.

- L1: the line is never given a run (or jog) other than one accepted from the client in
  control in the current epoch: no run from before a transition the line has reported,
  however late the hub applies it;
- L2: once everything is applied, the line sees exactly the hub's desired command;
- L3: once everything is applied, the hub shows the readings the line last reported (the
  port hands over only readings that changed).

Without the port's guard the line reads the hub's stale run between reporting a lost or
regained drive, a fault or local control, and the hub applying that report.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from gateway.adapter import Capabilities
from gateway.errors import CommandRejected, StopAppliedRestRefused
from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    Device,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    SpeedScale,
)
from gateway.runtime.lineport import LinePort

SOAK = bool(os.environ.get("DRIVE_GATEWAY_SOAK"))
CLIENTS = ((Source.ZENOH, "scada"), (Source.MODBUS, "10.0.0.5"), (Source.WEB, "10.0.0.9 p"))
STOP_FIELDS = {"run": False, "jog": False, "quick_stop": True, "coast_stop": True}

commands = st.builds(
    DriveCommand,
    run=st.sampled_from([None, True, True, False]),
    speed_rpm=st.sampled_from([None, 600.0]),
    quick_stop=st.sampled_from([None, None, None, True, False]),
    jog=st.sampled_from([None, None, True, False]),
    fault_reset=st.sampled_from([False, False, True]),
)


def asks_less_motion(cmd: DriveCommand) -> bool:
    return any(getattr(cmd, n) is v for n, v in STOP_FIELDS.items())


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class LinePortModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.clock = Clock()
        self.hub = Hub(clock=self.clock, wallclock=self.clock)
        self.hub.add_drive(
            DriveState(id="d", device=Device.CFW11, bus="b", address=1), DrivePolicy()
        )
        self.hub.set_capabilities("d", Capabilities(speed_scale=SpeedScale(1800.0)))
        self.posted: list[Callable[[], None]] = []
        self.port = LinePort(self.hub, self.posted.append)
        self.epoch = 0
        self.run_given: tuple[tuple[Source, str], int] | None = None
        self.comm = CommState.ONLINE  # as the line last reported it
        self.faulted = False
        self.local = False
        self.speed: float | None = None
        self._report(comm=self.comm, status=DriveStatus.READY)
        self.flush()

    def _report(self, **changes: object) -> None:
        self.port.update("d", **changes)  # type: ignore[arg-type]

    # ------------------------------------------------------------ the line

    @rule(comm=st.sampled_from(list(CommState)))
    def line_reports_comm(self, comm: CommState) -> None:
        if CommState.ONLINE in (comm, self.comm) and comm is not self.comm:
            self.epoch += 1
        if comm is not CommState.ONLINE:
            self.faulted = False  # nothing is known of a drive that is away
        if comm is not self.comm:
            self.speed = None  # not reported since the comm change
        self.comm = comm
        status = DriveStatus.READY if comm is CommState.ONLINE else DriveStatus.NOT_READY
        self._report(comm=comm, status=status)

    @rule(faulted=st.booleans())
    def line_reports_fault(self, faulted: bool) -> None:
        if self.comm is not CommState.ONLINE:
            return
        if faulted is not self.faulted:
            self.epoch += 1
        self.faulted = faulted
        self._report(status=DriveStatus.FAULTED if faulted else DriveStatus.READY)

    @rule(local=st.booleans())
    def line_reports_local_control(self, local: bool) -> None:
        if local is not self.local:
            self.epoch += 1
        self.local = local
        self._report(local_control=local)

    @rule(speed=st.sampled_from([0.0, 300.0, 600.0]))
    def line_reports_readings(self, speed: float) -> None:
        self.speed = speed
        self._report(speed_rpm=speed, running=speed > 0)

    # ------------------------------------------------------------ the hub's loop

    @rule()
    def flush(self) -> None:
        posted, self.posted[:] = list(self.posted), []
        for call in posted:
            call()

    @rule(who=st.sampled_from(CLIENTS), cmd=commands)
    def command(self, who: tuple[Source, str], cmd: DriveCommand) -> None:
        before = self.hub.desired("d")
        try:
            self.hub.submit("d", who[0], cmd, who[1])
        except StopAppliedRestRefused:
            pass
        except CommandRejected:
            return
        after = self.hub.desired("d")
        took_control = before.controller != who and before.source is not Source.NONE
        latched = before.quick_stop != after.quick_stop
        if took_control or latched or cmd.fault_reset or asks_less_motion(cmd):
            self.epoch += 1
        if (cmd.run or cmd.jog) and (after.run or after.jog):
            self.run_given = (who, self.epoch)

    # ------------------------------------------------------------ invariants

    @invariant()
    def l1_the_line_runs_only_on_a_current_run(self) -> None:
        desired = self.port.desired("d")
        if desired.run or desired.jog:
            assert self.run_given == (desired.controller, self.epoch), (
                f"the line was given a run from before a transition it reported: {desired}, "
                f"last run given {self.run_given}, epoch {self.epoch}, "
                f"hub state {self.hub.state('d').comm}/{self.hub.state('d').status}"
            )

    @invariant()
    def l2_applied_means_the_hubs_command(self) -> None:
        if not self.posted and not self.port.waiting:
            assert self.port.desired("d") == self.hub.desired("d")

    @invariant()
    def l3_applied_readings_are_the_lines(self) -> None:
        """Readings left out as unchanged are the hub's still (a comm change resends)."""
        if self.posted or self.port.waiting or self.comm is not CommState.ONLINE:
            return
        if self.speed is not None:
            assert self.hub.state("d").speed_rpm == self.speed, self.hub.state("d")


LinePortModel.TestCase.settings = settings(
    max_examples=400 if SOAK else 80,
    stateful_step_count=60 if SOAK else 40,
    deadline=None,
    derandomize=not SOAK,  # make test: a fixed set; make soak: new examples each run
    suppress_health_check=[HealthCheck.too_slow],
)
TestLinePortModel = LinePortModel.TestCase
