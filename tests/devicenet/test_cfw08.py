"""The CFW-08 profile: assemblies (seed 3, tables 5-7; fact sheet 2.11), parameter paths
(seed 5.10), the model mapping and the capabilities."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.cfw08 import (
    AssemblyPair,
    DriveStateCode,
    In70,
    In71,
    In150,
    Out20,
    Out21,
    Out100,
    ProfileSettings,
    capabilities,
    command_assembly,
    counts_to_rpm,
    decode_input,
    decode_output,
    decode_parameter,
    encode_parameter,
    fault_text,
    parameter_of,
    parameter_path,
    rpm_to_counts,
    state_changes,
)
from adapters.devicenet.codec.explicit import (
    ExplicitMessage,
    GetAttributeSingle,
    SetAttributeSingle,
)
from adapters.devicenet.errors import AssemblyDecodeError, DeviceNetDecodeError
from gateway.errors import FrameDecodeError, FrameEncodeError
from gateway.model import DesiredCommand, Direction, DriveStatus

# (assembly, wire bytes). Fact sheet 2.11 [TDN] gives words; little-endian on the wire.
GOLDEN = [
    # Out 21, forward at 1800 rpm: 0x0061, 0x0708 (Run Fwd, NetCtrl, NetRef).
    (Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=1800), "61 00 08 07"),
    # In 71, running forward: 0x04F6, 0x0708 (Toshiba sets Warning; state 4 Enabled).
    (
        In71(
            warning=True,
            running1=True,
            ready=True,
            ctrl_from_net=True,
            ref_from_net=True,
            at_reference=True,
            drive_state=DriveStateCode.ENABLED,
            speed_rpm=1800,
        ),
        "F6 04 08 07",
    ),
    # In 71, stopped: 0x0310 (Ready, state 3).
    (In71(ready=True, drive_state=DriveStateCode.READY), "10 03 00 00"),
    # Seed table 5: Out 20 b0 Run Fwd, b2 Fault Reset; In 70 b0 Faulted, b2 Running1.
    (Out20(run_fwd=True, fault_reset=True, speed_rpm=900), "05 00 84 03"),
    (In70(faulted=True, running1=True, speed_rpm=1), "05 00 01 00"),
    # Seed table 6: Run Rev b1.
    (Out21(run_rev=True, net_ctrl=True, net_ref=True, speed_rpm=600), "62 00 58 02"),
    # Seed table 7: Out 100 b0 ramp, b1 general enable, b2 direction, b3 JOG, b4 remote, b7 reset.
    (Out100(ramp_enable=True, general_enable=True, remote=True, speed_counts=8192), "13 00 00 20"),
    (Out100(general_enable=True, reverse=True, jog=True, fault_reset=True), "8E 00 00 00"),
    # In 150: byte 0 error code, byte 1 b0 ramp, b1 general, b2 cw, b3 JOG, b4 remote,
    # b5 undervoltage, b7 error.
    (In150(error_code=34, error=True, forward=True), "22 84 00 00"),
    (
        In150(
            ramp_enabled=True, general_enabled=True, forward=True, remote=True, speed_counts=4096
        ),
        "00 17 00 10",
    ),
    (In150(forward=False, undervoltage=True), "00 20 00 00"),
]


@pytest.mark.parametrize(("assembly", "wire"), GOLDEN)
def test_golden_assemblies(assembly: object, wire: str) -> None:
    raw = bytes.fromhex(wire)
    assert assembly.encode() == raw  # type: ignore[attr-defined]
    decode = decode_output if assembly.instance in (20, 21, 100) else decode_input  # type: ignore[attr-defined]
    assert decode(assembly.instance, raw) == assembly  # type: ignore[attr-defined]


@pytest.mark.parametrize("instance", [20, 21, 100, 70, 71, 150])
@pytest.mark.parametrize("length", [0, 3, 5, 8])
def test_wrong_length_is_a_typed_error(instance: int, length: int) -> None:
    decode = decode_output if instance in (20, 21, 100) else decode_input
    with pytest.raises(AssemblyDecodeError) as err:
        decode(instance, bytes(length))
    assert err.value.raw == bytes(length)


def test_unknown_instances_are_typed_errors() -> None:
    with pytest.raises(AssemblyDecodeError):
        decode_output(70, bytes(4))
    with pytest.raises(AssemblyDecodeError):
        decode_input(21, bytes(4))


def test_pairs_and_p710() -> None:
    # Seed 4.1.8: P710 0 = 20/70, 1 = 21/71, 2 = 100/150.
    assert [(p.label, p.p710) for p in AssemblyPair] == [("20/70", 0), ("21/71", 1), ("100/150", 2)]
    assert AssemblyPair.from_p710(2) is AssemblyPair.WEG
    assert AssemblyPair.from_p710(3) is None


# ---------------------------------------------------------------- hypothesis

speeds = st.integers(-32768, 32767)
b = st.booleans()
ASSEMBLIES = st.one_of(
    st.builds(Out20, b, b, speeds),
    st.builds(Out21, b, b, b, b, b, speeds),
    st.builds(Out100, b, b, b, b, b, b, st.integers(0, 0xFFFF)),
    st.builds(In70, b, b, speeds),
    st.builds(In71, b, b, b, b, b, b, b, b, st.integers(0, 255), speeds),
    st.builds(In150, st.integers(0, 255), b, b, b, b, b, b, b, st.integers(0, 0xFFFF)),
)


@settings(max_examples=300, deadline=None)
@given(ASSEMBLIES)
def test_assembly_round_trip(assembly: object) -> None:
    instance = assembly.instance  # type: ignore[attr-defined]
    decode = decode_output if instance in (20, 21, 100) else decode_input
    assert decode(instance, assembly.encode()) == assembly  # type: ignore[attr-defined]


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([20, 21, 100, 70, 71, 150]), st.binary(max_size=8))
def test_assembly_fuzz(instance: int, data: bytes) -> None:
    decode = decode_output if instance in (20, 21, 100) else decode_input
    try:
        first = decode(instance, data)
    except FrameDecodeError as exc:
        assert isinstance(exc, DeviceNetDecodeError)
        return
    # Unused bits are dropped, so a second pass is stable.
    assert decode(instance, first.encode()) == first


@pytest.mark.parametrize("bad", [Out20(speed_rpm=40000), Out100(speed_counts=-1)])
def test_encode_range_errors(bad: Out20 | Out100) -> None:
    with pytest.raises(FrameEncodeError):
        bad.encode()


# ---------------------------------------------------------------- parameters (seed 5.10)


@pytest.mark.parametrize(
    ("number", "path"),
    [(23, (0x64, 1, 123)), (100, (0x65, 1, 100)), (202, (0x66, 1, 102)), (432, (0x68, 1, 132))],
)
def test_parameter_paths_from_the_seed(number: int, path: tuple[int, int, int]) -> None:
    p = parameter_path(number)
    assert (p.class_id, p.instance_id, p.attribute_id) == path
    assert parameter_of(p.class_id, p.attribute_id) == number


@pytest.mark.parametrize("number", [-1, 800, True])
def test_parameters_outside_the_weg_classes(number: int) -> None:
    with pytest.raises(ValueError, match="outside the WEG classes"):
        parameter_path(number)


def test_parameter_of_rejects_other_attributes() -> None:
    assert parameter_of(0x64, 99) is None
    assert parameter_of(0x6C, 100) is None
    assert parameter_of(0x29, 100) is None


def test_parameter_requests_on_the_wire() -> None:
    # Read P100 and write P100 = 50 (0x32): class 65h, instance 1, attribute 100 (64h).
    p = parameter_path(100)
    get = ExplicitMessage(0, False, GetAttributeSingle(p.class_id, 1, p.attribute_id))
    assert get.encode().hex(" ") == "00 0e 65 01 64"
    put = SetAttributeSingle(p.class_id, 1, p.attribute_id, encode_parameter(50))
    assert ExplicitMessage(0, True, put).encode().hex(" ") == "40 10 65 01 64 32 00"
    assert decode_parameter(b"\x32\x00") == 50
    assert encode_parameter(-1) == b"\xff\xff"
    with pytest.raises(FrameEncodeError):
        encode_parameter(70000)
    with pytest.raises(DeviceNetDecodeError):
        decode_parameter(b"")


# ---------------------------------------------------------------- model mapping

S21 = ProfileSettings(AssemblyPair.EXTENDED, max_rpm=1800.0)
S20 = ProfileSettings(AssemblyPair.BASIC, max_rpm=1800.0)
S100 = ProfileSettings(AssemblyPair.WEG, max_rpm=1800.0)
RUN_900 = DesiredCommand(run=True, speed_rpm=900.0)


def test_state_71_running_forward() -> None:
    data = In71(
        running1=True,
        ready=True,
        ctrl_from_net=True,
        ref_from_net=True,
        at_reference=True,
        drive_state=4,
        speed_rpm=900,
    ).encode()
    c = state_changes(S21, data, RUN_900)
    assert c["status"] is DriveStatus.RUNNING and c["running"] and c["at_reference"]
    assert (c["speed_rpm"], c["speed_pct"], c["speed_ref_rpm"]) == (900.0, 50.0, 900.0)
    assert c["remote"] and c["direction"] is Direction.FORWARD
    assert c["values"] == {"drive_state": 4, "ref_from_net": 1}


def test_state_71_reverse_ramping_and_faulted() -> None:
    rev = In71(running2=True, ready=True, drive_state=4, speed_rpm=300).encode()
    want = DesiredCommand(run=True, direction=Direction.REVERSE, speed_rpm=900.0)
    c = state_changes(S21, rev, want)
    assert c["status"] is DriveStatus.STARTING and c["direction"] is Direction.REVERSE
    assert c["speed_rpm"] == -300.0 and c["speed_ref_rpm"] == -900.0
    stopping = state_changes(S21, In71(running1=True, drive_state=5, speed_rpm=5).encode(), RUN_900)
    assert stopping["status"] is DriveStatus.STOPPING
    faulted = state_changes(S21, In71(faulted=True, drive_state=7).encode(), RUN_900)
    assert faulted["status"] is DriveStatus.FAULTED and faulted["fault_code"] is None


def test_state_70_computes_at_reference() -> None:
    starting = state_changes(S20, In70(running1=True, speed_rpm=100).encode(), RUN_900)
    assert starting["status"] is DriveStatus.STARTING and not starting["at_reference"]
    running = state_changes(S20, In70(running1=True, speed_rpm=880).encode(), RUN_900)
    assert running["status"] is DriveStatus.RUNNING and running["at_reference"]
    stopped = state_changes(S20, In70().encode(), DesiredCommand())
    assert stopped["status"] is DriveStatus.READY and not stopped["running"]


def test_state_150_scale_direction_and_error_code() -> None:
    data = In150(
        ramp_enabled=True, general_enabled=True, forward=False, remote=True, speed_counts=4096
    ).encode()
    want = DesiredCommand(run=True, direction=Direction.REVERSE, speed_rpm=900.0)
    c = state_changes(S100, data, want)
    assert c["speed_rpm"] == -900.0 and c["direction"] is Direction.REVERSE
    assert c["status"] is DriveStatus.RUNNING and c["remote"]
    e34 = state_changes(S100, In150(error_code=34, error=True).encode(), DesiredCommand())
    assert e34["status"] is DriveStatus.FAULTED and e34["fault_code"] == 34
    assert e34["fault_text"] == fault_text(34) and "bus-off" in (e34["fault_text"] or "")
    e5 = state_changes(S100, In150(error_code=5, error=True).encode(), DesiredCommand())
    assert (e5["fault_code"], e5["fault_text"]) == (5, "E05")  # no invented text
    undervoltage = state_changes(S100, In150(undervoltage=True).encode(), DesiredCommand())
    assert undervoltage["alarm"] is True


def test_speed_scale_decision_for_100_150() -> None:
    assert rpm_to_counts(1800.0, 1800.0) == 8192  # 8192 counts = max_rpm (docs/devices.md)
    assert rpm_to_counts(-900.0, 1800.0) == 4096
    assert counts_to_rpm(8191, 1800.0, 8191) == 1800.0
    assert rpm_to_counts(1800.0, 1800.0, scale=16384) == 16384
    with pytest.raises(FrameEncodeError):
        rpm_to_counts(1.0, 0.0)


def test_commands_per_pair() -> None:
    assert command_assembly(S20, RUN_900, False) == Out20(run_fwd=True, speed_rpm=900)
    assert command_assembly(S20, DesiredCommand(fault_reset_seq=1), True) == Out20(fault_reset=True)
    rev = DesiredCommand(run=True, direction=Direction.REVERSE, speed_pct=25.0)
    assert command_assembly(S21, rev, False) == Out21(
        run_rev=True, net_ctrl=True, net_ref=True, speed_rpm=450
    )
    local = DesiredCommand(run=False, remote=False, speed_rpm=100.0)
    assert command_assembly(S21, local, False) == Out21(speed_rpm=100)
    assert command_assembly(S100, RUN_900, False) == Out100(
        ramp_enable=True, general_enable=True, remote=True, speed_counts=4096
    )
    coast = DesiredCommand(run=False, coast_stop=True)
    assert command_assembly(S100, coast, False) == Out100(remote=True)
    jog = DesiredCommand(jog=True)
    assert command_assembly(S100, jog, True) == Out100(
        general_enable=True, jog=True, remote=True, fault_reset=True
    )
    # A reference beyond the scale is clamped to max_rpm (the hub refuses it before).
    fast = DesiredCommand(run=True, speed_rpm=5000.0)
    assert command_assembly(S21, fast, False).speed_rpm == 1800  # type: ignore[union-attr]


def test_capabilities_per_pair() -> None:
    c20, c21, c100 = capabilities(S20), capabilities(S21), capabilities(S100)
    assert c21.speed_scale is not None and c21.speed_scale.max_rpm == 1800.0
    assert set(c20.unsupported) == {"jog", "direction", "remote"}
    assert set(c21.unsupported) == {"jog"}
    assert set(c100.unsupported) == set()
    # a stop kind the pair lacks becomes the nearest it has (issue 32 item 4)
    ramp = {"quick_stop": "run", "coast_stop": "run"}
    assert c20.stop_substitutes == ramp and c21.stop_substitutes == ramp
    assert c100.stop_substitutes == {"quick_stop": "coast_stop"}


def test_only_20_70_refuses_a_reverse() -> None:
    # Seed table 5: assembly 20 has Run Fwd only (issue 17 item 5).
    reason = capabilities(S20).reverse_refused
    assert reason is not None and "20/70 has no reverse" in reason
    assert capabilities(S21).reverse_refused is None  # Run Rev (seed table 6)
    assert capabilities(S100).reverse_refused is None  # Sentido de Giro (seed table 7)


def test_fault_texts_are_never_invented() -> None:
    assert fault_text(None) is None
    assert fault_text(37) is not None and "timed out" in fault_text(37)  # type: ignore[operator]
    assert fault_text(33) is not None and "not powered" in fault_text(33)  # type: ignore[operator]
    assert fault_text(36) == "network master is idle"
    assert fault_text(12) == "E12"
