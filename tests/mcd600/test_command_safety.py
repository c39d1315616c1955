"""Issue 32 on the MCD 600: no start by itself after not ready or local control (item 3),
a quick stop that is the card's coast stop (item 4), the starter's reaction to a lost
master (item 5), local control (item 6), and a fresh stop as the first output."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from adapters.mcd600.layout import Mode
from adapters.mcd600.monitoring import StarterState
from adapters.mcd600.options import Mcd600Options, safety_warning
from adapters.mcd600.paramtable import COMMAND_SOURCE, CommandSource, NetworkCommsAction
from adapters.mcd600.profile import Mcd600Profile
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.mcd600.trips import EXCESS_START_TIME
from gateway.adapter import Capabilities
from gateway.config import DriveConfig, safety_warnings
from gateway.config import parse as parse_config
from gateway.errors import CommandRejected, GatewayError
from gateway.hub import Hub
from gateway.model import (
    CommState,
    DesiredCommand,
    Device,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
)
from gateway.schema import Table
from tests.mcd600.loop import Loop, drive_config
from tests.mcd600.test_closed_loop import fast_sim, running_loop


def _no_start_after(loop: Loop, seconds: float = 3.0) -> None:
    starts = loop.sim.starts
    loop.step(round(seconds / 0.05))
    assert loop.sim.starts == starts, "the starter started with no new run command"
    assert not any(c.start for c in loop.controls[-5:])


def test_reset_input_opened_and_closed_with_run_held_does_not_start_again() -> None:
    """Item 3 (audit M54/F3, probe P4): the reset input opens while running (3.3 note: the
    starter does not operate), the run stays requested, the input closes again: no start
    until a new run command (run seen off, then on)."""
    loop = running_loop()
    assert loop.sim.starts == 1
    loop.sim.reset_input_closed = False  # the attribute the old simulator has too
    assert loop.step(2).status is DriveStatus.NOT_READY
    loop.sim.reset_input_closed = True
    assert loop.step(2).status is DriveStatus.READY
    _no_start_after(loop)
    loop.command(run=False)
    loop.step()
    loop.command(run=True)
    loop.run_until(lambda s: s.status is DriveStatus.RUNNING, limit=5.0)
    assert loop.sim.starts == 2


def test_run_given_while_not_ready_does_not_start_when_ready() -> None:
    """A run given while the starter is not ready is not held for later (rule 1)."""
    loop = Loop(sim=fast_sim(), flc_a=100.0)
    loop.sim.set_reset_input(False, loop.now)
    assert loop.step(2).status is DriveStatus.NOT_READY
    loop.command(run=True)
    loop.step(5)
    loop.sim.set_reset_input(True, loop.now)
    assert loop.step().status is DriveStatus.READY
    _no_start_after(loop)
    assert loop.sim.starts == 0


def test_back_from_local_control_with_run_held_does_not_start() -> None:
    """Item 6: 1-1 Command Source off Network (status byte 0 bit 6 = 0) is local control;
    a run held through it never starts the starter when Network comes back."""
    loop = Loop(sim=fast_sim(), flc_a=100.0)
    loop.sim.keypad_change(COMMAND_SOURCE, CommandSource.DIGITAL_INPUT)
    state = loop.step(2)
    assert state.local_control and not state.remote
    loop.command(run=True)
    loop.step(5)
    loop.sim.keypad_change(COMMAND_SOURCE, CommandSource.NETWORK)
    state = loop.step()
    assert not state.local_control and state.remote
    _no_start_after(loop)
    assert loop.sim.starts == 0


def test_local_control_is_published_from_status_bit_6() -> None:
    loop = Loop(sim=fast_sim())
    assert loop.step().local_control is False
    loop.sim.keypad_change(COMMAND_SOURCE, CommandSource.REMOTE_LCP)
    assert loop.step().local_control is True


def test_hub_refuses_run_in_local_control_and_still_sends_a_stop() -> None:
    loop = running_loop()
    hub = Hub(clock=lambda: loop.now, wallclock=lambda: loop.now)
    hub.add_drive(DriveState(id="ss1", device=Device.MCD600, bus="pb", address=5))
    hub.set_capabilities("ss1", loop.profile.capabilities())
    hub.update("ss1", comm=CommState.ONLINE, **loop.last)
    hub.submit("ss1", Source.ZENOH, DriveCommand(run=True), "a")
    loop.desired = hub.desired("ss1")
    loop.sim.keypad_change(COMMAND_SOURCE, CommandSource.DIGITAL_INPUT)
    loop.step()
    hub.update("ss1", **loop.last)
    assert hub.state("ss1").local_control
    with pytest.raises(CommandRejected, match="local control"):
        hub.submit("ss1", Source.ZENOH, DriveCommand(run=True), "a")
    hub.submit("ss1", Source.ZENOH, DriveCommand(run=False), "a")
    loop.desired = hub.desired("ss1")
    loop.step()
    assert not loop.controls[-1].start  # the stop is on the wire (the starter ignores it)


def test_quick_stop_is_the_cards_coast_stop_never_refused() -> None:
    """Item 4: quick stop -> coast_stop (byte 0 bit 4, 4.2 table 2), said by the hub."""
    caps = Mcd600Profile(drive_config()).capabilities()
    assert dict(caps.stop_substitutes) == {"quick_stop": "coast_stop"}
    assert "quick_stop" not in caps.unsupported and "coast_stop" not in caps.unsupported
    loop = running_loop()
    hub = Hub(clock=lambda: loop.now, wallclock=lambda: loop.now)
    hub.add_drive(DriveState(id="ss1", device=Device.MCD600, bus="pb", address=5))
    hub.set_capabilities("ss1", caps)
    hub.update("ss1", comm=CommState.ONLINE, **loop.last)
    hub.submit("ss1", Source.ZENOH, DriveCommand(run=True), "a")
    hub.submit("ss1", Source.ZENOH, DriveCommand(run=False, quick_stop=True), "a")
    desired = hub.desired("ss1")
    assert desired.coast_stop and not desired.run
    assert loop.profile.outputs(desired, loop.now + 0.05) == bytes.fromhex("10 00")


def _on_connect(**options: Any) -> dict[str, Any]:
    profile = Mcd600Profile(drive_config(**options))

    async def call() -> dict[str, Any]:
        return dict(await profile.on_connect(None, lambda *a, **k: None))  # type: ignore[arg-type]

    return asyncio.run(call())


def test_comm_timeout_zero_is_published_not_failsafe() -> None:
    """Item 5: guide 3.3 note, a timeout of 0 keeps the starter's state: not fail-safe."""
    changes = _on_connect(comm_timeout=0)
    assert changes["failsafe"] is False
    assert "comm_timeout = 0" in changes["failsafe_text"]
    assert _on_connect()["failsafe"] is None  # 6-13 not stated: unknown
    stated = _on_connect(network_comms=NetworkCommsAction.TRIP_STARTER)
    assert stated["failsafe"] is True and "Trip Starter" in stated["failsafe_text"]
    warn = _on_connect(network_comms=NetworkCommsAction.WARN_AND_LOG)
    assert warn["failsafe"] is False


