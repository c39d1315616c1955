"""The profile on its own: command mapping, status mapping, diagnosis, parameter refusals."""

from __future__ import annotations

import pytest

from adapters.mcd600.layout import LAYOUTS, InputTelegram, Mode
from adapters.mcd600.profile import NEEDS_PARAMETER_MODE, Mcd600Profile
from adapters.mcd600.words import ControlWord, MotorSet, StatusWord
from gateway.adapter import Capabilities
from gateway.errors import CommandRejected, ParameterError
from gateway.hub import Hub
from gateway.model import (
    CommState,
    DesiredCommand,
    Device,
    Direction,
    DriveCommand,
    DriveState,
    DriveStatus,
    Source,
)
from tests.mcd600.loop import drive_config


def control(profile: Mcd600Profile, desired: DesiredCommand, now: float = 1.0) -> ControlWord:
    return ControlWord.decode(profile.outputs(desired, now)[:2])


def feed(profile: Mcd600Profile, status: StatusWord, now: float = 1.0) -> DriveStatus:
    data = InputTelegram(status).encode(profile.layout)
    result: DriveStatus = profile.inputs(data, now)["status"]
    return result


# ------------------------------------------------------------------ commands


def test_capabilities_refuse_what_a_soft_starter_cannot_do() -> None:
    caps = Mcd600Profile(drive_config()).capabilities()
    assert caps.speed_scale is None
    assert set(caps.unsupported) == {"direction", "jog", "remote"}
    hub = Hub(clock=lambda: 0.0, wallclock=lambda: 0.0)
    hub.add_drive(DriveState(id="ss1", device=Device.MCD600, bus="pb", address=5))
    hub.set_capabilities("ss1", Capabilities(caps.speed_scale, caps.unsupported))
    hub.update("ss1", comm=CommState.ONLINE)
    for cmd, reason in (
        (DriveCommand(run=True, speed_pct=50.0), "no speed reference"),
        (DriveCommand(direction=Direction.REVERSE), "no direction"),
        (DriveCommand(jog=True), "no jog"),
        (DriveCommand(remote=True), "1-1 Command Source"),
    ):
        with pytest.raises(CommandRejected, match=reason):
            hub.submit("ss1", Source.ZENOH, cmd)
    assert hub.submit("ss1", Source.ZENOH, DriveCommand(run=True)).run


def test_run_is_start_and_stop_is_soft_stop() -> None:
    profile = Mcd600Profile(drive_config(motor_set=MotorSet.PRIMARY))
    assert control(profile, DesiredCommand()) == ControlWord(motor_set=MotorSet.PRIMARY)
    assert control(profile, DesiredCommand(run=True)) == ControlWord(
        start=True, motor_set=MotorSet.PRIMARY
    )
    assert profile.outputs(DesiredCommand(run=True), 1.0) == bytes.fromhex("04 01")


@pytest.mark.parametrize(
    "desired",
    [DesiredCommand(run=True, coast_stop=True), DesiredCommand(run=True, quick_stop=True)],
)
def test_coast_and_quick_stop_are_the_quick_stop_action(desired: DesiredCommand) -> None:
    profile = Mcd600Profile(drive_config())
    control(profile, DesiredCommand())
    word = control(profile, desired)
    # 4.2: bit 4 of byte 0 set = quick stop (coast); never together with a start
    assert word == ControlWord(start=False, quick_stop=True)
    assert profile.outputs(desired, 1.0) == bytes.fromhex("10 00")
    # released with run still desired: no start (rule 1, issue 17 item 4) until run is
    # seen off and given again
    assert control(profile, DesiredCommand(run=True)) == ControlWord()
    assert control(profile, DesiredCommand()) == ControlWord()
    assert control(profile, DesiredCommand(run=True)) == ControlWord(start=True)


