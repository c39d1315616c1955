"""The profile and the simulator against the Profibus contract, and fuzzed inputs."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.mcd600.layout import Mode
from adapters.mcd600.profile import Mcd600Profile
from adapters.mcd600.sim.starter import Mcd600Sim
from adapters.profibus.contract import DpProfile, SimDevice
from gateway.errors import FrameDecodeError
from gateway.model import DesiredCommand, Device, DriveState
from tests.mcd600.loop import drive_config


def test_classes_satisfy_the_contract() -> None:
    # checked by mypy: these assignments type-check only if the protocols are met.
    # (ProfileFactory cannot be checked this way: mypy never matches its ClassVar ``device``
    # against a class object; load_profile() returns the class untyped.)
    profile: DpProfile = Mcd600Profile(drive_config())
    sim: SimDevice = Mcd600Sim()
    assert profile.device is Device.MCD600
    assert sim.ident_number == profile.setup().ident_number


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(list(Mode)), st.binary(max_size=12), st.binary(max_size=12))
def test_any_input_gives_state_or_a_typed_error(mode: Mode, first: bytes, second: bytes) -> None:
    profile = Mcd600Profile(drive_config(mode=mode, request_period=0.0))
    state = DriveState(id="ss1", device=Device.MCD600, bus="pb", address=5)
    for now, data in ((1.0, first), (2.0, second)):
        profile.outputs(DesiredCommand(), now)
        try:
            changes = profile.inputs(data, now)
        except FrameDecodeError:
            continue
        state = state.changed(**changes)  # only DriveState fields
        assert state.speed_rpm is None


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=6))
def test_any_diagnosis_gives_events_or_a_typed_error(data: bytes) -> None:
    profile = Mcd600Profile(drive_config())
    try:
        events = profile.on_ext_diag(data)
    except FrameDecodeError as exc:
        assert exc.raw == data
    else:
        assert all(e.kind in ("trip", "info", "parameter") for e in events)


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(list(Mode)), st.binary(max_size=12))
def test_the_simulator_takes_any_outputs_or_raises_a_typed_error(mode: Mode, data: bytes) -> None:
    sim = Mcd600Sim(mode)
    try:
        inputs = sim.exchange(data, 1.0)
    except FrameDecodeError:
        assert len(data) != sim.layout.output_len
    else:
        assert len(inputs) == sim.layout.input_len