@pytest.mark.parametrize(
    ("keys", "watchdog", "words"),
    [
        ({"comm_timeout": 0}, 0.5, "not fail-safe"),
        ({"network_comms": NetworkCommsAction.TRIP_STARTER}, 0.0, "watchdog = 0"),
        ({}, 0.5, "unknown"),
        ({"network_comms": NetworkCommsAction.LOG_ONLY}, 0.5, "keeps running"),
    ],
)
def test_check_config_warning(keys: dict[str, Any], watchdog: float, words: str) -> None:
    options = Mcd600Options(**keys)
    text = safety_warning(options, watchdog)
    assert text is not None and words in text
    drive = DriveConfig(id="ss1", bus="pb", device=Device.MCD600, address=5, options=options)
    assert Mcd600Profile.safety_warnings(drive, watchdog) == [text]


@pytest.mark.parametrize(("watchdog", "words"), [(0.5, "not fail-safe"), (0.0, "watchdog = 0")])
def test_check_config_through_the_profibus_adapter(watchdog: float, words: str) -> None:
    """The hook check-config calls (gateway.config.safety_warnings) reaches the profile."""
    drive = {"id": "ss1", "device": "MCD 600", "address": 5, "comm_timeout": 0}
    bus = {"adapter": "profibus", "port": "/dev/null", "watchdog": watchdog, "drives": [drive]}
    config = parse_config({"buses": {"pb": bus}}, "site.toml")
    [line] = safety_warnings(config.buses[0], config.buses[0].drives[0])
    assert line.startswith("drive ss1: ") and words in line


def test_no_warning_when_the_starter_trips_on_a_lost_master() -> None:
    options = Mcd600Options(network_comms=NetworkCommsAction.SOFT_TRIP_AND_LOG)
    assert safety_warning(options, 0.5) is None


def test_network_comms_key_is_parsed() -> None:
    table = Table({"network_comms": "trip_starter", "comm_timeout": 0}, "site.toml", "d")
    options = Mcd600Profile.parse_options(table, drive_config())
    table.finish()
    assert options.network_comms is NetworkCommsAction.TRIP_STARTER
    assert options.comm_timeout == 0
    bad = Table({"network_comms": "ignore"}, "site.toml", "d")
    with pytest.raises(GatewayError, match="network_comms"):
        Mcd600Profile.parse_options(bad, drive_config())
        bad.finish()


@pytest.mark.parametrize("mode", list(Mode))
def test_first_output_is_a_fresh_stop_that_arms_nothing(mode: Mode) -> None:
    """The adapter's first telegram after a (re)connection: a stop, all zero but the motor
    set, and it does not arm a start for a run that is still held."""
    profile = Mcd600Profile(drive_config(mode=mode))
    running = DesiredCommand(run=True)
    out = profile.unconfigured_outputs(DesiredCommand(), 0.0)
    assert out == bytes(profile.layout.output_len)
    assert profile.outputs(running, 0.1)[:2] == bytes(2)  # still needs run off, then on


def test_reset_input_opening_resets_a_trip_and_applies_at_once() -> None:
    sim = Mcd600Sim()
    sim.trip(EXCESS_START_TIME, 0.0)
    sim.set_reset_input(False, 0.0)
    assert _state(sim) is StarterState.NOT_READY  # the trip was reset, the input holds it
    sim.set_reset_input(True, 0.0)
    assert _state(sim) is StarterState.READY


def _state(sim: Mcd600Sim) -> StarterState:
    return sim.starter.state


def test_capabilities_type() -> None:
    assert isinstance(Mcd600Profile(drive_config()).capabilities(), Capabilities)