def test_fault_reset_is_one_pulse_never_repeated() -> None:
    profile = Mcd600Profile(drive_config(reset_pulse=0.25))
    words = [control(profile, DesiredCommand(fault_reset_seq=5), 0.0)]  # first sight: no pulse
    t = 0.0
    for _ in range(20):
        t += 0.0625
        words.append(control(profile, DesiredCommand(fault_reset_seq=6), t))
    resets = [w.reset for w in words]
    assert resets[0] is False
    assert resets[1:5] == [True] * 4  # held for reset_pulse (0.25 s) at 62.5 ms cycles
    assert not any(resets[5:])
    words = [control(profile, DesiredCommand(fault_reset_seq=7), t + 1.0)]
    assert words[0].reset


def test_a_reset_asked_during_the_pulse_is_a_new_edge() -> None:
    profile = Mcd600Profile(drive_config(reset_pulse=0.2))
    control(profile, DesiredCommand(), 0.0)
    resets = [control(profile, DesiredCommand(fault_reset_seq=1), t).reset for t in (0.1, 0.15)]
    seq2 = [control(profile, DesiredCommand(fault_reset_seq=2), t / 100) for t in range(20, 60, 5)]
    resets += [w.reset for w in seq2]
    # pulse 1, one low telegram, pulse 2 for its full 0.2 s, then low
    assert resets == [True, True, False, True, True, True, True, False, False, False]


def test_reset_pulse_of_zero_still_sends_one_cycle() -> None:
    profile = Mcd600Profile(drive_config(reset_pulse=0.0))
    control(profile, DesiredCommand(), 0.0)
    assert control(profile, DesiredCommand(fault_reset_seq=1), 1.0).reset
    assert not control(profile, DesiredCommand(fault_reset_seq=1), 1.0).reset


def test_no_start_while_resetting() -> None:
    profile = Mcd600Profile(drive_config())
    control(profile, DesiredCommand(), 0.0)
    word = control(profile, DesiredCommand(run=True, fault_reset_seq=1), 0.05)
    assert word.reset and not word.start


def test_run_already_on_at_connection_needs_a_new_run() -> None:
    profile = Mcd600Profile(drive_config())
    assert not control(profile, DesiredCommand(run=True)).start
    assert not control(profile, DesiredCommand()).start
    assert control(profile, DesiredCommand(run=True)).start


# ------------------------------------------------------------------ status


def test_status_word_to_drive_status() -> None:
    profile = Mcd600Profile(drive_config())
    net = {"network_control": True}
    assert feed(profile, StatusWord(**net)) is DriveStatus.NOT_READY
    assert feed(profile, StatusWord(ready=True, **net)) is DriveStatus.READY
    control(profile, DesiredCommand())
    assert control(profile, DesiredCommand(run=True)).start
    assert feed(profile, StatusWord(ramping=True, active=True, **net)) is DriveStatus.STARTING
    assert feed(profile, StatusWord(active=True, **net)) is DriveStatus.RUNNING
    control(profile, DesiredCommand())
    assert feed(profile, StatusWord(ramping=True, active=True, **net)) is DriveStatus.STOPPING
    assert feed(profile, StatusWord(tripped=True, **net)) is DriveStatus.TRIPPED


def test_local_control_ramps_read_from_history() -> None:
    profile = Mcd600Profile(drive_config())
    assert feed(profile, StatusWord(ready=True)) is DriveStatus.READY
    assert feed(profile, StatusWord(ramping=True, active=True)) is DriveStatus.STARTING
    assert feed(profile, StatusWord(active=True)) is DriveStatus.RUNNING
    assert feed(profile, StatusWord(ramping=True, active=True)) is DriveStatus.STOPPING


