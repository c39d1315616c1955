"""The WEG profile's ``inputs`` fast path (a telegram equal to the last one, nothing else
changed: the last readings again) against the general decode, step by step.

Two profiles of the same drive go through the same sequence of output commands, input
telegrams (drawn from a few, so that repeats are common), DP-V1 code reads, P0202 changes
and communication losses; one answers with ``inputs``, the other always decodes
(``_decode_inputs``). Their readings, their output telegrams and their memory must agree
at every step.
"""

from __future__ import annotations

import struct
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.spec import DataProfile
from gateway.model import DesiredCommand, Device, Readings
from tests.profibus.weg.helpers import profile

STATUS = (0x1700, 0x1200, 0x1310, 0x9280, 0x1780, 0x3200, 0x0237, 0x02B7, 0x0008, 0x0040)
SPEED = (0, 1024, 2048, 0xF800)
EXTRA = (0, 47, 139, 239)
OPTIONS = (
    WegOptions(sync_rpm=1800.0),
    WegOptions(words=6, words_in=(3, 48, 49, 2), rated_current_a=10, sync_rpm=1800.0),
    WegOptions(words=4, words_in=(3, 2), sync_rpm=1800.0),  # no fault or alarm word: DP-V1
    WegOptions(data_profile=DataProfile.PROFIDRIVE, max_rpm=1800),
)


def _telegram(options: WegOptions) -> st.SearchStrategy[bytes]:
    n = options.words
    return st.tuples(
        st.sampled_from(STATUS), st.sampled_from(SPEED), *[st.sampled_from(EXTRA)] * (n - 2)
    ).map(lambda ws: struct.pack(f">{n}H", *ws))


STEP = st.one_of(
    st.tuples(st.just("inputs"), st.integers(0, 2**31)),
    st.tuples(
        st.just("outputs"),
        st.fixed_dictionaries(
            {
                "run": st.booleans(),
                "speed_rpm": st.sampled_from((0.0, 450.0, -900.0, 1800.0)),
                "fault_reset_seq": st.integers(0, 2),
            }
        ),
    ),
    st.tuples(
        st.just("codes"), st.tuples(st.sampled_from((None, 21, 239)), st.sampled_from((None, 139)))
    ),
    st.tuples(st.just("control_type"), st.sampled_from((0, 1, 2, 5))),
    st.tuples(st.just("lost"), st.none()),
)


def _memory(p: WegProfile) -> tuple[Any, ...]:
    return (
        p._faulted,
        p._alarm,
        p._zsw,
        p._polled_fault,
        p._polled_alarm,
        p._status_values,
        p._sent,
        p.wants_codes,
    )


@settings(max_examples=150, deadline=None)
@given(
    device=st.sampled_from((Device.CFW11, Device.CFW700, Device.CFW320)),
    which=st.integers(0, len(OPTIONS) - 1),
    data=st.data(),
    steps=st.lists(STEP, min_size=1, max_size=60),
)
def test_fast_inputs_agree_with_the_general_decode(
    device: Device, which: int, data: st.DataObject, steps: list[tuple[str, Any]]
) -> None:
    options = OPTIONS[which]
    if device is Device.CFW320 and options.data_profile is DataProfile.PROFIDRIVE:
        options = OPTIONS[0]  # the CFW320 has no PROFIdrive profile
    fast, general = profile(device, options), profile(device, options)
    telegrams = [data.draw(_telegram(options)) for _ in range(3)]  # few: repeats are common
    now = 0.0
    for kind, arg in steps:
        now += 0.01
        if kind == "inputs":
            telegram = telegrams[arg % len(telegrams)]
            assert fast.inputs(telegram, now) == general._decode_inputs(telegram)
        elif kind == "outputs":
            desired = DesiredCommand(**arg)
            assert fast.outputs(desired, now) == general.outputs(desired, now)
        elif kind == "codes":  # what read_codes leaves (a DP-V1 read while the bit is set)
            for p in (fast, general):
                if p._faulted and arg[0]:
                    p._polled_fault = arg[0]
                if p._alarm and arg[1]:
                    p._polled_alarm = arg[1]
        elif kind == "control_type":
            for p in (fast, general):
                p._set_control_type(arg)
        else:
            fast.on_comm_lost()
            general.on_comm_lost()
        assert _memory(fast) == _memory(general)


def test_a_repeated_telegram_is_not_decoded_again() -> None:
    p = profile(Device.CFW700, OPTIONS[1])
    telegram = struct.pack(">6H", 0x1700, 2048, 47, 0, 0, 1200)
    first = p.inputs(telegram, 0.0)
    calls: list[bytes] = []
    decode = p._decode_inputs

    def counted(data: bytes) -> Readings:
        calls.append(data)
        return decode(data)

    p._decode_inputs = counted  # type: ignore[method-assign]
    again = p.inputs(telegram, 0.01)
    assert again == first and calls == []
    values = again["values"]
    assert isinstance(values, dict)
    values["P0002"] = 0  # a caller's copy: the next readings are not changed by it
    assert p.inputs(telegram, 0.02) == first and calls == []
    p.outputs(DesiredCommand(run=True, speed_rpm=450.0), 0.03)  # what was asked changed
    assert p.inputs(telegram, 0.04) != first and calls == [telegram]
