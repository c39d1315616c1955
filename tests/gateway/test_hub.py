"""The safety rules 1-3 and arbitration, stepped with an injected clock (no sleeping)."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from gateway.adapter import Capabilities, EventKind
from gateway.errors import (
    CommandRejected,
    ParameterError,
    ParameterNotWritable,
    StopAppliedRestRefused,
)
from gateway.hub import DrivePolicy, Hub
from gateway.model import (
    CommState,
    ControlMode,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
    SpeedScale,
    StopAction,
)


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def make_hub(**policy: Any) -> tuple[Hub, Clock]:
    clock = Clock()
    hub = Hub(clock=clock, wallclock=clock)
    hub.add_drive(
        DriveState(id="d", device=Device.CFW11, bus="b", address=3), DrivePolicy(**policy)
    )
    hub.set_capabilities("d", Capabilities(speed_scale=SpeedScale(1800.0)))
    hub.update("d", comm=CommState.ONLINE, status=DriveStatus.READY)
    return hub, clock


RUN = DriveCommand(run=True, speed_rpm=900)


# ------------------------------------------------------------------ rule 1


def test_gateway_starts_with_every_drive_stopped() -> None:
    hub, _ = make_hub()
    assert hub.desired("d").run is False
    assert hub.desired("d").source is Source.NONE


def test_run_needs_a_run_command() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=900))
    assert hub.desired("d").run is False
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    assert hub.desired("d").run is True


def test_coming_back_online_clears_run() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", comm=CommState.OFFLINE)
    hub.update("d", comm=CommState.ONLINE)
    assert hub.desired("d").run is False
    # the speed reference is kept: only run needs renewing
    assert hub.desired("d").speed_rpm == 900
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))
    assert hub.desired("d").run is True


def test_fault_clears_run_and_reset_does_not_restart() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", status=DriveStatus.FAULTED, fault_code=70, fault_text="overcurrent")
    assert hub.desired("d").run is False
    # the client keeps sending run (a stale level) before the reset: not a restart
    hub.submit("d", Source.ZENOH, DriveCommand(fault_reset=True))
    hub.update("d", status=DriveStatus.READY, fault_code=None, fault_text=None)
    assert hub.desired("d").run is False


def test_run_given_while_faulted_is_refused_not_held() -> None:
    hub, _ = make_hub()
    hub.update("d", status=DriveStatus.FAULTED, fault_code=70, fault_text="overcurrent")
    with pytest.raises(CommandRejected, match=r"faulted 70 \(overcurrent\): reset the fault"):
        hub.submit("d", Source.ZENOH, RUN)
    assert hub.desired("d").run is False
    hub.submit("d", Source.ZENOH, DriveCommand(fault_reset=True))
    assert hub.desired("d").run is False  # the reset needs a new run command after it


def test_run_and_reset_together_is_refused() -> None:
    hub, _ = make_hub()
    with pytest.raises(CommandRejected, match="send run after the fault reset"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=True, fault_reset=True))
    assert hub.desired("d").fault_reset_seq == 0


def test_change_of_controlling_source_clears_run() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.MODBUS, RUN)
    hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=300))
    desired = hub.desired("d")
    assert desired.run is False and desired.source is Source.ZENOH
    assert desired.speed_rpm == 300
    hub.submit("d", Source.MODBUS, DriveCommand(run=True))
    assert hub.desired("d").run is True and hub.desired("d").source is Source.MODBUS


def test_new_source_may_run_in_its_first_command() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.MODBUS, RUN)
    hub.submit("d", Source.ZENOH, DriveCommand(run=True, speed_rpm=100))
    assert hub.desired("d").run is True and hub.desired("d").source is Source.ZENOH


# ------------------------------------------------------------------ rule 2


def test_fault_reset_is_one_edge_never_repeated() -> None:
    hub, clock = make_hub(command_timeout=1.0)
    hub.update("d", status=DriveStatus.FAULTED)
    hub.submit("d", Source.ZENOH, DriveCommand(fault_reset=True))
    assert hub.desired("d").fault_reset_seq == 1
    for _ in range(5):
        clock.t += 0.5
        hub.tick()
        hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=10))  # other commands
    assert hub.desired("d").fault_reset_seq == 1
    hub.submit("d", Source.ZENOH, DriveCommand(fault_reset=True))
    assert hub.desired("d").fault_reset_seq == 2


# ------------------------------------------------------------------ rule 3


@pytest.mark.parametrize(
    ("action", "run_after", "coast_after"),
    [
        (StopAction.RAMP_STOP, False, False),
        (StopAction.COAST, False, True),
        (StopAction.HOLD, True, False),
    ],
)
def test_command_watchdog(action: StopAction, run_after: bool, coast_after: bool) -> None:
    hub, clock = make_hub(command_timeout=2.0, on_command_timeout=action)
    hub.submit("d", Source.MODBUS, RUN)
    clock.t += 1.5
    hub.tick()
    assert hub.desired("d").run is True
    hub.refresh("d", Source.MODBUS)  # a keep-alive restarts the window
    clock.t += 1.9
    hub.tick()
    assert hub.desired("d").run is True
    clock.t += 0.2
    hub.tick()
    desired = hub.desired("d")
    assert desired.run is run_after
    assert desired.coast_stop is coast_after
    assert desired.source is Source.GATEWAY
    # the client comes back: its old run level does not restart the drive by itself
    if action is not StopAction.HOLD:
        hub.submit("d", Source.MODBUS, DriveCommand(speed_rpm=100))
        assert hub.desired("d").run is False


def test_watchdog_only_watches_the_controlling_client() -> None:
    hub, clock = make_hub(command_timeout=1.0)
    clock.t += 10
    hub.tick()
    assert hub.desired("d").source is Source.NONE  # nobody in control: nothing to do
    hub.submit("d", Source.ZENOH, RUN)
    hub.refresh("d", Source.MODBUS)  # not in control: does not feed the watchdog
    clock.t += 1.0
    hub.tick()
    assert hub.desired("d").run is False


def test_watchdog_acts_once_and_reports() -> None:
    hub, clock = make_hub(command_timeout=1.0)
    with hub.subscribe_events() as sub:
        hub.submit("d", Source.ZENOH, RUN)
        clock.t += 1.0
        hub.tick()
        clock.t += 5.0
        hub.tick()
        safety = [e.text for e in sub.drain() if e.kind is EventKind.SAFETY]
    assert safety == ["no command from zenoh for 1 s: ramp_stop applied"]


# ------------------------------------------------------------------ arbitration


@pytest.mark.parametrize(
    ("control", "zenoh_ok", "modbus_ok"),
    [
        (ControlMode.ANY, True, True),
        (ControlMode.ZENOH, True, False),
        (ControlMode.MODBUS, False, True),
    ],
)
def test_control_setting(control: ControlMode, zenoh_ok: bool, modbus_ok: bool) -> None:
    for source, ok in ((Source.ZENOH, zenoh_ok), (Source.MODBUS, modbus_ok)):
        hub, _ = make_hub(control=control)
        if ok:
            hub.submit("d", source, RUN)
            assert hub.desired("d").run is True
            assert hub.state("d").control_source is source
        else:
            with pytest.raises(CommandRejected, match=f"takes commands from {control.value} only"):
                hub.submit("d", source, RUN)
            assert hub.desired("d").run is False


def test_refused_commands_change_nothing() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    before = hub.desired("d")
    for cmd in (DriveCommand(speed_rpm=99999), DriveCommand(speed_pct=-101)):
        with pytest.raises(CommandRejected, match="beyond the drive's scale"):
            hub.submit("d", Source.ZENOH, cmd)
    assert hub.desired("d") == before


def test_a_stop_is_applied_even_beside_a_refused_field() -> None:
    """Rule 1: a command that asks for less motion is never refused because of another
    field: its stop part is applied, the rest is refused with the reason."""
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, RUN)
    before = hub.desired("d")
    with pytest.raises(StopAppliedRestRefused, match=r"run false applied.*beyond the drive"):
        hub.submit("d", Source.ZENOH, DriveCommand(run=False, speed_rpm=99999))
    assert hub.desired("d").run is False
    assert hub.desired("d").speed_rpm == before.speed_rpm


def test_capabilities_refuse_with_reason() -> None:
    hub, _ = make_hub()
    hub.set_capabilities(
        "d", Capabilities(speed_scale=None, unsupported={"remote": "no remote bit here"})
    )
    with pytest.raises(CommandRejected, match="no remote bit here"):
        hub.submit("d", Source.ZENOH, DriveCommand(remote=True))
    with pytest.raises(CommandRejected, match="has no speed reference"):
        hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=1))
    hub.submit("d", Source.ZENOH, DriveCommand(run=True))


def test_a_drive_that_cannot_reverse_refuses_a_reverse_with_the_reason() -> None:
    # Issue 17 item 5: a negative speed on a drive with no reverse must not be taken as a
    # stop (or a forward run) while the state says reverse.
    hub, _ = make_hub()
    hub.set_capabilities(
        "d", Capabilities(speed_scale=SpeedScale(1800.0), reverse_refused="forward only")
    )
    hub.submit("d", Source.ZENOH, RUN)
    before = hub.desired("d")
    refused = {
        DriveCommand(run=True, speed_rpm=-900): "speed_rpm -900 asks for reverse: forward only",
        DriveCommand(speed_pct=-0.5): "speed_pct -0.5 asks for reverse: forward only",
        DriveCommand(direction=Direction.REVERSE): "direction reverse: forward only",
    }
    for cmd, reason in refused.items():
        with pytest.raises(CommandRejected) as caught:
            hub.submit("d", Source.ZENOH, cmd)
        assert caught.value.reason == reason
    assert hub.desired("d") == before
    hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=0.0, direction=Direction.FORWARD))
    hub.submit("d", Source.ZENOH, DriveCommand(speed_pct=-0.0))  # no sign to refuse


def test_a_reversible_drive_takes_a_negative_speed() -> None:
    hub, _ = make_hub()
    hub.submit("d", Source.ZENOH, DriveCommand(run=True, speed_rpm=-900))
    assert hub.desired("d").speed_rpm == -900


def test_offline_drive_refuses_commands() -> None:
    hub, _ = make_hub()
    hub.update("d", comm=CommState.OFFLINE)
    with pytest.raises(CommandRejected, match="is offline"):
        hub.submit("d", Source.ZENOH, RUN)


# ------------------------------------------------------------------ state and shutdown


async def test_state_subscription_conflates_to_the_newest() -> None:
    hub, _ = make_hub()
    with hub.subscribe_states() as sub:
        for rpm in range(100):
            hub.update("d", speed_rpm=float(rpm))
        state = await sub.get()
        assert state.speed_rpm == 99
        assert sub.drain() == []


async def test_a_subscription_with_a_callback_is_called_once_until_it_is_drained() -> None:
    hub, _ = make_hub()
    calls: list[int] = []
    with hub.subscribe_states(on_ready=lambda: calls.append(len(calls))) as sub:
        hub.update("d", speed_rpm=1.0)
        hub.update("d", speed_rpm=2.0)  # one is waiting already: no second call
        assert calls == [0]
        assert [s.speed_rpm for s in sub.drain()] == [2.0]
        hub.update("d", speed_rpm=3.0)
        assert calls == [0, 1]
    hub.update("d", speed_rpm=4.0)  # closed: the hub no longer offers it anything
    assert calls == [0, 1] and [s.speed_rpm for s in sub.drain()] == [3.0]


async def test_an_emptied_subscription_wakes_its_reader_on_the_next_change() -> None:
    hub, _ = make_hub()
    with hub.subscribe_states() as sub:
        hub.update("d", speed_rpm=1.0)
        assert (await sub.get()).speed_rpm == 1.0  # taken: none waits, the event is stale
        reader = asyncio.create_task(sub.get())
        await asyncio.sleep(0)  # the reader clears the event and waits
        assert not reader.done()
        hub.update("d", speed_rpm=2.0)
        assert (await asyncio.wait_for(reader, 5)).speed_rpm == 2.0


def test_seq_grows_only_on_change() -> None:
    hub, _ = make_hub()
    s1 = hub.update("d", speed_rpm=1.0)
    s2 = hub.update("d", speed_rpm=1.0)
    s3 = hub.update("d", speed_rpm=2.0)
    assert s1.seq == s2.seq < s3.seq


def test_shutdown_applies_on_shutdown() -> None:
    hub, _ = make_hub(on_shutdown=StopAction.COAST)
    hub.submit("d", Source.ZENOH, RUN)
    hub.update("d", running=True)
    hub.apply_shutdown()
    assert hub.desired("d").run is False and hub.desired("d").coast_stop
    assert not hub.all_stopped()
    hub.update("d", running=False)
    assert hub.all_stopped()
    with pytest.raises(CommandRejected, match="shutting down"):
        hub.submit("d", Source.MODBUS, RUN)
    assert hub.desired("d").run is False


class Params:
    def __init__(self) -> None:
        self.values = {100: 50}

    async def read_param(self, drive_id: str, number: int, subindex: int) -> int:
        if number not in self.values:
            raise ParameterError("impermissible parameter number", code=0)
        return self.values[number]

    async def write_param(
        self, drive_id: str, number: int, subindex: int, value: int | float
    ) -> None:
        self.values[number] = int(value)


async def test_parameter_writes_only_where_allowed() -> None:
    hub, _ = make_hub(writable_params=frozenset({100}))
    params = Params()
    hub.attach_params(["d"], params)
    assert await hub.read_param("d", 100) == 50
    await hub.write_param("d", 100, 85)
    assert params.values[100] == 85
    with pytest.raises(ParameterNotWritable, match="not in writable_params"):
        await hub.write_param("d", 101, 1)
    assert 101 not in params.values


def test_update_refuses_unknown_fields_and_ignores_the_hubs_own() -> None:
    hub, clock = make_hub()
    before = hub.state("d")
    with pytest.raises(TypeError, match=r"no field\(s\) \['sped_rpm'\]"):
        hub.update("d", sped_rpm=1.0)  # type: ignore[call-arg]  # mypy says so first
    with pytest.raises(TypeError, match="__dict__"):
        hub.update("d", __dict__={})  # type: ignore[call-arg]  # a state attribute, no field
    assert hub.state("d") is before
    # seq, ts and control_source are the hub's: an adapter cannot set them
    assert hub.update("d", seq=999, ts=5.0, control_source=Source.MODBUS) is before  # type: ignore[call-arg]
    clock.t += 1.0
    after = hub.update("d", seq=999, speed_rpm=12.0)  # type: ignore[call-arg]
    assert after.seq == before.seq + 1 and after.ts == clock.t
    assert after.control_source is Source.NONE
    assert after == before.changed(seq=after.seq, ts=after.ts, speed_rpm=12.0)


def test_watchdog_hold_keeps_the_drive_running_until_the_client_speaks_again() -> None:
    """hold: the command in force stays (the drive keeps running), control passes to the
    gateway; the client that comes back takes control anew, so it must say run again."""
    hub, clock = make_hub(command_timeout=1.0, on_command_timeout=StopAction.HOLD)
    hub.submit("d", Source.ZENOH, RUN)
    clock.t += 1.0
    hub.tick()
    held = hub.desired("d")
    assert held.run and held.speed_rpm == 900 and held.source is Source.GATEWAY
    assert hub.state("d").control_source is Source.GATEWAY  # the state says who holds it
    hub.refresh("d", Source.ZENOH)  # a keep-alive does not take control back
    assert hub.desired("d").source is Source.GATEWAY
    hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=600, run=True))
    assert hub.desired("d").run and hub.desired("d").source is Source.ZENOH
    clock.t += 1.0
    hub.tick()
    hub.submit("d", Source.ZENOH, DriveCommand(speed_rpm=300))  # no run: rule 1
    assert not hub.desired("d").run