def test_inputs_fill_the_model() -> None:
    profile = Mcd600Profile(drive_config(flc_a=50.0))
    changes = profile.inputs(bytes.fromhex("60 0A"), 1.0)  # running, warning, raw 32
    assert changes["running"] is True
    assert changes["remote"] is True
    assert changes["alarm"] is True
    assert changes["at_reference"] is True
    assert changes["current_pct_flc"] == pytest.approx(101.59)
    assert changes["current_a"] == pytest.approx(50.79, abs=0.01)
    assert changes["fault_code"] is None
    state = DriveState(id="ss1", device=Device.MCD600, bus="pb", address=5).changed(**changes)
    assert state.speed_rpm is None and state.speed_pct is None
    assert state.motor_temp_pct is None and state.power_kw is None  # basic mode: not read


def test_current_in_amps_needs_the_flc() -> None:
    changes = Mcd600Profile(drive_config()).inputs(bytes.fromhex("60 02"), 1.0)
    assert changes["current_a"] is None
    assert changes["current_pct_flc"] == pytest.approx(101.59)


# ------------------------------------------------------------------ diagnosis


def test_ext_diag_events() -> None:
    profile = Mcd600Profile(drive_config())
    [trip] = profile.on_ext_diag(bytes.fromhex("03 02 00"))
    assert (trip.kind, trip.text, trip.data) == ("trip", "trip 2: Motor overload", {"code": 2})
    assert profile.on_ext_diag(bytes.fromhex("03 02 00")) == []  # nothing new
    [param] = profile.on_ext_diag(bytes.fromhex("03 02 07"))
    assert (param.kind, param.data) == ("parameter", {"number": 7})
    [cleared] = profile.on_ext_diag(bytes.fromhex("03 00 07"))
    assert cleared.kind == "info"
    assert profile.on_ext_diag(bytes.fromhex("03 00 00")) == []
    # the code is remembered for the state: tripped status now carries code and text
    profile.on_ext_diag(bytes.fromhex("03 5A 00"))
    changes = profile.inputs(bytes.fromhex("40 04"), 1.0)
    assert changes["fault_code"] == 90
    assert (changes["fault_text"] or "").startswith("Internal fault 90")


def test_the_same_trip_after_a_reset_is_a_new_trip() -> None:
    """5.1.1: a reset zeroes the card's trip code, so the same three bytes read after it are
    a new trip (the card raises no alert for the cleared telegram; the master may never read it)."""
    profile = Mcd600Profile(drive_config())
    assert Mcd600Profile.sees_every_diag  # the master hands it every read (adapter contract)
    profile.inputs(bytes.fromhex("40 04"), 1.0)  # tripped
    first = profile.on_ext_diag(bytes.fromhex("03 02 05"))
    assert [e.kind for e in first] == ["trip", "parameter"]
    assert profile.on_ext_diag(bytes.fromhex("03 02 05")) == []  # the same read again
    profile.inputs(bytes.fromhex("40 01"), 1.1)  # reset seen in the status word
    profile.inputs(bytes.fromhex("40 04"), 1.2)  # tripped again
    [again] = profile.on_ext_diag(bytes.fromhex("03 02 05"))  # the parameter is not new
    assert (again.kind, again.text) == ("trip", "trip 2: Motor overload")
    assert profile.inputs(bytes.fromhex("40 04"), 1.3)["fault_code"] == 2


def test_an_empty_diagnosis_clears_the_trip_code() -> None:
    profile = Mcd600Profile(drive_config())
    profile.on_ext_diag(bytes.fromhex("03 02 00"))
    [cleared] = profile.on_ext_diag(b"")
    assert (cleared.kind, cleared.data) == ("info", {"code": 0})
    assert profile.on_ext_diag(b"") == []
    [again] = profile.on_ext_diag(bytes.fromhex("03 02 00"))
    assert again.kind == "trip"


