"""Round trips and fuzzing: control words, profile -> simulator -> profile, decoders."""

from __future__ import annotations

import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.contract import RecordAccessError
from adapters.profibus.weg import words as w
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.spec import CFW11, CFW320, CFW700, DataProfile, ModelSpec
from gateway.errors import FrameDecodeError
from gateway.model import DesiredCommand, Device, Direction
from tests.profibus.weg.helpers import SIMS, profile

FAST = settings(max_examples=60, deadline=None)
SPECS = st.sampled_from([CFW11, CFW700, CFW320])


def mask(table: w.BitTable) -> int:
    return sum(1 << bit for _, bit in table)


@FAST
@given(spec=SPECS, word=st.integers(0, 0xFFFF))
def test_manufacturer_words_round_trip(spec: ModelSpec, word: int) -> None:
    control = w.ManufacturerControl.decode(word, spec.control_bits)
    assert control.encode(spec.control_bits) == word & mask(spec.control_bits)
    status = w.ManufacturerStatus.decode(word, spec.status_bits)
    assert status.encode(spec.status_bits) == word & mask(spec.status_bits)
    assert w.ManufacturerControl.decode(control.encode(spec.control_bits), spec.control_bits) == (
        control
    )


@FAST
@given(word=st.integers(0, 0xFFFF))
def test_profidrive_words_round_trip(word: int) -> None:
    assert w.ProfidriveControl.decode(word, w.STW1_BITS).encode(w.STW1_BITS) == word & 0x05DF
    for table in (CFW11.zsw1_bits, CFW700.zsw1_bits):
        assert w.ProfidriveStatus.decode(word, table).encode(table) == word & mask(table)


@FAST
@given(value=st.integers(-32768, 32767))
def test_signed_word_round_trip(value: int) -> None:
    assert w.signed(w.to_word(value)) == value


desired_commands = st.builds(
    DesiredCommand,
    run=st.booleans(),
    direction=st.sampled_from(Direction),
    speed_rpm=st.one_of(st.none(), st.floats(-1800.0, 1800.0)),
    quick_stop=st.booleans(),
    coast_stop=st.booleans(),
    remote=st.booleans(),
)


@FAST
@given(device=st.sampled_from([Device.CFW11, Device.CFW700, Device.CFW320]), d=desired_commands)
def test_profile_to_sim_to_profile_is_consistent(device: Device, d: DesiredCommand) -> None:
    options = WegOptions(sync_rpm=1800.0, words=3, words_in=(685,))
    p = profile(device, options)
    sim = SIMS[device].matching(options, params={**sp.NETWORK_SOURCES, 100: 10, 101: 10})
    s = p.inputs(sim.exchange(p.outputs(d, 0.05), 0.05), 0.05)
    # the drive holds what the profile meant: run, remote, the effective reference
    quick = d.quick_stop and device is not Device.CFW320
    assert sim.net.run is (d.run and not d.quick_stop and not d.coast_stop)  # issue 17 item 4
    assert sim.net.general_enable is not d.coast_stop
    assert sim.net.quick_stop is quick
    assert s["remote"] is d.remote
    wanted = d.speed_rpm or 0.0
    if d.direction is Direction.REVERSE:
        wanted = -wanted
    echoed = w.signed(int(s["values"]["P0685" if device is not Device.CFW320 else "P685"]))
    assert abs(w.effective_reference(sim.net.forward, echoed) * 1800 / 8192 - wanted) <= 0.12
    if d.remote:
        assert abs((s["speed_ref_rpm"] or 0.0) - wanted) <= 0.12
    # and in the end the motor turns as asked, reported back on the same scale
    for i in range(2, 60):
        s = p.inputs(sim.exchange(p.outputs(d, 0.05 * i), 0.05 * i), 0.05 * i)
    if d.run and d.remote and not d.coast_stop and not d.quick_stop:
        assert abs(sim.motor.speed - wanted) <= 0.12
        assert abs((s["speed_rpm"] or 0.0) - sim.motor.speed) <= 0.12
        if abs(wanted) > 1.0:
            forward = wanted > 0
            assert s["direction"] is (Direction.FORWARD if forward else Direction.REVERSE)
    elif not d.run or not d.remote:
        assert sim.motor.speed == 0.0 or not sim.motor.enabled


@FAST
@given(
    device=st.sampled_from([Device.CFW11, Device.CFW700]),
    d=desired_commands,
    steps=st.integers(1, 40),
)
def test_profidrive_round_trip(device: Device, d: DesiredCommand, steps: int) -> None:
    options = WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1800.0)
    p = profile(device, options)
    sim = SIMS[device].matching(options, params=sp.NETWORK_SOURCES)
    for i in range(1, steps + 1):
        s = p.inputs(sim.exchange(p.outputs(d, 0.05 * i), 0.05 * i), 0.05 * i)
        assert s["remote"] is d.remote
        assert sim.stw1.no_coast_stop is not d.coast_stop
        assert sim.stw1.no_quick_stop is not d.quick_stop
    if not d.run:
        assert not sim.stw1.on


@FAST
@given(data=st.binary(max_size=24), words=st.integers(2, 10))
def test_profile_inputs_take_any_telegram(data: bytes, words: int) -> None:
    p = profile(
        Device.CFW11, WegOptions(words=words, words_in=(3, 48, 49, 2, 760, 763)[: words - 2])
    )
    if len(data) != 2 * words:
        try:
            p.inputs(data, 0.0)
        except FrameDecodeError:
            return
        raise AssertionError("a telegram of the wrong length was taken")
    p.inputs(data, 0.0)


@FAST
@given(index=st.sampled_from([47, 48]), data=st.binary(max_size=40))
def test_sim_records_refuse_only_with_dpv1_errors(index: int, data: bytes) -> None:
    sim = SIMS[Device.CFW11]()
    try:
        sim.write_record(0, index, data, 0.0)
        sim.read_record(0, index, 240, 0.0)
    except RecordAccessError as exc:
        assert exc.code_1 in (0xB5, 0xB6, 0xB7, 0xB8, 0xC3)


@FAST
@given(outputs=st.binary(min_size=4, max_size=4), now=st.floats(0.0, 100.0))
def test_sim_takes_any_output_telegram(outputs: bytes, now: float) -> None:
    sim = SIMS[Device.CFW700](params=sp.NETWORK_SOURCES)
    assert len(sim.exchange(outputs, now)) == 4
    sim.tick(now + 1.0)
    assert struct.unpack(">2H", sim.exchange(outputs, now + 2.0))[0] & 0x8000 == 0