def test_tripped_without_a_code_yet_says_nothing_stale() -> None:
    profile = Mcd600Profile(drive_config())
    profile.on_ext_diag(bytes.fromhex("03 02 00"))
    assert profile.inputs(bytes.fromhex("40 04"), 1.0)["fault_code"] == 2
    assert profile.inputs(bytes.fromhex("40 01"), 1.1)["fault_code"] is None  # reset
    changes = profile.inputs(bytes.fromhex("40 04"), 1.2)  # a new trip, code not read yet
    assert changes["status"] is DriveStatus.TRIPPED
    assert changes["fault_code"] is None and changes["fault_text"] is None


# ------------------------------------------------------------------ parameters


@pytest.mark.parametrize("mode", [Mode.BASIC, Mode.EXTENDED])
async def test_parameters_need_parameter_mode(mode: Mode) -> None:
    profile = Mcd600Profile(drive_config(mode=mode))
    with pytest.raises(ParameterError) as info:
        await profile.read_param(_NoChannel(), 1, 0)
    assert info.value.text == NEEDS_PARAMETER_MODE
    assert 'mode = "parameter"' in info.value.text
    with pytest.raises(ParameterError):
        await profile.write_param(_NoChannel(), 1, 0, 1)


@pytest.mark.parametrize(
    ("number", "subindex", "value", "text"),
    [
        (1, 1, 0, "no subindex"),
        (0, 0, 0, "1..255"),
        (256, 0, 0, "1..255"),
        (1, 0, 1.5, "integers"),
        (1, 0, float("inf"), "integers"),
        (1, 0, -1, "0..65535"),
        (1, 0, 65536, "0..65535"),
    ],
)
async def test_parameter_requests_checked_before_the_bus(
    number: int, subindex: int, value: float, text: str
) -> None:
    profile = Mcd600Profile(drive_config(mode=Mode.PARAMETER))
    with pytest.raises(ParameterError, match=text):
        await profile.write_param(_NoChannel(), number, subindex, value)
    assert profile.outputs(DesiredCommand(), 1.0)[3:] == bytes(4)  # nothing was queued


def test_layout_of_outputs_per_mode() -> None:
    for mode, size in ((Mode.BASIC, 2), (Mode.EXTENDED, 3), (Mode.PARAMETER, 7)):
        profile = Mcd600Profile(drive_config(mode=mode))
        assert len(profile.outputs(DesiredCommand(), 0.0)) == size == LAYOUTS[mode].output_len


class _NoChannel:
    """The MCD 600 never uses DP-V1: any call is a test failure."""

    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        raise AssertionError("DP-V1 read")

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        raise AssertionError("DP-V1 write")


async def test_connection_keeps_the_start_up_diagnosis_and_comm_loss_forgets_it() -> None:
    profile = Mcd600Profile(drive_config())
    control(profile, DesiredCommand())
    assert control(profile, DesiredCommand(run=True)).start
    profile.on_ext_diag(bytes.fromhex("03 13 00"))  # read by the master before data exchange
    changes = await profile.on_connect(_NoChannel(), _no_event)  # no bus read: the config's
    assert set(changes) == {"failsafe", "failsafe_text"}  # reaction to a lost master (3.3)
    assert not control(profile, DesiredCommand(run=True)).start  # run must be renewed
    assert profile.inputs(bytes.fromhex("40 04"), 1.0)["fault_code"] == 19
    profile.on_comm_lost()
    assert profile.inputs(bytes.fromhex("40 04"), 2.0)["fault_code"] is None


def _no_event(text: str, kind: str = "info", **data: object) -> None:
    raise AssertionError(f"unexpected event {text}")


@pytest.mark.parametrize("stop", [DesiredCommand(coast_stop=True), DesiredCommand(quick_stop=True)])
def test_a_run_given_after_a_stop_with_run_off_starts(stop: DesiredCommand) -> None:
    # the hub clears run with the stop: the next run (even with the release) is a new one
    profile = Mcd600Profile(drive_config())
    control(profile, DesiredCommand())
    assert control(profile, stop) == ControlWord(quick_stop=True)
    assert control(profile, DesiredCommand(run=True)) == ControlWord(start=True)
